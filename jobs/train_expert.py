"""Train the ant direction-following expert with SAC (resumable), for AntMaze dataset generation.

    python jobs/train_expert.py expert.max_steps=2000 expert.start_steps=500 eval.every=1000   # smoke -> runs/
    python jobs/train_expert.py expert.out=checkpoints/ant-expert expert.max_steps=1000000

The task (fmctd_dist/families/maze/expert/direction_env.py): OGBench's open-arena ant, a random unit
direction per episode, resampled every env.resample_every steps; reward = torso velocity
along it + healthy reward - control cost; the episode ends when the ant falls. The
progress bar shows the mean return, mean speed along the commanded direction (m/s) of the
last episodes, the last evaluation's success rate (fmctd_dist/families/maze/expert/evaluate.py: every
segment >= eval.min_speed m/s along its direction without falling), alpha and steps/s.

A killed run continues from its last checkpoint (expert.ckpt_every) when rerun with the
same command; raising expert.max_steps continues a finished one. expert.threads=1 by
default: SAC's small matrices gain little from more threads and the machine is shared.
"""

import time

from fmctd_dist.families.maze.expert.config import load_expert_config
from fmctd_dist.families.maze.expert.train import train_expert
from fmctd_dist.cli import run


def main(argv: list[str]) -> int:
    cfg = load_expert_config(argv)
    out = cfg.out_dir()
    t0 = time.time()
    s = train_expert(cfg, out)
    ev = s["eval"] or {}
    print(f"ant expert {out}: {s['step']} env steps, train wall {s['wall_time_s']:.0f}s "
          f"(this call {time.time() - t0:.0f}s); recent return {s['recent_return']}, "
          f"speed {s['recent_speed']} m/s; eval success {ev.get('success')}, speed {ev.get('speed_mean')} m/s, "
          f"falls {ev.get('fall_rate')}")
    return 0


if __name__ == "__main__":
    run(main)
