"""Denoiser quality and throughput report (docs/results.md, "Denoiser quality").

    python jobs/bench_denoiser.py                                  # every shipped checkpoint
    python jobs/bench_denoiser.py checkpoints/pointmaze-medium-h5  # one
    python jobs/bench_denoiser.py --throughput                     # transitions/s table only

Quality, per checkpoint: validation loss (manifest), then 100 unguided and 100 guided plans
(20 per task start, full pyramid schedule = plain Diffusion Forcing sampling; Diffuser
checkpoints: all tokens denoised together, start inpainted): share of plans
without a warp (a step over the method's warp threshold), share of plan points inside free
maze cells, share of guided plans that come within 2.0 of the goal. These say whether a
search has anything to work with. Throughput: guided DDIM transitions per second.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import torch

from fmctd_dist.config import REPO_ROOT, config_from_dict
from fmctd_dist.data.tokens import PlanCodec
from fmctd_dist.denoiser.local import LocalDenoiser
from fmctd_dist.denoiser.protocol import DenoiseBatch
from fmctd_dist.diffusion.checkpoint import load_checkpoint, normaliser_from_manifest
from fmctd_dist.diffusion.model import DFTransformer
from fmctd_dist.diffusion.schedule import PyramidSchedule
from fmctd_dist.envs import maze_geometry
from fmctd_dist.planners.diffuser import uniform_levels

SAMPLES_PER_TASK = 20


def full_levels(cfg) -> np.ndarray:
    """[R+1, T] the whole denoising schedule of a plan: the pyramid (DF) or all tokens together (Diffuser)."""
    if cfg.model.kind == "diffuser":
        return uniform_levels(cfg.plan_tokens, cfg.diffusion.levels)
    return PyramidSchedule(cfg.plan_tokens, cfg.diffusion.levels).full()


def sample_plans(denoiser, cfg, codec, start, goal, scale, seed) -> np.ndarray:
    """[n, F, 2] world plans from the full schedule, one noise seed per sample."""
    n = len(start)
    full = full_levels(cfg)
    noise = np.stack([np.random.default_rng([seed, i]).standard_normal((cfg.plan_tokens, cfg.token_dim))
                      for i in range(n)]).astype(np.float32)
    x = np.concatenate([codec.context(start), np.clip(noise, -20, 20)], axis=1)
    levels = np.broadcast_to(full, (n, *full.shape)).copy()
    norm = codec.normaliser
    out = denoiser.denoise(DenoiseBatch(x, levels, np.full(n, scale, np.float32), norm.normalise(start),
                                        norm.normalise(goal)))
    return codec.decode(out.x)


def quality(ckpt: Path) -> dict:
    model, manifest = load_checkpoint(ckpt)
    cfg = config_from_dict(manifest["config"])
    codec = PlanCodec(normaliser_from_manifest(manifest), cfg.model.frame_stack)
    denoiser = LocalDenoiser(model, cfg.diffusion, "cpu", micro_batch=50)
    geo = maze_geometry(cfg.env.name)
    starts = np.repeat(np.stack([t.init_xy for t in geo.tasks]), SAMPLES_PER_TASK, 0)
    goals = np.repeat(np.stack([t.goal_xy for t in geo.tasks]), SAMPLES_PER_TASK, 0)
    warp = 1.0 if cfg.jump == 1 else 2.0
    row = {"checkpoint": ckpt.name, "steps": manifest["train_steps"], "params": manifest["param_count"],
           "val_loss": manifest["final_losses"]["val"], "train_h": manifest["wall_time_s"] / 3600}
    for name, scale in (("unguided", 0.0), ("guided", cfg.method.guidance_scale)):
        t0 = time.perf_counter()
        plans = sample_plans(denoiser, cfg, codec, starts, goals, scale, seed=0)
        steps = np.linalg.norm(np.diff(np.concatenate([starts[:, None], plans], 1), axis=1), axis=-1)
        row[f"{name}_no_warp"] = float((steps.max(1) <= warp).mean())
        row[f"{name}_in_free"] = float(geo.in_free_cell(plans).mean())
        row[f"{name}_near_goal"] = float((np.linalg.norm(plans - goals[:, None], axis=-1).min(1) < 2.0).mean())
        row[f"{name}_s"] = time.perf_counter() - t0
    return row


def throughput(batches=(1, 25, 200), tokens=(11, 21, 51, 101), width=128, layers=6, reps=3) -> list[str]:
    from fmctd_dist.config import DiffusionConfig
    from fmctd_dist.diffusion.sampler import make_consts, transition

    consts = make_consts(DiffusionConfig())
    lines = ["| tokens | batch 1 | batch 25 | batch 200 |", "|---|---|---|---|"]
    for t in tokens:
        model = DFTransformer(20, t, width, layers, 4, 512).eval().requires_grad_(False)
        cells = []
        for b in batches:
            x = torch.randn(b, t, 20)
            a = torch.full((b, t), 30)
            a[:, 0] = 0
            bl = (a - 1).clamp(min=0)
            scale, s, g = torch.full((b,), 1.0), torch.zeros(b, 2), torch.ones(b, 2)
            transition(model, consts, x, a, bl, scale, s, g)  # warm-up
            t0 = time.perf_counter()
            for _ in range(reps):
                transition(model, consts, x, a, bl, scale, s, g)
            dt = (time.perf_counter() - t0) / reps
            cells.append(f"{b / dt:,.0f}")
        lines.append(f"| {t} | " + " | ".join(cells) + " |")
    return lines


def main(argv: list[str]) -> None:
    torch.manual_seed(0)
    if argv and argv[0] == "--throughput":
        print(f"guided transitions/s (jobs x transitions per second), torch threads={torch.get_num_threads()}")
        print("\n".join(throughput()))
        return
    ckpts = [Path(a) for a in argv] or sorted(p.parent for p in (REPO_ROOT / "checkpoints").glob("*/manifest.json"))
    print("| checkpoint | steps | params | val loss | train h | unguided: no warp / in free cells | "
          "guided: no warp / in free cells / within 2.0 of goal |")
    print("|---|---|---|---|---|---|---|")
    for ckpt in ckpts:
        r = quality(ckpt)
        print(f"| {r['checkpoint']} | {r['steps']} | {r['params']:,} | {r['val_loss'] if r['val_loss'] is None else round(r['val_loss'], 4)} | {r['train_h']:.2f} | "
              f"{100 * r['unguided_no_warp']:.0f}% / {100 * r['unguided_in_free']:.1f}% | "
              f"{100 * r['guided_no_warp']:.0f}% / {100 * r['guided_in_free']:.1f}% / "
              f"{100 * r['guided_near_goal']:.0f}% |")


if __name__ == "__main__":
    main(sys.argv[1:])
