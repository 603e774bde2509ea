"""What PointMaze and AntMaze episodes share: the OGBench env, its geometry, and the start/goal protocol.

Protocols (README "Protocol choices"):
- ``fixed`` (default, the paper's customised env): start and goal at the task's cell centres.
- ``ogbench``: stock OGBench noise, uniform in [-1, 1] on start x, y and goal x, y, drawn
  from the episode seed (stock OGBench draws it from numpy's global RNG; we do not).

Each robot's module (``pointmaze.py``, ``antmaze.py``) subclasses :class:`OGBenchMaze`; this
module sits below both so neither imports the other.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fmctd_dist.config import PROTOCOLS
from fmctd_dist.families.maze.geometry import make_navigate_env, maze_geometry
from fmctd_dist.seeding import check_seed
from fmctd_dist.errors import unknown_name

NOISE = 1.0  # OGBench start/goal noise half-width (maze_unit / 4)


@dataclass
class Reset:
    obs: np.ndarray  # start observation: [2] position (PointMaze) | [29] ant state, x, y first (AntMaze)
    goal: np.ndarray  # [2] goal position


class OGBenchMaze:
    """What PointMaze and AntMaze share: the OGBench env, its geometry, and the start/goal protocol."""

    def __init__(self, name: str, protocol: str = "fixed"):
        if protocol not in PROTOCOLS:
            raise unknown_name("env.protocol", protocol, PROTOCOLS)
        self.geometry = maze_geometry(name)
        self.name = name
        self.protocol = protocol
        self._env = make_navigate_env(name)
        self._u = self._env.unwrapped
        self.goal = np.zeros(2)

    def task_start_goal(self, task_id: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
        """Task ``task_id`` (1..5): start/goal at its cell centres (``fixed``) or with seeded +-1 noise."""
        seed = check_seed(seed)
        task = self.geometry.task(task_id)
        start, goal = task.init_xy.copy(), task.goal_xy.copy()
        if self.protocol == "ogbench":
            noise = np.random.default_rng(np.random.SeedSequence([seed, task_id])).uniform(-NOISE, NOISE, size=4)
            start, goal = start + noise[:2], goal + noise[2:]
        return start, goal

    def close(self) -> None:
        self._env.close()
