"""Maze geometry: cells <-> world xy, free cells, BFS distances, the 5 evaluation tasks.

The map and tasks are read from OGBench's own env (so they can never drift from the
benchmark); everything else is plain numpy so the oracle, the value function and the
plots can use it without MuJoCo stepping.
"""

from __future__ import annotations

import os
from collections import deque
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from fmctd_dist.config import TASK_IDS
from fmctd_dist.errors import ConfigError
from fmctd_dist.families.maze.record import MAZE_KINDS
from fmctd_dist.registry import require_family

MAZE_UNIT = 4.0
OFFSET = 4.0  # OGBench: cell (i, j) centre = (4j - 4, 4i - 4)
UNREACHABLE = -1
NEIGHBOURS = ((-1, 0), (0, -1), (1, 0), (0, 1))  # OGBench's BFS order

os.environ.setdefault("MUJOCO_GL", "egl")


def make_navigate_env(name: str):
    """OGBench's ``<name>-navigate-v0`` env only (no dataset download), goal not terminating, no goal noise."""
    import ogbench  # deferred: MuJoCo start-up is not free

    return ogbench.make_env_and_datasets(
        f"{name}-navigate-v0", env_only=True, terminate_at_goal=False, add_noise_to_goal=False
    )


@dataclass(frozen=True)
class Task:
    task_id: int
    init_ij: tuple[int, int]
    goal_ij: tuple[int, int]
    init_xy: np.ndarray  # [2]
    goal_xy: np.ndarray  # [2]


@dataclass
class MazeGeometry:
    """One maze layout. ``walls[i, j]`` is 1 for a wall cell (row i = y, column j = x)."""

    name: str
    walls: np.ndarray  # [rows, cols] int
    tasks: tuple[Task, ...]
    _bfs_cache: dict = field(default_factory=dict, repr=False)

    @property
    def shape(self) -> tuple[int, int]:
        return self.walls.shape  # type: ignore[return-value]

    def free_cells(self) -> list[tuple[int, int]]:
        return [(int(i), int(j)) for i, j in zip(*np.nonzero(self.walls == 0))]

    def vertex_cells(self) -> list[tuple[int, int]]:
        """Free cells that are not straight corridor cells (OGBench's navigate goal set)."""
        out = []
        for i, j in self.free_cells():
            open_ = [self.is_free((i + di, j + dj)) for di, dj in NEIGHBOURS]
            up, left, down, right = open_
            corridor = sum(open_) == 2 and ((up and down) or (left and right))
            if not corridor:
                out.append((i, j))
        return out

    def is_free(self, ij: tuple[int, int]) -> bool:
        i, j = ij
        return 0 <= i < self.walls.shape[0] and 0 <= j < self.walls.shape[1] and self.walls[i, j] == 0

    @staticmethod
    def cell_to_xy(ij: tuple[int, int]) -> np.ndarray:
        return np.array([ij[1] * MAZE_UNIT - OFFSET, ij[0] * MAZE_UNIT - OFFSET], dtype=np.float64)

    @staticmethod
    def xy_to_cell(xy: np.ndarray) -> tuple[int, int]:
        """OGBench's rounding: int((coord + offset + unit/2) / unit)."""
        return int((xy[1] + OFFSET + 0.5 * MAZE_UNIT) / MAZE_UNIT), int((xy[0] + OFFSET + 0.5 * MAZE_UNIT) / MAZE_UNIT)

    def bfs(self, goal_ij: tuple[int, int]) -> np.ndarray:
        """[rows, cols] BFS cell distance to ``goal_ij`` over free cells (UNREACHABLE for walls)."""
        if goal_ij not in self._bfs_cache:
            dist = np.full(self.walls.shape, UNREACHABLE, dtype=np.int64)
            dist[goal_ij] = 0
            queue = deque([goal_ij])
            while queue:
                i, j = queue.popleft()
                for di, dj in NEIGHBOURS:
                    n = (i + di, j + dj)
                    if self.is_free(n) and dist[n] == UNREACHABLE:
                        dist[n] = dist[i, j] + 1
                        queue.append(n)
            self._bfs_cache[goal_ij] = dist
        return self._bfs_cache[goal_ij]

    def next_cell(self, ij: tuple[int, int], goal_ij: tuple[int, int]) -> tuple[int, int]:
        """The neighbour with the smallest BFS distance to the goal (OGBench's oracle subgoal)."""
        dist = self.bfs(goal_ij)
        best = ij
        for di, dj in NEIGHBOURS:
            n = (ij[0] + di, ij[1] + dj)
            if self.is_free(n) and dist[n] < dist[best]:
                best = n
        return best

    def task(self, task_id: int) -> Task:
        if task_id not in TASK_IDS:
            raise ConfigError(f"task={task_id!r} is not a task id; choose one of {list(TASK_IDS)}")
        return self.tasks[task_id - 1]

    def in_free_cell(self, xy: np.ndarray) -> np.ndarray:
        """[..., 2] world points -> [...] bool: the point's cell is free (inside the maze)."""
        xy = np.asarray(xy, dtype=np.float64)
        i = np.floor((xy[..., 1] + OFFSET + 0.5 * MAZE_UNIT) / MAZE_UNIT).astype(np.int64)
        j = np.floor((xy[..., 0] + OFFSET + 0.5 * MAZE_UNIT) / MAZE_UNIT).astype(np.int64)
        inside = (i >= 0) & (i < self.walls.shape[0]) & (j >= 0) & (j < self.walls.shape[1])
        out = np.zeros(i.shape, dtype=bool)
        out[inside] = self.walls[i[inside], j[inside]] == 0
        return out

    def path_in_free(self, path: np.ndarray, per_step: int = 10) -> np.ndarray:
        """[..., F, 2] polylines -> [...] bool: every point along every step is in a free cell (the
        path crosses no wall; a straight step of up to 4 units can cut a wall's corner otherwise)."""
        return self.in_free_cell(densify(path, per_step)).all(-1)

    def steps_cross_wall(self, path: np.ndarray, per_step: int = 10) -> np.ndarray:
        """[..., F + 1, 2] polylines -> [..., F] bool: step t (point t to t + 1) leaves the free cells at
        one of ``per_step`` evenly spaced points along it (its end included): the value's wall test."""
        along = densify(path, per_step)[..., 1:, :]  # [..., F * k, 2], step-major
        return ~self.in_free_cell(along.reshape(*along.shape[:-2], -1, per_step, 2)).all(-1)


