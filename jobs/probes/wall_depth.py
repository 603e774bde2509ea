"""How far a maze model's x0 predictions sit inside walls, per noise level (the lever ``train.wall_weight``).

    OMP_NUM_THREADS=1 python jobs/probes/wall_depth.py checkpoints/antmaze-large-h5 [more checkpoints]

Guidance acts on the model's x0 prediction at every level of the pyramid. On data windows of the
checkpoint's own maze (the validation split, 256 seeded windows, the same for every checkpoint), each plan
token is noised to one timestep (the context clean, as the sampler feeds it) and the model predicts x0.
The table gives, per timestep, the share of predicted frames inside a wall, their mean depth there (maze
units, 0 in free space) and the token MSE. The data's own frames are never inside a wall, so a prediction
that is marks the blur of routes around a wall that guidance then pushes straight through it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fmctd_dist.cli import run
from fmctd_dist.config import config_from_dict

TIMESTEPS = (0, 200, 400, 600, 800, 999)
WINDOWS = 256
IN_WALL = 0.01  # maze units: a frame deeper than this counts as inside


def wall_depths(ckpt: Path) -> list[tuple[int, float, float, float]]:
    """[(timestep, share of predicted frames inside a wall, their mean depth, token MSE)] of one checkpoint."""
    import torch

    from fmctd_dist.data.windows import train_data
    from fmctd_dist.diffusion.checkpoint import load_checkpoint
    from fmctd_dist.diffusion.train import DFLoss
    from fmctd_dist.families import load_dataset

    model, manifest = load_checkpoint(ckpt)
    cfg = config_from_dict(manifest["config"])
    data = train_data(cfg, load_dataset(cfg))
    depth, _ = data.wall_depth(cfg)
    noising = DFLoss(cfg, torch.device("cpu"))
    x0 = torch.as_tensor(data.val.sample(np.random.default_rng(0), WINDOWS))
    b, t, dd = x0.shape
    ctx = cfg.diffusion.stabilization - 1
    out = []
    model.eval()
    with torch.no_grad():
        for k in TIMESTEPS:
            kk = torch.full((b, t), k)
            kk[:, 0] = ctx
            xt = noising.noised(x0, kk, torch.Generator().manual_seed(k))
            xt[:, 0] = noising.sqrt_ab[ctx] * x0[:, 0]
            pred = model(xt, kk)
            d = depth(pred[:, 1:].reshape(b, t - 1, cfg.model.frame_stack, dd // cfg.model.frame_stack))
            inside = d > IN_WALL
            out.append((k, float(inside.float().mean()), float(d.mean()),
                        float((pred - x0)[:, 1:].square().mean())))
    return out


def main(argv: list[str]) -> int:
    import torch

    torch.set_num_threads(1)
    if not argv:
        print(__doc__)
        return 2
    print("| checkpoint | " + " | ".join(f"t={k}: inside / depth / MSE" for k in TIMESTEPS) + " |")
    print("|---|" + "---|" * len(TIMESTEPS))
    for a in argv:
        cells = [f"{100 * s:.0f}% / {d:.3f} / {m:.3f}" for _, s, d, m in wall_depths(Path(a))]
        print(f"| {Path(a).name} | " + " | ".join(cells) + " |", flush=True)
    return 0


if __name__ == "__main__":
    run(main)
