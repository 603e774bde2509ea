"""PD waypoint controller for PointMaze (docs/reference.md §7).

At env step t the target is waypoint t (the last one once the plan is exhausted):
a = clip(kp (p_t - pos) + kd (v_plan - vel), -1, 1), v_plan = p_t - p_{t-1} (p_0 - pos at t=0).
Stock OGBench observations are 2-D positions, so ``vel`` is the finite difference of the
last two observed positions (the authors' customised env exposed it directly).
"""

from __future__ import annotations

import numpy as np


class PDController:
    """Follows a dense waypoint sequence one waypoint per env step, open loop in time."""

    def __init__(self, plan: np.ndarray, kp: float = 12.5, kd: float = 1.2):
        assert plan.ndim == 2 and plan.shape[1] == 2 and len(plan) > 0, f"plan must be [F, 2], got {plan.shape}"
        self.plan = np.asarray(plan, dtype=np.float64)
        self.kp, self.kd = kp, kd
        self.t = 0
        self._prev_pos: np.ndarray | None = None

    def act(self, pos: np.ndarray) -> np.ndarray:
        """Action for the current position; advances the waypoint clock by one step."""
        pos = np.asarray(pos, dtype=np.float64)
        last = len(self.plan) - 1
        target = self.plan[min(self.t, last)]
        previous = self.plan[min(self.t, last) - 1] if self.t > 0 else pos
        v_plan = target - previous if self.t <= last else np.zeros(2)
        vel = pos - self._prev_pos if self._prev_pos is not None else np.zeros(2)
        self._prev_pos = pos
        self.t += 1
        return np.clip(self.kp * (target - pos) + self.kd * (v_plan - vel), -1.0, 1.0)
