"""Generate (or verify) a PointMaze navigate dataset with our own BFS-subgoal noisy oracle.

    python jobs/make_dataset.py env=pointmaze-giant
    python jobs/make_dataset.py env=pointmaze-medium data.seed=1 data.root=/tmp/data

Nothing is downloaded. The same config always writes the same bytes (sha256 printed).
"""

import time

from fmctd_dist.cli import run
from fmctd_dist.config import load_config
from fmctd_dist.data.dataset import make_dataset


def main(argv: list[str]) -> int:
    t0 = time.time()
    cfg = load_config(argv, method="mctd")
    path, manifest = make_dataset(cfg)
    action = "generated" if "_generation_s" in manifest else "verified existing"
    print(f"{action} {path} in {time.time() - t0:.1f}s")
    for split, digest in manifest["sha256"].items():
        print(f"  {split}: {manifest['episodes'][split]} episodes x {manifest['episode_steps']} steps  sha256={digest}")
    print(f"  obs mean {manifest['obs_mean']}  std {manifest['obs_std']}")
    return 0


if __name__ == "__main__":
    run(main)
