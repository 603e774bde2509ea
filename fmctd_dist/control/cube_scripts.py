"""The arm's pre-defined plans between cube segments (reference §13), as scripted effector actions.

The planner plans cube positions only; between two object segments the authors insert
redundant, hand-written arm motions: before a new plan ~30 steps moving the open gripper
above the target cube's first planned position (so the low-level policy starts from a pose it
knows), and after a placement a 30-step release (10 steps lifting while opening, 20 steps
moving away in +x while open) so the arm leaves the placed cube alone. The arm takes 5-D
actions in [-1, 1]: relative effector xyz (x 0.05 m = 0.5 obs units), relative yaw (x 0.3 rad)
and a relative gripper target (-1 opens fully, +1 closes).
"""

from __future__ import annotations

import numpy as np

from fmctd_dist.envs.cube import ACT_DIM, XYZ_SCALE

EFFECTOR = slice(12, 15)  # effector xyz in the observation (obs units)
STEP_OBS = 0.05 * XYZ_SCALE  # obs units the effector moves for an xyz action of 1
OPEN = -1.0  # gripper action that opens the gripper fully (relative target, clipped to [0, 1])
PRE_STEPS = 30  # steps of moving above the target cube before a new plan
ABOVE = 1.0  # obs units (0.1 m) above the cube's planned position (OGBench's oracle: 0.1-0.2 m)
RELEASE_LIFT = 10  # steps lifting while opening
RELEASE_AWAY = 20  # steps moving away in +x while open
LIFT_SPEED = 0.5  # xyz action while lifting / moving away (0.025 m per step)


def move_action(effector: np.ndarray, target: np.ndarray, gripper: float = OPEN) -> np.ndarray:
    """[5] action moving the effector [3] toward ``target`` [3] (obs units), at most one full step per axis."""
    a = np.zeros(ACT_DIM)
    a[:3] = np.clip((np.asarray(target, np.float64) - np.asarray(effector, np.float64)) / STEP_OBS, -1.0, 1.0)
    a[4] = gripper
    return a


class PrePosition:
    """PRE_STEPS steps steering the open gripper to ABOVE over ``cube_xyz`` [3] (the target cube's first
    planned position), closed loop on the effector."""

    steps = PRE_STEPS

    def __init__(self, cube_xyz: np.ndarray):
        self.target = np.asarray(cube_xyz, np.float64) + np.array([0.0, 0.0, ABOVE])  # [3] obs units

    def act(self, obs: np.ndarray, k: int) -> np.ndarray:
        return move_action(np.asarray(obs)[EFFECTOR], self.target)


class Release:
    """10 steps up while opening, then 20 steps in +x while open (k = step index within the release)."""

    steps = RELEASE_LIFT + RELEASE_AWAY

    def act(self, obs: np.ndarray, k: int) -> np.ndarray:
        a = np.zeros(ACT_DIM)
        a[2 if k < RELEASE_LIFT else 0] = LIFT_SPEED
        a[4] = OPEN
        return a