def cell_centres(walls: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """[rows, cols] wall map -> ([W, 2] wall cell centres, [F, 2] free cell centres), world x, y in row-major
    cell order: the squares a signed distance to the walls is measured against (wall guide, clearance)."""
    centres = np.array([MazeGeometry.cell_to_xy((i, j)) for i, j in np.ndindex(*np.shape(walls))])
    wall = np.asarray(walls).reshape(-1) != 0
    return centres[wall], centres[~wall]


def densify(path: np.ndarray, per_step: int = 10) -> np.ndarray:
    """[..., F, 2] polyline -> [..., 1 + per_step (F - 1), 2]: its first point, then ``per_step`` evenly
    spaced points along each step (ending on every vertex). Two free points can sit on either side
    of a wall; the points between them cannot."""
    path = np.asarray(path, dtype=np.float64)
    frac = np.linspace(1.0 / per_step, 1.0, per_step)[:, None]  # [k, 1]
    seg = path[..., :-1, None, :] + frac * (path[..., 1:, None, :] - path[..., :-1, None, :])  # [..., F-1, k, 2]
    return np.concatenate([path[..., :1, :], seg.reshape(*path.shape[:-2], -1, 2)], axis=-2)


def check_env_name(name: str) -> str:
    """``name`` if it is a maze env; an unknown name or a cube env is one ConfigError."""
    return require_family(name, MAZE_KINDS, "the maze code (geometry, PointMaze / AntMaze episodes)")


@lru_cache(maxsize=None)
def maze_geometry(name: str) -> MazeGeometry:
    """Geometry of ``{pointmaze,antmaze}-{medium,large,giant}`` read from OGBench's env definition."""
    env = make_navigate_env(check_env_name(name))
    u = env.unwrapped
    tasks = tuple(
        Task(k + 1, tuple(t["init_ij"]), tuple(t["goal_ij"]),
             MazeGeometry.cell_to_xy(t["init_ij"]), MazeGeometry.cell_to_xy(t["goal_ij"]))
        for k, t in enumerate(u.task_infos)
    )
    walls = np.asarray(u.maze_map, dtype=np.int64).copy()
    env.close()
    return MazeGeometry(name, walls, tasks)
