"""Figure: held-out chase-camera frames and their VAE reconstructions, with the estimator's position read from z.

    python jobs/figures/plot_visual_vae.py env=visual-pointmaze-medium     # -> docs/figures/visual_vae_<env>.png

Top row: validation frames (other episodes than the VAE's training frames), evenly spaced in the
frame store; bottom row: decode(mu). Titles: true (x, y) and the position estimator's reading of
mu, so the figure shows both what the 8 numbers keep of the picture and of the position.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from fmctd_dist.cli import run  # noqa: E402
from fmctd_dist.config import REPO_ROOT  # noqa: E402
from fmctd_dist.device import set_threads  # noqa: E402
from fmctd_dist.families.visual.config import load_parts_args, part_dir  # noqa: E402
from fmctd_dist.families.visual.frames import load_frame_set  # noqa: E402
from fmctd_dist.families.visual.latents import vae_dir  # noqa: E402
from fmctd_dist.families.visual.load import load_estimator, load_vae  # noqa: E402

FRAMES = 8


def main(argv: list[str]) -> int:
    cfg, pcfg, _ = load_parts_args(["part=vae", *argv])
    set_threads(1)
    vae = load_vae(vae_dir(cfg, pcfg), cfg.env.name)
    est = load_estimator(part_dir(cfg, pcfg.estimator.out, "estimator"), cfg.env.name, vae)
    fs = load_frame_set(cfg)
    picks = np.linspace(0, len(fs.val_images) - 1, FRAMES).round().astype(int)
    images, xy = fs.val_images[picks], fs.val_xy[picks]
    z = vae.encode(images)
    recon, guess = vae.decode(z), est(z)
    fig, axes = plt.subplots(2, FRAMES, figsize=(1.6 * FRAMES, 3.8))
    for k in range(FRAMES):
        for row, img in ((0, images[k]), (1, recon[k])):
            axes[row, k].imshow(img, interpolation="nearest")
            axes[row, k].set_xticks([])
            axes[row, k].set_yticks([])
        axes[0, k].set_title(f"({xy[k, 0]:.1f}, {xy[k, 1]:.1f})", fontsize=8)
        axes[1, k].set_title(f"est ({guess[k, 0]:.1f}, {guess[k, 1]:.1f})", fontsize=8)
    axes[0, 0].set_ylabel("frame", fontsize=8)
    axes[1, 0].set_ylabel("decode(mu)", fontsize=8)
    mse = vae.manifest["metrics"]["val_mse"]
    fig.suptitle(f"{cfg.env.name}: held-out frames and VAE reconstructions ({vae.latent_dim}-D z, VAE "
                 f"{vae.digest[:8]}, {vae.manifest['steps']} steps; val per-pixel MSE {mse:.4f})", fontsize=9)
    fig.tight_layout()
    out = REPO_ROOT / "docs" / "figures" / f"visual_vae_{cfg.env.name}.png"
    fig.savefig(out, dpi=110)
    print(out)
    return 0


if __name__ == "__main__":
    run(main)
