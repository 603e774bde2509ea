"""Reach rate of a trained low-level policy on held-out data, beside the family's scripted reference and zero actions.

    python jobs/eval_policy.py env=antmaze-medium policy.out=checkpoints/antmaze-medium-policy
    python jobs/eval_policy.py env=antmaze-medium data.root=/tmp/antdata data.episodes=20 \\
        policy.out=runs/antmaze-medium-policy reach.rows=200 reach.seed=0
    python jobs/eval_policy.py env=cube-single policy.out=checkpoints/cube-single-policy reach.rows=100
    python jobs/eval_policy.py env=cube-double policy.out=checkpoints/cube-single-policy   # the single-cube policy

Ant (fmctd_dist/families/maze/ant_reach.py): for reach.rows val rows (seeded), restore the
ant's MuJoCo state, subgoal = the episode's x, y reach.offset steps later, reach.max_steps env
steps; reached = within reach.radius after a step; reference: the ant expert. Cube
(fmctd_dist/families/cube/reach.py): restore a val row inside a pick-and-place, the
plan is the data's cube path to its end (subgoal reach.offset steps ahead, moved on within
reach.advance), reached = the cube within reach.radius (0.4 obs units = 0.04 m) of the end;
reference: OGBench's CubePlanOracle. reach.expert=false skips the reference, reach.zero=false
the zero actions. The policy is checked before the data is read: a missing dir, another kind
of checkpoint or one trained for another env is one `error:` line.
"""

import time

from fmctd_dist.cli import run
from fmctd_dist.control.policy.checkpoint import load_policy
from fmctd_dist.control.policy.config import load_policy_args, policy_dir
from fmctd_dist.device import set_threads
from fmctd_dist.families import policy_hooks


def main(argv: list[str]) -> int:
    cfg, pcfg = load_policy_args(argv)
    set_threads(pcfg.policy.threads)
    hooks = policy_hooks(cfg.env.name)
    policy = load_policy(policy_dir(cfg, pcfg), hooks.spec, env_name=cfg.env.name)
    _, val, _ = hooks.load(cfg, pcfg)
    r = pcfg.reach
    t0 = time.time()
    results = hooks.reach(cfg, pcfg, policy.act, val, progress=True)
    print(f"reach on {cfg.env.name} val rows (offset {r.offset}, seed {r.seed}), policy {policy.where} "
          f"(trained on {policy.env}, digest {policy.manifest['digest']}, {policy.manifest['steps']} steps), "
          f"{time.time() - t0:.0f}s:")
    for name, res in results.items():
        print(hooks.format(name, res))
    return 0


if __name__ == "__main__":
    run(main)
