"""``make_env(name)``: the maze env class for an env name (the one place that knows both robots)."""

from __future__ import annotations

from fmctd_dist.config import is_ant
from fmctd_dist.families.maze.antmaze import AntMaze
from fmctd_dist.families.maze.geometry import check_env_name
from fmctd_dist.families.maze.pointmaze import PointMaze


def make_env(name: str, protocol: str = "fixed") -> PointMaze | AntMaze:
    """``pointmaze-*`` -> :class:`PointMaze`, ``antmaze-*`` -> :class:`AntMaze`; any other name is one ConfigError."""
    if is_ant(check_env_name(name)):
        return AntMaze(name, protocol)
    return PointMaze(name, protocol)
