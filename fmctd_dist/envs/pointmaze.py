"""PointMaze episodes over OGBench's MuJoCo env, with a seeded, documented start/goal protocol.

Protocols (README "Protocol choices"):
- ``fixed`` (default, the paper's customised env): start and goal at the task's cell centres.
- ``ogbench``: stock OGBench noise, uniform in [-1, 1] on start x, y and goal x, y, drawn
  from the episode seed (stock OGBench draws it from numpy's global RNG; we do not).
Success is OGBench's: within 1.0 of the goal after a step.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from fmctd_dist.config import PROTOCOLS
from fmctd_dist.errors import ConfigError, unknown_name

if TYPE_CHECKING:
    from fmctd_dist.envs.antmaze import AntMaze

os.environ.setdefault("MUJOCO_GL", "egl")

GOAL_TOLERANCE = 1.0  # OGBench point success radius
NOISE = 1.0  # OGBench start/goal noise half-width (maze_unit / 4)


def _make_ogbench_env(name: str):
    import ogbench  # deferred: MuJoCo start-up is not free

    return ogbench.make_env_and_datasets(
        f"{name}-navigate-v0", env_only=True, terminate_at_goal=False, add_noise_to_goal=False
    )


def check_seed(seed: object, field: str = "seed") -> int:
    """Gymnasium-style seed check: a non-negative int, else one ConfigError naming the field."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ConfigError(f"{field}={seed!r} must be a non-negative integer (e.g. {field}=0)")
    return int(seed)


@dataclass
class Reset:
    obs: np.ndarray  # start observation: [2] position (PointMaze) | [29] ant state, x, y first (AntMaze)
    goal: np.ndarray  # [2] goal position


class OGBenchMaze:
    """What PointMaze and AntMaze share: the OGBench env, its geometry, and the start/goal protocol."""

    def __init__(self, name: str, protocol: str = "fixed"):
        from fmctd_dist.envs.maze import maze_geometry

        if protocol not in PROTOCOLS:
            raise unknown_name("env.protocol", protocol, PROTOCOLS)
        self.geometry = maze_geometry(name)
        self.name = name
        self.protocol = protocol
        self._env = _make_ogbench_env(name)
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


def make_env(name: str, protocol: str = "fixed") -> "PointMaze | AntMaze":
    """``pointmaze-*`` -> :class:`PointMaze`, ``antmaze-*`` -> :class:`~fmctd_dist.envs.antmaze.AntMaze`."""
    from fmctd_dist.config import is_ant
    from fmctd_dist.envs.maze import check_env_name

    if is_ant(check_env_name(name)):
        from fmctd_dist.envs.antmaze import AntMaze

        return AntMaze(name, protocol)
    return PointMaze(name, protocol)
