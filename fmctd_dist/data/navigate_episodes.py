"""What PointMaze and AntMaze navigate data share: OGBench's start / goal draws and the episode loop.

OGBench's navigate recipe (reference §9): a random free cell's centre + uniform [-1, 1]
noise as the start, a random vertex cell as the goal, a new goal on each success, the
episode runs on. The robot-specific step (oracle actions for the point, the expert for the
ant) is the caller's ``episode`` function.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from tqdm.auto import tqdm

from fmctd_dist.config import Config
from fmctd_dist.data.splits import episode_rng
from fmctd_dist.envs.maze import MazeGeometry
from fmctd_dist.envs.maze_episodes import NOISE

Episode = Callable[[np.random.Generator], dict[str, np.ndarray]]


def random_start(geo: MazeGeometry, rng: np.random.Generator) -> np.ndarray:
    """[2] a uniformly drawn free cell's centre + uniform [-1, 1] noise (OGBench navigate's start)."""
    free = geo.free_cells()
    return geo.cell_to_xy(free[rng.integers(len(free))]) + rng.uniform(-NOISE, NOISE, size=2)


def random_goal(geo: MazeGeometry, rng: np.random.Generator) -> np.ndarray:
    """[2] a uniformly drawn vertex cell's centre (OGBench navigate's goal set, no goal noise here)."""
    vertices = geo.vertex_cells()
    return geo.cell_to_xy(vertices[rng.integers(len(vertices))])


def run_episodes(cfg: Config, split: str, episodes: int, episode: Episode,
                 progress: bool = True) -> dict[str, np.ndarray]:
    """Call ``episode(rng)`` (-> arrays [S, ...]) per episode; stack to [E, S, ...] and add ``terminals``."""
    out: dict[str, list[np.ndarray]] = {}
    for ep in tqdm(range(episodes), desc=f"{cfg.env.name} {split}", unit="ep", disable=not progress):
        for k, v in episode(episode_rng(cfg, split, ep)).items():
            out.setdefault(k, []).append(v)
    arrays = {k: np.stack(v) for k, v in out.items()}
    terminals = np.zeros(arrays["observations"].shape[:2], dtype=bool)
    terminals[:, -1] = True
    arrays["terminals"] = terminals
    return arrays
