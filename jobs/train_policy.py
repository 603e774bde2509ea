"""Train a goal-conditioned low-level policy (goal-conditioned BC with hindsight subgoals), resumable.

    python jobs/train_policy.py env=antmaze-medium policy.out=checkpoints/antmaze-medium-policy
    python jobs/train_policy.py env=antmaze-medium data.root=/tmp/antdata data.episodes=20 policy.max_steps=5000
    python jobs/train_policy.py env=cube-single policy.out=checkpoints/cube-single-policy policy.time_budget_s=2100

The dataset is the one `jobs/make_dataset.py` writes for the same env= / data.* words
(manifest and sha256 verified; the ant's expert too). Ant: the ant state without x, y + the
subgoal relative to the ant -> 8 torques (fmctd_dist/families/maze/ant_policy.py). Cube: the arm +
the target cube + its subgoal relative to the cube -> the 5-D action
(fmctd_dist/families/cube/policy.py). MSE onto the data's actions, subgoals relabelled in
hindsight (fmctd_dist/control/policy/hindsight.py). The progress bar shows the train loss,
the last val loss and steps/s; the end prints the val loss (beside the ant expert's, the
noise floor) and the reach rates of the policy and the family's references.

A killed run continues from its last checkpoint (policy.ckpt_every) when rerun with the same
command; raising policy.max_steps continues a finished one; policy.time_budget_s stops a call
at the first checkpoint past the budget. policy.threads=1 by default.
"""

import time

from fmctd_dist.cli import run
from fmctd_dist.control.policy.config import load_policy_args, policy_dir
from fmctd_dist.control.policy.train import train_policy
from fmctd_dist.families import policy_hooks


def main(argv: list[str]) -> int:
    cfg, pcfg = load_policy_args(argv)
    hooks = policy_hooks(cfg.env.name)
    out = policy_dir(cfg, pcfg)
    t0 = time.time()
    s = train_policy(cfg, pcfg, hooks, out)
    rows = s["rows"]["train"]
    extra = ""
    if "fallen_rows" in rows:
        fallen = "dropped" if pcfg.policy.drop_fallen else "kept (policy.drop_fallen=false)"
        extra = f", {rows['fallen_rows']} rows with a fallen ant ({rows['episodes_with_falls']} episodes) {fallen}"
    print(f"{cfg.env.name} policy {out}: {s['step']} steps, train wall {s['wall_time_s']:.0f}s (this call "
          f"{time.time() - t0:.0f}s); trained on {rows['trained_rows']} of {rows['rows']} train rows{extra}")
    floor = "" if s["val_mse_expert"] is None else f"; the expert on the same val rows: {s['val_mse_expert']:.4f}"
    val = "-" if s["val_loss"] is None else f"{s['val_loss']:.4f}"
    best = "-" if s["best_val_loss"] is None else f"{s['best_val_loss']:.4f}"
    print(f"  loss train {s['train_loss']:.4f}  val {val} (best {best} at step {s['best_val_step']}{floor})")
    if s.get("stopped"):
        print(f"  stopped: {s['stopped']}")
    for name, r in (s.get("reach") or {}).items():
        print(hooks.format(name, r))
    return 0


if __name__ == "__main__":
    run(main)
