"""PointMaze and AntMaze environments over OGBench (env_only: no network), maze geometry and BFS."""

from fmctd_dist.envs.maze import MazeGeometry, maze_geometry
from fmctd_dist.envs.pointmaze import PointMaze, make_env

__all__ = ["MazeGeometry", "maze_geometry", "PointMaze", "make_env"]
