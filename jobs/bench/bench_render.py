"""Rendering speed of the visual maze: frames/s in one process on one thread, side by side.

    python jobs/bench/bench_render.py env=visual-pointmaze-medium            # 300 frames per arm
    python jobs/bench/bench_render.py env=visual-pointmaze-large frames=100

Arms: the chase camera (the task's view) and OGBench's fixed top-down view, each with MuJoCo's
default 4096 shadow map (the reference frames) and a 1024 one (visual.shadowsize=1024). Arms
are interleaved in rounds so load on the machine hits them alike; the load average (uptime) is
printed with the numbers. Positions: seeded, uniform over the maze's free cells. Also prints
how long rendering every train frame of an OGBench-size dataset (1000 x 1001) would take, and
how far the 1024 shadow map's frames are from the 4096 reference on the same positions.
"""

from __future__ import annotations

import os
import time

import numpy as np

from fmctd_dist.cli import run
from fmctd_dist.config import load_config
from fmctd_dist.families.maze.geometry import maze_geometry
from fmctd_dist.families.visual.env import CAMERA, REFERENCE_SHADOWSIZE, FrameRenderer, point_env_name
from fmctd_dist.errors import ConfigError

ARMS = [(CAMERA, REFERENCE_SHADOWSIZE), (CAMERA, 1024), (None, REFERENCE_SHADOWSIZE), (None, 1024)]
ROUNDS = 3


def free_positions(name: str, n: int, seed: int = 0) -> np.ndarray:
    """[n, 2] seeded positions uniform in the free cells (within 1.3 of a cell centre: the ball fits)."""
    geo = maze_geometry(point_env_name(name))
    cells = np.argwhere(geo.walls == 0)
    rng = np.random.default_rng(seed)
    ij = cells[rng.integers(len(cells), size=n)]
    return np.stack([4.0 * ij[:, 1] - 4.0, 4.0 * ij[:, 0] - 4.0], axis=1) + rng.uniform(-1.3, 1.3, size=(n, 2))


def main(argv: list[str]) -> int:
    frames = 300
    rest = []
    for a in argv:
        if a.startswith("frames="):
            frames = int(a.split("=", 1)[1])
            if frames < ROUNDS:
                raise ConfigError(f"frames={frames} must be at least {ROUNDS}")
        else:
            rest.append(a)
    cfg = load_config(rest, env="visual-pointmaze-medium", method="mctd")
    xy = free_positions(cfg.env.name, frames)
    renderers = {arm: FrameRenderer(cfg.env.name, camera=arm[0], shadowsize=arm[1]) for arm in ARMS}
    for r in renderers.values():
        r.render(xy[:2])  # warm-up: first frame compiles shaders
    load0 = os.getloadavg()
    spent = {arm: 0.0 for arm in ARMS}
    images: dict[tuple, list[np.ndarray]] = {arm: [] for arm in ARMS}
    for chunk in np.array_split(xy, ROUNDS):
        for arm, r in renderers.items():
            t = time.perf_counter()
            images[arm].append(r.render(chunk))
            spent[arm] += time.perf_counter() - t
    load1 = os.getloadavg()
    total = cfg.data.episodes * cfg.data.episode_steps
    print(f"{cfg.env.name}: {frames} frames per arm at 64x64, one process, LP_NUM_THREADS="
          f"{os.environ.get('LP_NUM_THREADS')}, MUJOCO_GL={os.environ.get('MUJOCO_GL')}; "
          f"load average {load0[0]:.2f} before, {load1[0]:.2f} after ({os.cpu_count()} cores)")
    print(f"| view | shadow map | frames/s | ms/frame | all {total:,} train frames |")
    print("|---|---|---|---|---|")
    for (camera, shadow), s in spent.items():
        fps = frames / s
        print(f"| {'chase (back)' if camera else 'top-down'} | {shadow} | {fps:.1f} | {1e3 / fps:.1f} | "
              f"{total / fps / 3600:.1f} h |")
    chase = spent[(CAMERA, REFERENCE_SHADOWSIZE)] / spent[(CAMERA, 1024)]
    print(f"chase camera: shadow map 1024 is {chase:.2f}x faster than 4096")
    for camera in (CAMERA, None):
        ref = np.concatenate(images[(camera, REFERENCE_SHADOWSIZE)]).astype(np.int16)
        d = np.abs(np.concatenate(images[(camera, 1024)]).astype(np.int16) - ref)
        print(f"{'chase' if camera else 'top-down'}: 1024 vs 4096 on the same {frames} frames: mean |diff| "
              f"{d.mean():.3f} levels, {(d.max(-1) > 8).mean():.3%} of pixels off by > 8, max {d.max()}, "
              f"worst frame mean {d.reshape(frames, -1).mean(1).max():.3f}")
    return 0


if __name__ == "__main__":
    run(main)
