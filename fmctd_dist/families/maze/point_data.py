"""PointMaze navigate data: the noisy BFS oracle's own actions (OGBench's pointmaze navigate recipe).

The layout, manifest and verification are :mod:`fmctd_dist.families.maze.data`'s (shared with the
ant); the start / goal draws and the episode loop are :mod:`fmctd_dist.families.maze.navigate`'s.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from fmctd_dist.config import Config
from fmctd_dist.families.maze.navigate import Episode, random_goal, random_start, run_episodes
from fmctd_dist.families.maze.oracle import NoisyOracle
from fmctd_dist.families.maze.geometry import MazeGeometry
from fmctd_dist.families.maze.pointmaze import GOAL_TOLERANCE, PointMaze

POINT_GENERATOR_VERSION = 1


def generate_episode(env: PointMaze, oracle: NoisyOracle, steps: int,
                     rng: np.random.Generator) -> dict[str, np.ndarray]:
    """One navigate episode: random start cell, random vertex goal, a new goal on each success."""
    geo: MazeGeometry = env.geometry
    start = random_start(geo, rng)
    goal = random_goal(geo, rng)
    env.set_position(start)
    pos = env.position()
    obs = np.empty((steps, 2), np.float32)
    act = np.empty((steps, 2), np.float32)
    goals = np.empty((steps, 2), np.float32)
    for t in range(steps):
        a = oracle.act(pos, goal, rng)
        obs[t], act[t], goals[t] = pos, a, goal
        env.goal = goal
        pos, success = env.step(a)
        if success:
            goal = random_goal(geo, rng)
    return {"observations": obs, "actions": act, "goals": goals}


def point_episodes(cfg: Config) -> tuple[Episode, Callable[[], None]]:
    """The episode function (one env and oracle per process) and the env's close."""
    env = PointMaze(cfg.env.name)
    env.reset(1, cfg.data.seed)  # initialise MuJoCo state; positions are then set per episode
    oracle = NoisyOracle(env.geometry, cfg.data.noise)
    return (lambda rng: generate_episode(env, oracle, cfg.data.episode_steps, rng)), env.close


def generate_split(cfg: Config, split: str, episodes: int, progress: bool = True) -> dict[str, np.ndarray]:
    return run_episodes(cfg, split, episodes, point_episodes, progress)


class PointSource:
    """PointMaze data source for :func:`fmctd_dist.families.maze.data.make_dataset`."""

    version = POINT_GENERATOR_VERSION

    def __init__(self, cfg: Config):
        self.cfg = cfg

    def generate(self, split: str, episodes: int, progress: bool) -> dict[str, np.ndarray]:
        return generate_split(self.cfg, split, episodes, progress)

    def manifest_fields(self) -> dict[str, Any]:
        return {"oracle": "BFS next-cell direction + N(0, noise^2), clipped; new vertex-cell goal on success "
                          f"(within {GOAL_TOLERANCE})",
                "keys": ["observations", "actions", "goals", "terminals"]}
