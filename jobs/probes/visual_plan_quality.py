"""Latent plan quality of a visual planner: warps on estimated positions and distance to the latent manifold.

    python jobs/probes/visual_plan_quality.py env=visual-pointmaze-medium                 # Fast-MCTD, tasks 1-5, seed 0
    python jobs/probes/visual_plan_quality.py env=visual-pointmaze-medium \
        checkpoint=runs/visual/visual-pointmaze-medium-h5

One search per task from the start frame to the goal frame (no control); per task the share of
plans that warp, the median largest and first step, the closest approach to the goal, and the
median distance of plan latents to the nearest real latent, beside that distance for held-out
real latents (``fmctd_dist/families/visual/plan_quality.py``). Prints a table and the JSON.
"""

from __future__ import annotations

import json

from fmctd_dist.cli import run
from fmctd_dist.config import load_config
from fmctd_dist.device import set_threads
from fmctd_dist.families.visual.plan_quality import plan_quality


def main(argv: list[str]) -> int:
    cfg = load_config(argv, env="visual-pointmaze-medium", method="fast-mctd")
    set_threads(cfg.eval.threads or 1)
    q = plan_quality(cfg, list(cfg.eval.tasks), int(cfg.eval.seeds[0]))
    print(f"{q['checkpoint']} ({q['digest']}, {q['train_steps']} steps, val loss {q['val_loss']:.4f}); "
          f"warp threshold {q['warp_threshold']}")
    print("| task | status | plans | warping | median largest step | median first step | median closest to goal "
          "| median NN distance |")
    print("|---|---|---|---|---|---|---|---|")
    for r in q["tasks"]:
        print(f"| {r['task']} | {r['status']} ({r['stop_reason']}) | {r['plans']} | {100 * r['warp_fraction']:.0f}% | "
              f"{r['median_max_step']:.2f} | {r['median_first_step']:.2f} | {r['median_closest_to_goal']:.2f} | "
              f"{r['median_nn_distance']:.3f} |")
    print(f"real held-out latents: median NN distance {q['real_val_median_nn_distance']:.3f}; estimator's 5-step "
          f"moves along real episodes: p99 {q['real_val_p99_5step_move']:.2f}, max {q['real_val_max_5step_move']:.2f}")
    print(json.dumps(q))
    return 0


if __name__ == "__main__":
    run(main)
