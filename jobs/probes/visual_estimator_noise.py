"""Probe: does a position estimator trained with latent noise read a visual planner's plans more smoothly?

    python jobs/probes/visual_estimator_noise.py                      # visual-pointmaze-medium, the shipped planner

The value and the guidance read latent plans through the position estimator, which saw only real
latents. If the plans' 9-11 unit jumps (docs/results.md 13.4) were the estimator extrapolating off
the VAE's manifold, an estimator trained on latents with added Gaussian noise (sigma x the latent's
per-dimension std) would read the same plans with small steps. One Fast-MCTD search per task
(seed 0, the shipped estimator guiding) gives the plans; each estimator, trained on the latent
store's train episodes, then reads them. Prints one markdown row per estimator.
"""

from __future__ import annotations

import time

import numpy as np
import torch

from fmctd_dist.cli import run
from fmctd_dist.config import Config, load_config
from fmctd_dist.device import set_threads
from fmctd_dist.families.visual.guide import Positions
from fmctd_dist.families.visual.mlp import build_mlp
from visual_plan_quality import TaskSearch, estimated_steps, search_task, visual_planner

SIGMAS = (0.0, 0.1, 0.3, 0.6)  # noise std in units of each latent dimension's std over the train latents
WARP = 2.0  # the maze's sparse warp threshold, on estimated positions


def store_arrays(cfg: Config) -> dict[str, np.ndarray]:
    from fmctd_dist.families.visual.dataset import _parts
    from fmctd_dist.families.visual.latents import load_latents, vae_dir
    from fmctd_dist.families.visual.load import load_vae

    pcfg = _parts(cfg)
    store = load_latents(cfg, pcfg, load_vae(vae_dir(cfg, pcfg), cfg.env.name))
    tr, va = store.split("train"), store.split("val")
    d = tr["mu"].shape[-1]
    return {"x": tr["mu"].reshape(-1, d).astype(np.float32), "y": tr["xy"].reshape(-1, 2).astype(np.float32),
            "val_x": va["mu"].reshape(-1, d).astype(np.float32), "val_y": va["xy"].reshape(-1, 2).astype(np.float64),
            "val_paths": va["mu"][:, ::5]}


def train_estimator(a: dict[str, np.ndarray], sigma: float, steps: int = 6000, seed: int = 0) -> Positions:
    """The estimator's MLP (8 -> 512 -> 512 -> 2), Adam 1e-3, batch 256, inputs jittered by sigma x latent std."""
    x, y = a["x"], a["y"]
    net = build_mlp(x.shape[1], 2, [512, 512], seed)
    net.set_normaliser(x, y)
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    rng = np.random.default_rng(seed)
    xt, yt, zstd = torch.from_numpy(x), torch.from_numpy(y), x.std(0)
    for _ in range(steps):
        i = torch.from_numpy(rng.integers(0, len(x), 256))
        noise = torch.from_numpy((sigma * zstd * rng.standard_normal((256, x.shape[1]))).astype(np.float32))
        loss = ((net(xt[i] + noise) - yt[i]) / net.out_std).pow(2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
    return Positions(net)


def row(name: str, pos: Positions, a: dict[str, np.ndarray], searches: list[TaskSearch]) -> str:
    val_rmse = np.sqrt(np.mean(np.sum((pos(a["val_x"]) - a["val_y"]) ** 2, -1)))
    real_moves = np.linalg.norm(np.diff(pos(a["val_paths"]), axis=1), axis=-1)
    warping, largest, first = [], [], []
    for search in searches:
        steps = estimated_steps(pos, search.plans, search.z)[:, :-1]
        warping.append(f"{100 * (steps.max(1) > WARP).mean():.0f}%")
        largest.append(np.median(steps.max(1)))
        first.append(np.median(steps[:, 0]))
    return (f"| {name} | {val_rmse:.3f} | {np.percentile(real_moves, 99):.2f} / {real_moves.max():.2f} | "
            f"{' '.join(warping)} | {np.median(largest):.2f} | {np.median(first):.2f} |")


def main(argv: list[str]) -> int:
    cfg = load_config(["env=visual-pointmaze-medium", "method=fast-mctd"] + argv, env="visual-pointmaze-medium")
    set_threads(cfg.eval.threads or 1)
    a = store_arrays(cfg)
    t0 = time.time()
    planner, episodes, _, _ = visual_planner(cfg)
    searches = [search_task(cfg, planner, episodes, task) for task in cfg.eval.tasks]
    shipped = episodes.frames
    print(f"searched in {time.time() - t0:.0f}s; plans per task {[len(s.plans) for s in searches]}", flush=True)
    print("| estimator | val RMSE | real 5-step move p99 / max | warping plans per task | median largest step "
          "| median first step |\n|---|---|---|---|---|---|")
    print(row("shipped", shipped, a, searches), flush=True)
    for sigma in SIGMAS:
        t0 = time.time()
        pos = train_estimator(a, sigma)
        print(row(f"store-trained, noise {sigma} std ({time.time() - t0:.0f} s)", pos, a, searches), flush=True)
    return 0


if __name__ == "__main__":
    run(main)
