"""Reach rate of a trained AntMaze policy on held-out data, beside the ant expert steered at the same subgoals.

    python jobs/eval_policy.py env=antmaze-medium policy.out=checkpoints/antmaze-medium-policy
    python jobs/eval_policy.py env=antmaze-medium data.root=/tmp/antdata data.episodes=20 \
        policy.out=runs/antmaze-medium-policy reach.rows=200 reach.seed=0

For reach.rows val rows (seeded): restore the ant's MuJoCo state from the row, subgoal = the
episode's x, y reach.offset steps later, reach.max_steps env steps; reached = within
reach.radius after a step (fmctd_dist/control/policy/ant_reach.py). reach.expert=false skips the expert.
The policy is checked before the data is read: a missing dir, another kind of checkpoint
or one trained for another maze is one `error:` line.
"""

import time

from fmctd_dist.control.policy.ant import load_policy
from fmctd_dist.control.policy.config import load_policy_args, policy_dir
from fmctd_dist.control.policy.ant_data import load_policy_data
from fmctd_dist.control.policy.ant_reach import evaluate_reach, expert_controller, zero_controller, format_reach
from fmctd_dist.cli import run
from fmctd_dist.config import resolve_path
from fmctd_dist.device import set_threads


def main(argv: list[str]) -> int:
    cfg, pcfg = load_policy_args(argv)
    set_threads(pcfg.policy.threads)
    policy = load_policy(policy_dir(cfg, pcfg), env_name=cfg.env.name)
    ctrls = {"policy": policy.act}
    if pcfg.reach.expert:
        from fmctd_dist.ant.expert import load_expert

        ctrls["expert"] = expert_controller(load_expert(resolve_path(cfg.data.expert)))
    if pcfg.reach.zero:
        ctrls["zero"] = zero_controller
    _, val, _ = load_policy_data(cfg, drop_fallen=True)
    r = pcfg.reach
    t0 = time.time()
    results = evaluate_reach(cfg.env.name, ctrls, val, r.rows, r.offset, r.max_steps, r.radius, r.seed)
    print(f"reach on {cfg.env.name} val rows (offset {r.offset}, seed {r.seed}), policy {policy.where} "
          f"(digest {policy.manifest['digest']}, {policy.manifest['steps']} steps), {time.time() - t0:.0f}s:")
    for name, res in results.items():
        print(format_reach(name, res))
    return 0


if __name__ == "__main__":
    run(main)
