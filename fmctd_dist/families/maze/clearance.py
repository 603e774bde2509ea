"""Plans kept off the walls before a robot follows them (``env.wall_clearance``; not the paper's).

Why: our ant's low-level policy learned from data that walks corridor centres, and it falls when a plan
takes it within a leg's length of a wall: on AntMaze-large half the failed Fast-MCTD episodes end with
the ant on its back beside a wall (docs/results.md, AntMaze). The planner's plan is left as it is (rows
record it); the controller follows a copy whose every point is pushed out along the walls' normal until
it is ``clearance`` world units from the nearest wall face, or as far as the corridor allows (a corridor
is one 4-unit cell wide, so 2.0 is its centre line). A point inside a wall goes to the nearest free cell
the same way. Plain numpy, a pure function of (plan, maze, clearance).
"""

from __future__ import annotations

import numpy as np

from fmctd_dist.families.maze.geometry import MAZE_UNIT, MazeGeometry, cell_centres

ITERATIONS = 20  # each moves a point half its shortfall: 1 - 2^-20 of the way where one wall decides
STEP = 0.5  # half steps settle between two walls closer than 2 x clearance instead of bouncing


def _nearest_square(xy: np.ndarray, centres: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """[N, 2] points, [K, 2] cell centres -> distance [N] to the nearest cell square (0 inside or on it), the
    nearest point on it [N, 2] and its centre [N, 2]."""
    half = 0.5 * MAZE_UNIT
    closest = np.clip(xy[:, None, :], centres - half, centres + half)  # [N, K, 2]
    dist = np.linalg.norm(xy[:, None, :] - closest, axis=-1)  # [N, K]
    k = dist.argmin(axis=1)
    n = np.arange(len(xy))
    return dist[n, k], closest[n, k], centres[k]


def _face_normal(offset: np.ndarray) -> np.ndarray:
    """[N, 2] point - square centre -> the square's outward unit normal on the face nearest the point."""
    axis = np.abs(offset).argmax(axis=-1)
    normal = np.zeros_like(offset)
    normal[np.arange(len(offset)), axis] = np.where(np.take_along_axis(offset, axis[:, None], 1)[:, 0] >= 0, 1.0, -1.0)
    return normal


def keep_clear(plan: np.ndarray, geo: MazeGeometry, clearance: float) -> np.ndarray:
    """[F, 2] plan -> [F, 2] copy with each point at least ``clearance`` from every wall (where it fits)."""
    xy = np.array(plan, dtype=np.float64)
    if clearance <= 0 or len(xy) == 0:
        return xy
    walls, free = cell_centres(geo.walls)
    for _ in range(ITERATIONS):
        d_wall, q_wall, c_wall = _nearest_square(xy, walls)
        d_free, q_free, _ = _nearest_square(xy, free)
        inside = d_free > 0.0  # inside a wall cell: head for the nearest free cell
        away = np.where(inside[:, None], q_free - xy, xy - q_wall)
        length = np.linalg.norm(away, axis=-1)
        on_face = length == 0.0  # on a wall's face: straight out of it
        away[on_face] = _face_normal(xy[on_face] - c_wall[on_face])
        length[on_face] = 1.0
        sdf = np.where(inside, -d_free, d_wall)
        short = np.maximum(clearance - sdf, 0.0)
        if not short.any():
            break
        xy += STEP * short[:, None] * away / length[:, None]
    return xy
