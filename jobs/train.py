"""Train a Diffusion Forcing planner model on our own dataset of the env's family (resumable).

    python jobs/train.py env=pointmaze-medium jump=5 train.max_steps=200        # smoke run -> runs/
    python jobs/train.py env=pointmaze-medium jump=5 train.out=checkpoints/pointmaze-medium-h5
    python jobs/train.py env=pointmaze-medium model.kind=diffuser    # Diffuser U-Net -> runs/pointmaze-medium-diffuser
    python jobs/train.py env=cube-single jump=5                      # cube xyz plans (play data) -> runs/cube-single-h5

model.kind=diffuser without a method= word trains with configs/method/diffuser.yaml (its
lr, batch, EMA, cosine betas, frame_stack 1 are the Diffuser defaults).

The dataset is generated first if it is missing (and verified if it exists). A killed run
continues from its last checkpoint when rerun with the same command; raising
train.max_steps continues a finished one.
"""

import time

from fmctd_dist.cli import run
from fmctd_dist.config import load_config, resolve_path
from fmctd_dist.data.windows import train_data
from fmctd_dist.device import resolve_device
from fmctd_dist.families import load_dataset, make_dataset
from fmctd_dist.diffusion.train import train


def main(argv: list[str]) -> int:
    method = "diffuser" if "model.kind=diffuser" in [a.replace(" ", "") for a in argv] else "mctd"
    # dense (jump=1) unless jump=... is given; cube models are trained before the cube planner exists
    cfg = load_config(argv, method=method)
    resolve_device(cfg.device)  # a missing GPU fails here, before any work
    make_dataset(cfg)
    data = train_data(cfg, load_dataset(cfg))
    out = resolve_path(cfg.train.out or f"runs/{cfg.run_name}")
    t0 = time.time()
    summary = train(cfg, data, out)
    print(f"checkpoint {out}: step {summary['step']}, {summary['param_count']:,} parameters, "
          f"train wall {summary['wall_time_s']:.0f}s (this call {time.time() - t0:.0f}s), "
          f"losses {summary['final_losses']}")
    return 0


if __name__ == "__main__":
    run(main)
