"""OGBench's PointMaze navigate oracle: head for the next BFS cell, plus Gaussian noise.

Direction = unit vector from the agent to the centre of the neighbouring free cell with the
smaller BFS distance to the goal cell (the goal itself once in the goal cell); action =
direction + N(0, noise^2) per dimension, clipped to [-1, 1] (docs/reference.md §9).
"""

from __future__ import annotations

import numpy as np

from fmctd_dist.families.maze.geometry import MazeGeometry


class NoisyOracle:
    def __init__(self, geometry: MazeGeometry, noise: float = 0.5):
        self.geometry = geometry
        self.noise = noise

    def subgoal(self, pos: np.ndarray, goal: np.ndarray) -> np.ndarray:
        cell, goal_cell = self.geometry.xy_to_cell(pos), self.geometry.xy_to_cell(goal)
        if cell == goal_cell:
            return np.asarray(goal, dtype=np.float64)
        return self.geometry.cell_to_xy(self.geometry.next_cell(cell, goal_cell))

    def direction(self, pos: np.ndarray, goal: np.ndarray) -> np.ndarray:
        d = self.subgoal(pos, goal) - pos
        return d / (np.linalg.norm(d) + 1e-6)

    def act(self, pos: np.ndarray, goal: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        a = self.direction(pos, goal) + rng.normal(0.0, self.noise, size=2)
        return np.clip(a, -1.0, 1.0)
