"""Generate (or verify) the planner dataset of an env's family: PointMaze with our BFS-subgoal noisy oracle,
AntMaze with our ant expert steered by that oracle, the cubes with OGBench's play oracle, the visual maze's latents.

    python jobs/make_dataset.py env=pointmaze-giant
    python jobs/make_dataset.py env=pointmaze-medium data.seed=1 data.root=/tmp/data
    python jobs/make_dataset.py env=antmaze-medium                      # expert: data.expert
    python jobs/make_dataset.py env=antmaze-medium data.episodes=20 data.root=/tmp/data   # a small look
    python jobs/make_dataset.py env=antmaze-large data.workers=2       # 2 processes, the same bytes
    python jobs/make_dataset.py env=cube-single                         # OGBench's CubePlanOracle play data

Nothing is downloaded. The same config (and, for AntMaze, the same expert) always writes the
same bytes (sha256 printed).
"""

import time

from fmctd_dist.cli import run
from fmctd_dist.config import load_config
from fmctd_dist.families import data_module, make_dataset


def main(argv: list[str]) -> int:
    t0 = time.time()
    cfg = load_config(argv, method="mctd")
    path, manifest = make_dataset(cfg)  # the family's own data (its registry record names the module)
    action = "generated" if "_generation_s" in manifest else "verified existing"
    print(f"{action} {path} in {time.time() - t0:.1f}s")
    for line in data_module(cfg.env.name).describe(manifest):
        print(line)
    return 0


if __name__ == "__main__":
    run(main)
