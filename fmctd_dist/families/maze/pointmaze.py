"""PointMaze episodes over OGBench's MuJoCo env, with a seeded, documented start/goal protocol.

The protocols (``fixed``, ``ogbench``) are :mod:`fmctd_dist.families.maze.tasks`'s, shared with AntMaze.
Success is OGBench's: within 1.0 of the goal after a step.
"""

from __future__ import annotations

import numpy as np

from fmctd_dist.families.maze.tasks import OGBenchMaze, Reset

GOAL_TOLERANCE = 1.0  # OGBench point success radius


class PointMaze(OGBenchMaze):
    """One PointMaze env. ``reset(task_id, seed)`` then ``step(action) -> (obs, success)``."""

    def reset(self, task_id: int, seed: int) -> Reset:
        start, goal = self.task_start_goal(task_id, seed)
        self._env.action_space.seed(seed)
        self._u.reset(seed=seed, options=dict(task_id=task_id))
        self._u.set_goal(goal_xy=goal)
        self._u.set_xy(start)
        self.goal = goal
        return Reset(self.position(), goal.copy())

    def set_position(self, xy: np.ndarray) -> None:
        self._u.set_xy(np.asarray(xy, dtype=np.float64))

    def position(self) -> np.ndarray:
        return self._u.get_xy().astype(np.float64)

    def step(self, action: np.ndarray) -> tuple[np.ndarray, bool]:
        """Apply one action in [-1, 1]^2; return the new position and OGBench success."""
        self._u.step(np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0))
        pos = self.position()
        return pos, bool(np.linalg.norm(pos - self.goal) <= GOAL_TOLERANCE)
