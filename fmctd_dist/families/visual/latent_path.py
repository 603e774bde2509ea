"""The visual maze's low-level controller: inverse dynamics toward a planned latent path.

The planner hands out latents [F_env, D], one per env step, a sparse plan (jump H) holding each of
its frames for H steps (``control.pd.repeat_waypoints``). The inverse dynamics was trained on
consecutive frames, (z_{t-1}, z_t, z_{t+1}) -> a_t, so it is asked for one step at a time: the
target of step k is the planned path at k + 1, linearly interpolated in latent space between the
plan's frames (anchors at 0, H, 2H, ..., the observed latent at 0). Open loop in time, as the point
maze's PD controller and ``visual/reach.py`` (which measured this controller on recorded paths).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

InverseDynamics = Callable[[np.ndarray], np.ndarray]  # (z_{t-1}, z_t, z_{t+1}) [3 D] -> a_t [2]


def latent_targets(waypoints: np.ndarray, jump: int, z0: np.ndarray) -> np.ndarray:
    """Per-step targets [F_env + 1, D]: row k is where the path is at step k (row 0 = ``z0``, the observed latent).

    ``waypoints`` [F_env, D] hold each sparse frame ``jump`` times; frame i of the sparse plan is
    the path at step (i + 1) * jump, and steps between two frames are interpolated linearly.
    """
    w = np.asarray(waypoints, np.float64)
    assert w.ndim == 2 and len(w) > 0 and w.shape[1] == len(z0), f"waypoints {w.shape} vs latent {np.shape(z0)}"
    anchors = np.concatenate([np.asarray(z0, np.float64)[None], w[jump - 1::jump] if jump > 1 else w])
    if jump > 1 and len(w) % jump:
        anchors = np.concatenate([anchors, w[-1:]])  # a ragged tail (not made by repeat_waypoints): keep its end
    times = np.arange(len(anchors)) * jump
    steps = np.arange(len(w) + 1)
    return np.stack([np.interp(steps, times, anchors[:, j]) for j in range(w.shape[1])], axis=1)


class LatentPathController:
    """a_k = clip(invdyn(z_{k-1}, z_k, target_{k+1}), -1, 1), the step clock advancing once per call."""

    def __init__(self, waypoints: np.ndarray, jump: int, invdyn: InverseDynamics, z0: np.ndarray):
        self.targets = latent_targets(waypoints, jump, z0)
        self.invdyn = invdyn
        self.t = 0

    def act(self, z_prev: np.ndarray, z: np.ndarray) -> np.ndarray:
        """The action at the current observation's latent ``z`` (``z_prev`` the one before; at the start, ``z``)."""
        target = self.targets[min(self.t + 1, len(self.targets) - 1)]
        self.t += 1
        x = np.concatenate([z_prev, z, target]).astype(np.float32)
        return np.clip(np.asarray(self.invdyn(x), np.float64), -1.0, 1.0)
