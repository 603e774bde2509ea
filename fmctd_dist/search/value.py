"""Maze plan value (docs/reference.md §4): reach the goal early, without teleporting.

MCTD scores a fully denoised plan by how early it comes within ``goal_radius`` of the goal,
and gives 0 to plans that jump further than ``warp_threshold`` in one frame before getting
there (a learned model can "teleport" through walls; there is no wall check). Works in
world units on a batch of plans at once.
"""

from __future__ import annotations

import numpy as np

NOT_REACHED = 0  # never within goal_radius, no warp before the end: value 0
ACHIEVED = 1  # within goal_radius at reach_t with no warp up to and including reach_t
WARP = 2  # a step longer than warp_threshold (or, with a wall test, through a wall) before reaching: value 0


def plan_values(plans: np.ndarray, start: np.ndarray, goal: np.ndarray, warp_threshold: float, goal_radius: float = 2.0,
                blocked: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Score plans [B, F, d] (world units) from ``start`` [d] towards ``goal`` [d].

    ``blocked`` [B, F'] bool (optional; not the paper's): the step at t crosses a wall. Such a step
    counts as a warp, so a plan through a wall is worth 0 like one that teleports.

    The last frame is dropped as a dummy; frames t = 0..F'-1 (F' = F - 1) are scanned.
    The step at t is |p_0 - start| for t = 0, else |p_t - p_{t-1}|. At each t the warp
    test runs before the reach test (a warp at the reach frame is a warp).
    Value of an ACHIEVED plan = (F' - reach_t) / F' (F' = scanned length, see docs).

    Returns values [B] float64, status [B] int8, reach_t [B] int64 (-1 unless ACHIEVED).
    """
    p = np.asarray(plans, np.float64)[:, :-1]  # [B, F', d]
    b, f = p.shape[0], p.shape[1]
    start = np.asarray(start, np.float64)
    goal = np.asarray(goal, np.float64)
    if f == 0:
        return np.zeros(b), np.full(b, NOT_REACHED, np.int8), np.full(b, -1, np.int64)
    prev = np.concatenate([np.broadcast_to(start, (b, 1, p.shape[2])), p[:, :-1]], axis=1)  # [B, F', d]
    steps = np.linalg.norm(p - prev, axis=-1)  # [B, F']
    near = np.linalg.norm(p - goal, axis=-1) < goal_radius  # [B, F']
    warp = steps > warp_threshold  # [B, F']
    if blocked is not None:
        warp = warp | np.asarray(blocked, bool)[:, :f]
    first_near = np.where(near.any(1), near.argmax(1), f)  # [B], f = never
    first_warp = np.where(warp.any(1), warp.argmax(1), f)  # [B]
    achieved = first_near < first_warp
    warped = ~achieved & (first_warp < f)
    status = np.where(achieved, ACHIEVED, np.where(warped, WARP, NOT_REACHED)).astype(np.int8)
    reach_t = np.where(achieved, first_near, -1).astype(np.int64)
    values = np.where(achieved, (f - first_near) / f, 0.0)
    return values, status, reach_t


def barely_moves(plans: np.ndarray, min_step: float = 0.1) -> np.ndarray:
    """[B] bool: every consecutive step of the plan [B, F, d] is shorter than ``min_step``.

    Such plans are degenerate samples ("stay put") that MCTD re-samples.
    """
    p = np.asarray(plans, np.float64)
    steps = np.linalg.norm(p[:, 1:] - p[:, :-1], axis=-1)  # [B, F-1]
    return np.all(steps < min_step, axis=1)


def truncate_at_goal(plan: np.ndarray, reach_t: int, goal: np.ndarray) -> np.ndarray:
    """[reach_t + 2, d] float32: plan frames 0..reach_t, then the goal as final waypoint."""
    head = np.asarray(plan[: reach_t + 1], np.float32)
    return np.concatenate([head, np.asarray(goal, np.float32)[None]], axis=0)
