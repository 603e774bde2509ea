"""Subgoal schedule for plans executed by a learned goal-conditioned policy (AntMaze §7, cubes §13).

The ant cannot be driven by a PD law on positions; a low-level policy gets the ant state plus
a 2-D subgoal instead (the cube policy: its cube's planned xyz, ``dim=3``). The subgoal is
the plan point ``interval`` steps ahead, moved another ``interval`` along the plan each time
the agent comes within ``radius`` of it, and held at the plan's last point once past the end. Unlike
the PD controller this is closed loop in space, not in time: a slow ant keeps its subgoal until it gets there.
"""

from __future__ import annotations

import numpy as np


class SubgoalTracker:
    """plan: [F, dim] positions (one per env step). ``update(pos)`` -> the current subgoal [dim]."""

    def __init__(self, plan: np.ndarray, interval: int = 10, radius: float = 1.0, dim: int = 2):
        plan = np.asarray(plan, dtype=np.float64)
        if plan.ndim != 2 or plan.shape[1] != dim or len(plan) == 0:
            raise ValueError(f"plan must be [F, {dim}] positions, got shape {plan.shape}")
        if interval < 1 or radius <= 0:
            raise ValueError(f"need interval >= 1 and radius > 0, got interval={interval}, radius={radius}")
        self.plan, self.interval, self.radius = plan, interval, radius
        self.index = min(interval, len(plan) - 1)

    @property
    def subgoal(self) -> np.ndarray:
        return self.plan[self.index]

    @property
    def done(self) -> bool:
        """The subgoal is the plan's last point."""
        return self.index == len(self.plan) - 1

    def update(self, pos: np.ndarray) -> np.ndarray:
        """Call once per env step: advance one ``interval`` if ``pos`` is within ``radius`` of the subgoal."""
        pos = np.asarray(pos, dtype=np.float64)[:self.plan.shape[1]]
        if not self.done and np.linalg.norm(pos - self.plan[self.index]) < self.radius:
            self.index = min(self.index + self.interval, len(self.plan) - 1)
        return self.subgoal
