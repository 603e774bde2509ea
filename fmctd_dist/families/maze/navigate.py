"""What PointMaze and AntMaze navigate data share: OGBench's start / goal draws and the episode loop.

OGBench's navigate recipe (docs/reference.md §9): a random free cell's centre + uniform [-1, 1]
noise as the start, a random vertex cell as the goal, a new goal on each success, the
episode runs on. The robot-specific step (oracle actions for the point, the expert for the
ant) is the caller's: an ``EpisodeMaker`` builds the env (and expert) once per process and
returns the episode function.

Every episode draws only from its own seeded stream and starts from a full reset of the robot,
so episodes are independent: ``data.workers`` processes generate contiguous chunks of them and
the stacked arrays are the same bytes as one process's (``test_dataset.py``, ``test_antmaze.py``). That is
what makes the AntMaze datasets (~15 min per maze on one core) cheap on a many-core machine.
"""

from __future__ import annotations

import multiprocessing
import os
import sys
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed

import numpy as np
from tqdm.auto import tqdm

from fmctd_dist.config import Config
from fmctd_dist.data.splits import episode_rng
from fmctd_dist.families.maze.geometry import MazeGeometry
from fmctd_dist.families.maze.tasks import NOISE

Episode = Callable[[np.random.Generator], dict[str, np.ndarray]]
# cfg -> (episode function, close); a module-level function, so that worker processes can build their own
EpisodeMaker = Callable[[Config], tuple[Episode, Callable[[], None]]]


def random_start(geo: MazeGeometry, rng: np.random.Generator) -> np.ndarray:
    """[2] a uniformly drawn free cell's centre + uniform [-1, 1] noise (OGBench navigate's start)."""
    free = geo.free_cells()
    return geo.cell_to_xy(free[rng.integers(len(free))]) + rng.uniform(-NOISE, NOISE, size=2)


def random_goal(geo: MazeGeometry, rng: np.random.Generator) -> np.ndarray:
    """[2] a uniformly drawn vertex cell's centre (OGBench navigate's goal set, no goal noise here)."""
    vertices = geo.vertex_cells()
    return geo.cell_to_xy(vertices[rng.integers(len(vertices))])


def run_episodes(cfg: Config, split: str, episodes: int, make: EpisodeMaker,
                 progress: bool = True) -> dict[str, np.ndarray]:
    """Episodes 0..episodes-1 of ``split`` (in ``data.workers`` processes), stacked to [E, S, ...],
    plus ``terminals``."""
    workers = min(cfg.data.workers, episodes)
    bar = tqdm(total=episodes, desc=f"{cfg.env.name} {split}", unit="ep", disable=not progress)
    if workers <= 1:
        episode, close = make(cfg)
        try:
            parts = [_episodes(episode, cfg, split, range(episodes), bar.update)]
        finally:
            close()
    else:
        bounds = np.linspace(0, episodes, 4 * workers + 1).round().astype(int)  # 4 chunks per worker: even finish
        chunks = [range(a, b) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]
        parts_by_start: dict[int, dict[str, np.ndarray]] = {}
        ctx = multiprocessing.get_context("spawn")  # no forked torch / MuJoCo state
        with ProcessPoolExecutor(workers, mp_context=ctx, initializer=_init_worker, initargs=(make, cfg)) as pool:
            futures = {pool.submit(_worker_chunk, split, c.start, c.stop): c for c in chunks}
            for done in as_completed(futures):
                parts_by_start[futures[done].start] = done.result()
                bar.update(len(futures[done]))
        parts = [parts_by_start[c.start] for c in chunks]
    bar.close()
    arrays = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    terminals = np.zeros(arrays["observations"].shape[:2], dtype=bool)
    terminals[:, -1] = True
    arrays["terminals"] = terminals
    return arrays


def _episodes(episode: Episode, cfg: Config, split: str, eps: range,
              tick: Callable[[int], object] = lambda n: None) -> dict[str, np.ndarray]:
    out: dict[str, list[np.ndarray]] = {}
    for ep in eps:
        for k, v in episode(episode_rng(cfg, split, ep)).items():
            out.setdefault(k, []).append(v)
        tick(1)
    return {k: np.stack(v) for k, v in out.items()}


_WORKER: dict[str, object] = {}


def _init_worker(make: EpisodeMaker, cfg: Config) -> None:
    """One env (and expert) per worker process, one thread each: the workers are the parallelism."""
    os.environ["OMP_NUM_THREADS"] = "1"  # read by torch when the maker first imports it
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(1)
    _WORKER["episode"], _ = make(cfg)
    _WORKER["cfg"] = cfg


def _worker_chunk(split: str, start: int, stop: int) -> dict[str, np.ndarray]:
    return _episodes(_WORKER["episode"], _WORKER["cfg"], split, range(start, stop))
