"""Why a cube episode failed, read off its trajectory (the robot table's failure analysis, issue 20).

The reasons, first that applies wins (obs units: table z 0.2, stack level 0.4, success radius 0.4):

- ``planning time out``: the planner used up ``eval.episode_time_limit``;
- ``stack knocked over``: a cube that rested on another cube ended on the table away from its
  goal without having been the policy's target since it rested there;
- ``wrong cube``: a cube the policy never targeted moved more than 0.4 from its start, or a cube
  that reached its goal was pushed off it while another cube was the target;
- ``dropped``: a target cube was lifted (z > 0.5, not resting on a cube) and came down on the
  table away from its goal;
- ``time out``: none of these, the env steps ran out (too slow, or stuck).
"""

from __future__ import annotations

import numpy as np

from fmctd_dist.families.cube.env import SUCCESS_RADIUS
from fmctd_dist.families.cube.value import LEVEL, TABLE_Z

REST_TOL = 0.15  # |z - support height| still resting
STACK_XY = 0.3  # xy offset of a cube still resting on the one below
LIFTED_Z = TABLE_Z + 0.3  # a cube above this, not on a cube, is in the gripper

PLANNING_TIME_OUT = "planning time out"
KNOCKED = "stack knocked over"
WRONG_CUBE = "wrong cube"
DROPPED = "dropped"
TIME_OUT = "time out"
REASONS = (PLANNING_TIME_OUT, KNOCKED, WRONG_CUBE, DROPPED, TIME_OUT)


def on_cube(cubes: np.ndarray) -> np.ndarray:
    """[T, N] bool: cube i rests on another cube at frame t (cubes [T, N, 3])."""
    dxy = np.linalg.norm(cubes[:, :, None, :2] - cubes[:, None, :, :2], axis=-1)  # [T, i, j]
    dz = cubes[:, :, None, 2] - cubes[:, None, :, 2]
    other = ~np.eye(cubes.shape[1], dtype=bool)
    return ((dxy < STACK_XY) & (np.abs(dz - LEVEL) < REST_TOL) & other).any(-1)


def why_failed(cubes: np.ndarray, targets: np.ndarray, goal: np.ndarray, success: bool, timed_out: bool) -> str:
    """cubes [T+1, N, 3] (frame 0 = start), targets [T] (the policy's cube per step, -1 = scripted arm
    motion), goal [N, 3] -> "" on success, else one of :data:`REASONS`."""
    if success:
        return ""
    if timed_out:
        return PLANNING_TIME_OUT
    cubes = np.asarray(cubes, np.float64)
    targets = np.asarray(targets, np.int64)
    goal = np.asarray(goal, np.float64).reshape(cubes.shape[1], 3)
    n = cubes.shape[1]
    target_at = np.concatenate([[-1], targets])  # [T+1]: the target of the step that led to frame t
    stacked = on_cube(cubes)  # [T+1, N]
    table = np.abs(cubes[..., 2] - TABLE_Z) < REST_TOL
    away = np.linalg.norm(cubes - goal, axis=-1) > SUCCESS_RADIUS  # [T+1, N]
    for i in range(n):
        rested = np.flatnonzero(stacked[:, i])
        if rested.size and table[-1, i] and away[-1, i] and not (target_at[rested[-1]:] == i).any():
            return KNOCKED
    for i in range(n):
        moved = np.linalg.norm(cubes[:, i] - cubes[0, i], axis=-1).max() > SUCCESS_RADIUS
        pushed_off = (~away[:-1, i] & away[1:, i] & (target_at[1:] >= 0) & (target_at[1:] != i)).any()
        if (moved and not (targets == i).any()) or pushed_off:
            return WRONG_CUBE
    for i in range(n):
        lifted = np.flatnonzero((cubes[:, i, 2] > LIFTED_Z) & ~stacked[:, i])
        if lifted.size and (table[lifted[0]:, i] & away[lifted[0]:, i]).any():
            return DROPPED
    return TIME_OUT
