"""Rows of a cube play dataset for the goal-conditioned cube policy, and their hindsight subgoals.

A row t is (the arm + target cube view before step t, the oracle's action at t). The target
cube is the one the data's oracle was moving (``target_block``, stored per step), and the
row's subgoal is where *that* cube actually was k steps later (k ~ 2 x Geometric(0.2), mean
10): goal-conditioned BC with hindsight relabelling, as for the ant.

Runs end with the current pick-and-place (a change of ``target_block`` or ``target_pos``, i.e.
``set_new_target``) or the episode: a subgoal never comes from the next pick-and-place, where
the same cube may be picked again for another reason.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fmctd_dist.config import Config
from fmctd_dist.families.cube.policy import VIEW_DIM, cube_view, policy_input
from fmctd_dist.control.policy.hindsight import label_run_ends
from fmctd_dist.families.cube.data import dataset_dir, load_cube_manifest
from fmctd_dist.data.npz import load_npz
from fmctd_dist.families.cube.env import ACT_DIM, cube_xyz, n_cubes
from fmctd_dist.errors import DatasetError


@dataclass
class CubeRows:
    """One split, episodes flattened to rows [N = E*S]."""

    views: np.ndarray  # [N, 28] float32: arm + the row's target cube, before the step
    xyz: np.ndarray  # [N, n, 3] float32: every cube's xyz (obs units), before the step
    target: np.ndarray  # [N] int64: the row's target cube
    actions: np.ndarray  # [N, 5] float32: the oracle's action at the row
    qpos: np.ndarray  # [N, nq] float32: MuJoCo state at the row (the reach test restores it)
    qvel: np.ndarray  # [N, nv] float32
    target_pos: np.ndarray  # [N, 3] float32: where the data's oracle was taking the target cube (obs units)
    end: np.ndarray  # [N] int64: last row of the row's pick-and-place run
    valid: np.ndarray  # [M] int64: rows that may be sampled (end > i)
    stats: dict[str, int]

    def inputs(self, i: np.ndarray, j: np.ndarray, max_dist: float) -> np.ndarray:
        """Network inputs [B, 34] of rows i with the target cube's position at rows j as subgoal."""
        return policy_input(self.views[i], self.xyz[j, self.target[i]], max_dist)


def make_rows(arrays: dict[str, np.ndarray], n: int) -> CubeRows:
    """One split's arrays [E, S, ...] -> CubeRows; runs end where the oracle's target changes."""
    obs, target = arrays["observations"], arrays["target_block"].astype(np.int64)
    e, s = target.shape
    tpos = arrays["target_pos"]
    change = np.zeros((e, s), dtype=np.int64)
    change[:, 1:] = (target[:, 1:] != target[:, :-1]) | np.any(tpos[:, 1:] != tpos[:, :-1], axis=-1)
    end = label_run_ends(np.cumsum(change, axis=1))
    idx = np.arange(e * s, dtype=np.int64)
    valid = idx[end > idx]
    flat = obs.reshape(e * s, -1)
    t = target.reshape(-1)
    return CubeRows(views=np.ascontiguousarray(cube_view(flat, t), np.float32),
                    xyz=np.ascontiguousarray(cube_xyz(flat, n).reshape(e * s, n, 3), np.float32),
                    target=t, actions=np.ascontiguousarray(arrays["actions"].reshape(e * s, ACT_DIM), np.float32),
                    qpos=arrays["qpos"].reshape(e * s, -1), qvel=arrays["qvel"].reshape(e * s, -1),
                    target_pos=tpos.reshape(e * s, 3), end=end, valid=valid,
                    stats={"rows": int(e * s), "trained_rows": int(valid.size),
                           "pick_and_place_runs": int((change.sum(axis=1) + 1).sum())})


def load_cube_policy_data(cfg: Config, path: Path | None = None) -> tuple[CubeRows, CubeRows, dict[str, Any]]:
    """Train and val rows of the cube play dataset ``cfg`` names (manifest and sha256 verified) + the manifest."""
    path = path or dataset_dir(cfg)
    manifest = load_cube_manifest(path, cfg, verify=True)
    n = n_cubes(cfg.env.name)
    obs_dim = int(manifest["obs_dim"])
    out = []
    for split in ("train", "val"):
        e, s = manifest["episodes"][split], manifest["episode_steps"]
        arrays = load_npz(path / f"{split}.npz", {"observations": (np.float32, (e, s, obs_dim)),
                                                  "actions": (np.float32, (e, s, ACT_DIM)),
                                                  "qpos": (np.float32, (e, s, None)),
                                                  "qvel": (np.float32, (e, s, None)),
                                                  "target_block": (np.int8, (e, s)),
                                                  "target_pos": (np.float32, (e, s, 3))},
                          f"it does not match {path / 'manifest.json'}; delete {path} and regenerate")
        rows = make_rows(arrays, n)
        if rows.valid.size == 0:
            raise DatasetError(f"{path / f'{split}.npz'} has no row to train on (episodes of one step); regenerate "
                               "with more data.episode_steps")
        out.append(rows)
    assert out[0].views.shape[1] == VIEW_DIM, out[0].views.shape
    return out[0], out[1], manifest
