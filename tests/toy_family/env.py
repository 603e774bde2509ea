"""The toy env: a point on an open plane that moves by its action (clipped to 0.2 a step)."""

from __future__ import annotations

import numpy as np

TASKS = {1: ((1.0, 1.0), (6.0, 6.0)), 2: ((6.0, 1.0), (1.0, 6.0))}  # task -> (start, goal)
STEP = 0.2


class Plane:
    def reset(self, task: int) -> tuple[np.ndarray, np.ndarray]:
        start, goal = TASKS[task]
        self.pos, self.goal = np.array(start, np.float64), np.array(goal, np.float64)
        return self.pos.copy(), self.goal.copy()

    def step(self, action: np.ndarray) -> tuple[np.ndarray, bool]:
        move = np.asarray(action, np.float64)
        norm = np.linalg.norm(move)
        self.pos = np.clip(self.pos + (move if norm <= STEP else move * STEP / norm), 0.0, 8.0)
        return self.pos.copy(), bool(np.linalg.norm(self.pos - self.goal) < 1.0)
