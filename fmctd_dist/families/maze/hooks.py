"""Maze hooks (PointMaze, AntMaze): guidance scales + the reach value; PD or ant-policy episodes.

The actions and value are exactly what the search used before they were handed in
(``scale_actions(method.guidance_scales)``, ``MazeValue(warp_threshold, goal_radius)``), so maze
batches, trees and plans are bitwise those of the old defaults.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fmctd_dist.config import Config
from fmctd_dist.planners.base import Planner
from fmctd_dist.search.actions import Actions, scale_actions
from fmctd_dist.search.value_rule import MazeValue, PlanValue


@dataclass(frozen=True)
class MazeRules:
    """Guidance scales as the tree's children and one plan value; the visual maze reuses it with its value."""

    scales: tuple[float, ...]  # the tree's guidance scales (method.guidance_scales)
    fixed_scale: float  # method.guidance_scale of planners without search
    value: PlanValue  # MazeValue here; VisualValue (estimated positions) for the visual maze

    def tree(self, start: np.ndarray, goal: np.ndarray) -> tuple[Actions, PlanValue]:
        return scale_actions(self.scales), self.value

    def fixed(self, start: np.ndarray, goal: np.ndarray) -> tuple[Actions, PlanValue]:
        return scale_actions([self.fixed_scale]), self.value


def plan_rules(cfg: Config) -> MazeRules:
    m = cfg.method
    crosses_wall = None
    if m.wall_test:  # not the paper's: the maze's cells say which steps cross a wall
        from fmctd_dist.families.maze.geometry import maze_geometry

        crosses_wall = maze_geometry(cfg.env.name).steps_cross_wall
    return MazeRules(tuple(float(s) for s in m.guidance_scales), float(m.guidance_scale),
                     MazeValue(float(m.warp_threshold), float(m.goal_radius), crosses_wall))


def guide_map(cfg: Config, manifest: dict[str, Any]):
    """The denoiser's guide map: None (the paper's guidance), or with ``method.wall_guidance`` > 0 the wall
    term (``maze/wall_guide.py``)."""
    if cfg.method.wall_guidance <= 0:
        return None
    from fmctd_dist.families.maze.wall_guide import wall_guide

    return wall_guide(cfg.env.name, manifest, cfg.method.wall_guidance, cfg.method.wall_margin)


def check_episodes(cfg: Config) -> str:
    from fmctd_dist.families.maze.robots import check_controller

    manifest = check_controller(cfg)  # AntMaze: the low-level policy exists and was trained for this maze
    return str(manifest.get("digest", "")) if manifest else ""


class MazeEpisodes:
    """The maze env + its controller factory, built once; :func:`evaluation.episode.run_episode` per episode."""

    def __init__(self, cfg: Config):
        from fmctd_dist.families.maze.make import make_env
        from fmctd_dist.families.maze.robots import controller_factory

        self.cfg = cfg
        self.env = make_env(cfg.env.name, cfg.env.protocol)
        self.policy_digest = check_episodes(cfg)  # the ant policy the factory loads (its sha256 is checked there)
        self.make_controller = controller_factory(cfg)

    def run(self, planner: Planner, task: int, seed: int) -> dict[str, Any]:
        from fmctd_dist.families.maze.episode import run_episode

        return run_episode(self.cfg, self.env, planner, task, seed, make_controller=self.make_controller)


def episodes(cfg: Config) -> MazeEpisodes:
    return MazeEpisodes(cfg)


def plot_episode(row: dict[str, Any], path: Path) -> Path:
    """The first plan and the executed trajectory on the maze."""
    from fmctd_dist.families.maze.geometry import maze_geometry
    from fmctd_dist.families.maze.plots import plot_episode as plot_maze_episode

    return plot_maze_episode(row, maze_geometry(row["env"]), path)
