"""The plan value as a plug-in of the one search loop (mazes by default, cubes beside them).

The loop never asks which env family it serves (docs/design.md §13): it hands decoded plans and each
job's action to a :class:`PlanValue` and uses what comes back for the tree's values, the
early-stop test and the returned plan. :class:`MazeValue` wraps :func:`value.plan_values`
unchanged, so a maze search with the default rule is the search it was before the rule was
pluggable (golden trees unchanged).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from fmctd_dist.search.actions import Actions
from fmctd_dist.search.value import plan_values, truncate_at_goal


@runtime_checkable
class PlanValue(Protocol):
    """How a family scores plans. Statuses are value.py's (ACHIEVED = stop-worthy), plus any
    family-specific ones >= 0; a plan with status ACHIEVED or a value > 0 is a fallback candidate."""

    def prepare(self, plans: np.ndarray, start: np.ndarray, actions: Actions) -> np.ndarray:
        """[B, F, d] plans as the controller would follow them (e.g. pin the un-guided objects).

        Runs before the bad-plan test and the scoring; may return ``plans`` itself."""
        ...

    def values(self, plans: np.ndarray, start: np.ndarray, goal: np.ndarray,
               actions: Actions) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Prepared plans [B, F, d], start/goal [d], per-job actions -> values [B] float64,
        status [B] int8, reach_t [B] int64 (the frame that ends the plan; -1 = none)."""
        ...

    def output(self, plan: np.ndarray, reach_t: int, goal: np.ndarray) -> np.ndarray:
        """[F', d] float32 waypoints handed out for one prepared plan [F, d] (reach_t -1: whole plan)."""
        ...


@dataclass(frozen=True)
class MazeValue:
    """docs/reference.md §4: reach within ``goal_radius`` early, no step over ``warp_threshold`` (world units).

    ``crosses_wall`` (method.wall_test; not the paper's): [B, F + 1, 2] paths, start first ->
    [B, F] bool, step t crosses a wall; such a step counts as a warp. The env hands it in (the
    maze's cells), so the search never learns what a wall is.
    """

    warp_threshold: float = 2.0
    goal_radius: float = 2.0
    crosses_wall: Callable[[np.ndarray], np.ndarray] | None = None

    def prepare(self, plans: np.ndarray, start: np.ndarray, actions: Actions) -> np.ndarray:
        return plans  # one agent, every dim guided: nothing to pin

    def values(self, plans: np.ndarray, start: np.ndarray, goal: np.ndarray,
               actions: Actions) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        blocked = None
        if self.crosses_wall is not None:
            head = np.asarray(plans, np.float64)[:, :-1]  # the frames plan_values scans
            lead = np.broadcast_to(np.asarray(start, np.float64), (head.shape[0], 1, head.shape[2]))
            blocked = self.crosses_wall(np.concatenate([lead, head], axis=1))
        return plan_values(plans, start, goal, self.warp_threshold, self.goal_radius, blocked)

    def output(self, plan: np.ndarray, reach_t: int, goal: np.ndarray) -> np.ndarray:
        """Reached: frames up to the reach, then the goal as final waypoint; else every frame but the dummy."""
        if reach_t >= 0:
            return truncate_at_goal(plan, reach_t, goal)
        return np.asarray(plan)[:-1].astype(np.float32)  # a copy: the caller may reuse its array
