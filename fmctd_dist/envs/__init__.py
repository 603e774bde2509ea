"""PointMaze and AntMaze environments over OGBench (env_only: no network), maze geometry and BFS; the cubes.

Layering (no module imports one above it): ``seeding``, ``maze`` (geometry, the OGBench env)
-> ``maze_episodes`` (start/goal protocol) -> ``pointmaze``, ``antmaze`` -> ``make``;
``cube`` and ``visual_pointmaze`` are families of their own beside them.
"""

from fmctd_dist.envs.make import make_env
from fmctd_dist.envs.maze import MazeGeometry, maze_geometry
from fmctd_dist.envs.pointmaze import PointMaze

__all__ = ["MazeGeometry", "maze_geometry", "PointMaze", "make_env"]
