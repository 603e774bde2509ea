"""Train the goal-conditioned AntMaze policy (goal-conditioned BC with hindsight subgoals), resumable.

    python jobs/train_policy.py env=antmaze-medium policy.out=checkpoints/antmaze-medium-policy
    python jobs/train_policy.py env=antmaze-medium data.root=/tmp/antdata data.episodes=20 policy.max_steps=5000

The dataset is the one `jobs/make_dataset.py` writes for the same env= / data.* words
(manifest, sha256 and expert verified). Input: the ant state without x, y + the subgoal
relative to the ant; output: 8 torques; MSE onto the data's noisy expert torques, subgoals
relabelled in hindsight (fmctd_dist/control/policy/ant_data.py). The progress bar shows the train
loss, the last val loss and steps/s; the end prints the val loss beside the expert's (the
noise floor) and the reach rates (fmctd_dist/control/policy/ant_reach.py) of the policy and the expert.

A killed run continues from its last checkpoint (policy.ckpt_every) when rerun with the same
command; raising policy.max_steps continues a finished one. policy.threads=1 by default.
"""

import time

from fmctd_dist.control.policy.config import load_policy_args, policy_dir
from fmctd_dist.control.policy.train import train_policy
from fmctd_dist.control.policy.ant_reach import format_reach
from fmctd_dist.cli import run


def main(argv: list[str]) -> int:
    cfg, pcfg = load_policy_args(argv)
    out = policy_dir(cfg, pcfg)
    t0 = time.time()
    s = train_policy(cfg, pcfg, out)
    rows = s["rows"]["train"]
    fallen = "dropped" if pcfg.policy.drop_fallen else "kept (policy.drop_fallen=false)"
    print(f"ant policy {out}: {s['step']} steps, train wall {s['wall_time_s']:.0f}s (this call "
          f"{time.time() - t0:.0f}s); trained on {rows['trained_rows']} of {rows['rows']} train rows, "
          f"{rows['fallen_rows']} rows with a fallen ant ({rows['episodes_with_falls']} episodes) {fallen}")
    print(f"  loss train {s['train_loss']:.4f}  val {s['val_loss']:.4f} (best {s['best_val_loss']:.4f} at step "
          f"{s['best_val_step']}; the expert on the same val rows: {s['val_mse_expert']:.4f})")
    for name, r in (s.get("reach") or {}).items():
        print(format_reach(name, r))
    return 0


if __name__ == "__main__":
    run(main)
