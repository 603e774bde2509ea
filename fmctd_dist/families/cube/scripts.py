"""The arm's pre-defined plans between cube segments (docs/reference.md §13), as scripted effector actions.

The planner plans cube positions only; between two object segments the authors insert
redundant, hand-written arm motions: before a new plan ~30 steps moving the open gripper
above the target cube's first planned position (so the low-level policy starts from a pose it
knows; with ``env.preposition_yaw`` also turning it face-on to the cube, as OGBench's oracle does,
since the play data's grasps are all face-on), and after a placement a 30-step release (10 steps
lifting while opening, 20 steps moving away in +x while open) so the arm leaves the placed cube alone. The arm takes 5-D
actions in [-1, 1]: relative effector xyz (x 0.05 m = 0.5 obs units), relative yaw (x 0.3 rad)
and a relative gripper target (-1 opens fully, +1 closes).
"""

from __future__ import annotations

import numpy as np

from fmctd_dist.families.cube.env import ACT_DIM, ARM_DIM, CUBE_OBS, XYZ_SCALE

EFFECTOR = slice(12, 15)  # effector xyz in the observation (obs units)
EFFECTOR_YAW = slice(15, 17)  # effector yaw cos, sin
CUBE_YAW = 7  # a cube's yaw cos, sin: obs columns ARM_DIM + CUBE_OBS * i + 7, + 8
YAW_STEP = 0.3  # rad the effector turns for a yaw action of 1 (OGBench's action range)
QUARTER = np.pi / 2  # a cube looks the same turned by 90 degrees
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


def yaw_offset(obs: np.ndarray, cube: int) -> float:
    """Radians in [-pi/4, pi/4) the effector must turn to face cube ``cube``: the shortest turn to the cube's
    yaw mod 90 degrees (OGBench's ``shortest_yaw`` with n=4)."""
    obs = np.asarray(obs, np.float64)
    eff = np.arctan2(obs[EFFECTOR_YAW][1], obs[EFFECTOR_YAW][0])
    col = ARM_DIM + CUBE_OBS * cube + CUBE_YAW
    box = np.arctan2(obs[col + 1], obs[col])
    return float((box - eff + QUARTER / 2) % QUARTER - QUARTER / 2)


class PrePosition:
    """PRE_STEPS steps steering the open gripper to ABOVE over ``cube_xyz`` [3] (the target cube's first
    planned position), closed loop on the effector; with ``turn_to`` (a cube index) it also turns the
    gripper to that cube's yaw, closed loop on both yaws (None: the authors' rule, yaw action 0)."""

    steps = PRE_STEPS

    def __init__(self, cube_xyz: np.ndarray, turn_to: int | None = None):
        self.target = np.asarray(cube_xyz, np.float64) + np.array([0.0, 0.0, ABOVE])  # [3] obs units
        self.turn_to = turn_to

    def act(self, obs: np.ndarray, k: int) -> np.ndarray:
        a = move_action(np.asarray(obs)[EFFECTOR], self.target)
        if self.turn_to is not None:
            a[3] = np.clip(yaw_offset(obs, self.turn_to) / YAW_STEP, -1.0, 1.0)
        return a


class Release:
    """10 steps up while opening, then 20 steps in +x while open (k = step index within the release)."""

    steps = RELEASE_LIFT + RELEASE_AWAY

    def act(self, obs: np.ndarray, k: int) -> np.ndarray:
        a = np.zeros(ACT_DIM)
        a[2 if k < RELEASE_LIFT else 0] = LIFT_SPEED
        a[4] = OPEN
        return a
