"""Generate (or verify) a navigate dataset: PointMaze with our BFS-subgoal noisy oracle, AntMaze
with our ant expert steered by that oracle.

    python jobs/make_dataset.py env=pointmaze-giant
    python jobs/make_dataset.py env=pointmaze-medium data.seed=1 data.root=/tmp/data
    python jobs/make_dataset.py env=antmaze-medium                      # expert: data.expert
    python jobs/make_dataset.py env=antmaze-medium data.episodes=20 data.root=/tmp/data   # a small look

Nothing is downloaded. The same config (and, for AntMaze, the same expert) always writes the
same bytes (sha256 printed).
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
    print(f"  x, y mean {manifest['obs_mean']}  std {manifest['obs_std']}")
    if "expert" in manifest:
        expert = manifest["expert"]
        print(f"  expert {expert['path']} (digest {expert['digest']}), noise {manifest['noise']}")
        for split, s in manifest["stats"].items():
            print(f"  {split}: {s['goals_per_1000_steps']} goals / 1000 steps, "
                  f"unhealthy {s['unhealthy_fraction']:.2%}, upside down {s['upside_down_fraction']:.2%}, "
                  f"{s['episodes_fallen']} episodes fell, {s['mean_speed_m_per_s']} m/s")
        g = manifest["generation"]
        print(f"  generation {g['wall_s']}s, {g['env_steps_per_s']} env steps/s")
    return 0


if __name__ == "__main__":
    run(main)
