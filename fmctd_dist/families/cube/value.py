"""Cube plan value (docs/reference.md §13): place cubes on their goals, physically plausibly.

A plan is N cubes' xyz per frame in obs units ([B, F, 3N]; table z = 0.2, one stack level 0.4).
The rules, in the order they apply:

- **single-object movement**: the authors guide one cube and overwrite the other cubes with
  their current (start) positions, so the plan moves only the guided cube. :meth:`CubeValue.prepare`
  does that from each job's action mask before anything is scored, and the returned plan is
  the pinned one (what the controller follows).
- **warp**: value 0 if any step moves any cube more than ``warp_threshold`` (1.0 dense, 2.0
  sparse) before the frame that ends the plan (as the maze: a warp after the goal is harmless).
  The first step is from the observed cubes to the plan's first frame; ``start_tol`` > 0 (ours,
  off by default) holds that step to a tighter bound, because a plan that starts away from the
  cubes sends the arm to an empty spot (docs/results.md 12.8).
- **placed** at frame t: within ``goal_tol`` (0.15) of its goal AND supported (table under it,
  |z - 0.2| < ``support_tol``, or another cube one level below, |dz - 0.4| < ``support_tol`` and
  xy within ``stack_xy``: not mid-air) AND its goal not occupied by another cube (another
  cube's centre within ``occupied_tol`` < one cube width of the goal) AND it is not a cube that
  had another cube on it at the plan's start and has left its start (moving a covered cube:
  read this way so the bottom cube of a finished stack, covered but unmoved, still counts).
- **value**: full success (every cube placed) first at scanned frame t: (H - t) / H, H the
  scanned length (the last frame is a dummy, as the maze); otherwise 0.1 per cube placed at
  the plan's end (status PARTIAL when > 0).
- **replanning** mode: the first frame at which a cube that was not placed at the start becomes
  placed ends the plan: status ACHIEVED (the search's early stop), reach_t = that frame, value
  (H - t) / H if that completes the task, else 0.1 per cube placed then; :meth:`output` returns
  the plan truncated there.

The denoiser-quality table (jobs/bench/plan_quality.py) reads its tolerances from here, so it
measures what the value will demand.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fmctd_dist.search.actions import Actions
from fmctd_dist.search.value import ACHIEVED, NOT_REACHED, WARP

PARTIAL = 3  # not every cube placed; value 0.1 per cube placed at the plan's end

TABLE_Z = 0.2  # obs units: centre height of a cube resting on the table
LEVEL = 0.4  # obs units: one stack level (cube width 0.04 m x 10)
PER_CUBE = 0.1  # partial-success value per placed cube


@dataclass(frozen=True)
class CubeValue:
    """The cube value rules (see the module docstring); obs units throughout."""

    warp_threshold: float = 1.0  # 1.0 dense, 2.0 sparse (H = 5)
    replanning: bool = True  # the first newly placed cube ends the plan
    goal_tol: float = 0.15  # a cube within this of its goal is there
    support_tol: float = 0.15  # |z - support height| still resting (table or one level up)
    stack_xy: float = 0.3  # xy offset of a cube still resting on the one below (width 0.4)
    occupied_tol: float = 0.3  # another cube's centre this close to a goal occupies it (< one level)
    start_tol: float = 0.0  # > 0: the first frame's step from the observed cubes is a warp above this (ours)

    # ------------------------------------------------------------ the rules on single states

    def placed(self, pos: np.ndarray, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """[..., N] bool: cube i counts as placed in state ``pos`` [..., N, 3] (start/goal [N, 3])."""
        near = np.linalg.norm(pos - goal, axis=-1) < self.goal_tol  # [..., N]
        n = pos.shape[-2]
        other = ~np.eye(n, dtype=bool)  # [i, j]: j is another cube
        on_table = np.abs(pos[..., 2] - TABLE_Z) < self.support_tol
        dxy = np.linalg.norm(pos[..., :, None, :2] - pos[..., None, :, :2], axis=-1)  # [..., i, j]
        dz = pos[..., :, None, 2] - pos[..., None, :, 2]  # z_i - z_j
        on_cube = ((dxy < self.stack_xy) & (np.abs(dz - LEVEL) < self.support_tol) & other).any(-1)
        to_goal = np.linalg.norm(pos[..., None, :, :] - goal[:, None, :], axis=-1)  # [..., i, j]: |p_j - g_i|
        occupied = ((to_goal < self.occupied_tol) & other).any(-1)
        moved = np.linalg.norm(pos - start, axis=-1) > self.goal_tol
        return near & (on_table | on_cube) & ~occupied & ~(self.covered(start) & moved)

    def covered(self, start: np.ndarray) -> np.ndarray:
        """[N] bool: another cube rests on cube i in the start state [N, 3]."""
        n = start.shape[0]
        dxy = np.linalg.norm(start[None, :, :2] - start[:, None, :2], axis=-1)  # [i, j]
        dz = start[None, :, 2] - start[:, None, 2]  # z_j - z_i
        return ((dxy < self.stack_xy) & (np.abs(dz - LEVEL) < self.support_tol) & ~np.eye(n, dtype=bool)).any(1)

    def unsolved(self, start: np.ndarray, goal: np.ndarray) -> list[int]:
        """Cubes not placed in the start state [3N]: the objects to build the tree's actions from."""
        s, g = cubes(start), cubes(goal)
        return [int(i) for i in np.flatnonzero(~self.placed(s, s, g))]

    # ------------------------------------------------------------ the PlanValue protocol

    def prepare(self, plans: np.ndarray, start: np.ndarray, actions: Actions) -> np.ndarray:
        """Overwrite the dims a job's action does not guide with the start (single-object movement)."""
        if actions.mask is None:
            return plans
        keep = actions.mask[:, None, :] > 0  # [B, 1, 3N]
        s = np.asarray(start, plans.dtype)[None, None]
        return np.where(keep, plans, s).astype(plans.dtype)

    def values(self, plans: np.ndarray, start: np.ndarray, goal: np.ndarray,
               actions: Actions) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """values [B] float64, status [B] int8, reach_t [B] int64 of prepared plans [B, F, 3N]."""
        s, g = cubes(start), cubes(goal)  # [N, 3]
        p = cubes(np.asarray(plans, np.float64)[:, :-1])  # [B, H, N, 3], last frame is the dummy
        b, h, n = p.shape[0], p.shape[1], s.shape[0]
        if h == 0:
            return np.zeros(b), np.full(b, NOT_REACHED, np.int8), np.full(b, -1, np.int64)
        prev = np.concatenate([np.broadcast_to(s, (b, 1, n, 3)), p[:, :-1]], axis=1)
        limit = np.full(h, self.warp_threshold)
        if self.start_tol > 0:
            limit[0] = min(self.warp_threshold, self.start_tol)
        warp = (np.linalg.norm(p - prev, axis=-1) > limit[None, :, None]).any(-1)  # [B, H]
        placed = self.placed(p, s, g)  # [B, H, N]
        done = placed.all(-1)  # [B, H]
        ends = (placed & ~self.placed(s, s, g)).any(-1) if self.replanning else done  # [B, H]
        first_end = np.where(ends.any(1), ends.argmax(1), h)  # [B], h = never
        first_warp = np.where(warp.any(1), warp.argmax(1), h)
        achieved = first_end < first_warp
        warped = ~achieved & (first_warp < h)
        t = np.minimum(first_end, h - 1)
        rows = np.arange(b)
        count = np.where(achieved, placed[rows, t].sum(-1), placed[:, -1].sum(-1))  # [B]
        full = np.where(achieved, done[rows, t], False)
        values = np.where(full, (h - first_end) / h, PER_CUBE * count)
        values = np.where(warped, 0.0, values)
        partial = ~achieved & ~warped & (values > 0)
        status = np.select([achieved, warped, partial], [ACHIEVED, WARP, PARTIAL], NOT_REACHED).astype(np.int8)
        reach_t = np.where(achieved, first_end, -1).astype(np.int64)
        return values.astype(np.float64), status, reach_t

    def output(self, plan: np.ndarray, reach_t: int, goal: np.ndarray) -> np.ndarray:
        """Frames 0..reach_t (the frame that ended the plan), else every frame but the dummy."""
        plan = np.asarray(plan)
        return (plan[: reach_t + 1] if reach_t >= 0 else plan[:-1]).astype(np.float32)


def cubes(x: np.ndarray) -> np.ndarray:
    """[..., 3N] -> [..., N, 3] float64."""
    x = np.asarray(x, np.float64)
    assert x.shape[-1] % 3 == 0, f"cube states have 3 numbers per cube, got {x.shape[-1]}"
    return x.reshape(*x.shape[:-1], -1, 3)
