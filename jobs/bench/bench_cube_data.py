"""How fast the cube play data is made: env steps/s of OGBench's CubePlanOracle loop, per cube env.

    python jobs/bench/bench_cube_data.py                       # 2 episodes x 1001 steps per env
    python jobs/bench/bench_cube_data.py --episodes 4 --envs cube-triple

Reports steps per CPU second of this process (what one free core would do; the machine may be
shared) beside steps per wall second, and what OGBench's full sizes would take on one core.
The episodes are those of data.seed=0 train (the same the dataset job makes first).
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

from fmctd_dist.families.cube.data import OGBENCH_EPISODES, episode_seeds, generate_episode  # noqa: E402
from fmctd_dist.families.cube.env import make_cube_env  # noqa: E402
from fmctd_dist.families.cube.record import CUBE_ENVS  # noqa: E402

STEPS = 1001


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=2)
    ap.add_argument("--envs", nargs="+", default=list(CUBE_ENVS), choices=CUBE_ENVS)
    args = ap.parse_args()
    print("| env | steps/CPU s | steps/wall s | OGBench size (train + val) | one core |")
    print("|---|---|---|---|---|")
    for name in args.envs:
        env = make_cube_env(name, mode="data_collection")
        generate_episode(env, 20, 0.1, (0, 0))  # compile the model, warm caches
        c0, w0 = time.process_time(), time.time()
        for ep in range(args.episodes):
            generate_episode(env, STEPS, 0.1, episode_seeds(0, "train", ep))
        cpu, wall = time.process_time() - c0, time.time() - w0
        rate = args.episodes * STEPS / cpu
        full = OGBENCH_EPISODES[name.split("-")[1]]
        full_steps = (full + full // 10) * STEPS
        print(f"| {name} | {rate:.0f} | {args.episodes * STEPS / wall:.0f} | {full} + {full // 10} episodes "
              f"({full_steps / 1e6:.2f} M steps) | {full_steps / rate / 3600:.2f} h |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
