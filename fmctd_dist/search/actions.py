"""The tree's action set as data: what each child slot of a node does to the guidance.

A child slot is one action = (guidance scale, which frame-state dims the goal guidance acts
on). Mazes guide every dim and differ only in the scale (``method.guidance_scales``: slot a
= scale a, exactly the old hard-wired set). Cubes guide one object at a time (docs/reference.md §13):
a child is an (unsolved cube, scale) pair, so 1 / 2 / 3 unsolved cubes x scales {1, 2, 4} give
3 / 6 / 9 children. The search only indexes these arrays; it never asks which family built them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

ALL = -1  # Actions.obj of an action that guides every state dim (no object chosen)


@dataclass(frozen=True)
class Actions:
    """A actions (child slots), or, after :meth:`take`, one action per job.

    mask None means "every dim for every action" and makes the denoiser batches carry no mask,
    so a maze search sends the very batches it sent before actions were data.
    """

    scale: np.ndarray  # [A] float32, guidance scale of the action (0 = unguided)
    obj: np.ndarray  # [A] int32, object whose goal distance is guided (ALL = every dim)
    mask: np.ndarray | None  # [A, d] float32, 1 on the frame-state dims the goal term uses; None = all

    def __post_init__(self) -> None:
        a = self.scale.shape[0]
        assert self.scale.shape == (a,) and self.obj.shape == (a,), "scale and obj must be [A]"
        assert self.mask is None or (self.mask.ndim == 2 and self.mask.shape[0] == a), "mask must be [A, d]"

    @property
    def size(self) -> int:
        return int(self.scale.shape[0])

    def take(self, idx: np.ndarray) -> "Actions":
        """Per-job actions from slot indices [J]."""
        idx = np.asarray(idx, np.int64)
        return Actions(self.scale[idx], self.obj[idx], None if self.mask is None else self.mask[idx])


def scale_actions(scales: Sequence[float]) -> Actions:
    """One action per guidance scale, guiding every dim (mazes: slot a = scale a, as before)."""
    s = np.asarray(scales, np.float32).reshape(-1)
    if s.size == 0:
        raise ValueError("an action set needs at least one guidance scale")
    return Actions(s, np.full(s.shape[0], ALL, np.int32), None)


def object_actions(objects: Sequence[int], num_objects: int, obj_dim: int, scales: Sequence[float]) -> Actions:
    """(object, scale) pairs, object-major: slot = i * len(scales) + k guides ``objects[i]`` at ``scales[k]``.

    The frame state is ``num_objects`` blocks of ``obj_dim`` numbers (cubes: xyz); the mask of an
    action is 1 on its object's block only, so the goal term sees that object's distance alone.
    ``objects`` are the not-yet-solved ones, chosen by the caller (a family's value rule).
    """
    objs = [int(o) for o in objects]
    if not objs or not scales:
        raise ValueError(f"object actions need objects and scales, got objects={objs} scales={list(scales)}")
    bad = [o for o in objs if not 0 <= o < num_objects]
    if bad or len(set(objs)) != len(objs):
        raise ValueError(f"objects {objs} must be distinct indices in [0, {num_objects})")
    obj = np.repeat(np.asarray(objs, np.int32), len(scales))  # [A]
    scale = np.tile(np.asarray(scales, np.float32), len(objs))  # [A]
    mask = np.zeros((obj.shape[0], num_objects * obj_dim), np.float32)
    for a, o in enumerate(obj):
        mask[a, o * obj_dim:(o + 1) * obj_dim] = 1.0
    return Actions(scale, obj, mask)
