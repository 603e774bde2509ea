"""Denoiser quality and throughput report (docs/results.md, "Denoiser quality").

    python jobs/bench_denoiser.py                                  # every shipped checkpoint
    python jobs/bench_denoiser.py checkpoints/pointmaze-medium-h5  # one
    python jobs/bench_denoiser.py --throughput                     # transitions/s table only
    python jobs/bench_denoiser.py --precision checkpoints/pointmaze-medium-h1   # why plans warp

Quality, per checkpoint: validation loss (manifest), then 100 unguided and 100 guided plans
(20 per task start, full pyramid schedule = plain Diffusion Forcing sampling; Diffuser
checkpoints: all tokens denoised together, start inpainted): share of plans
without a warp (a step over 0.75 + 0.25 H: the authors' 1.0 dense, 2.0 at H=5), share of plan points inside free
maze cells, share of guided plans that come within 2.0 of the goal. These say whether a
search has anything to work with. Throughput: guided DDIM transitions per second.
"""

from __future__ import annotations

import json
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
    warp = 0.75 + 0.25 * cfg.jump  # the authors' 1.0 (H=1) and 2.0 (H=5), linear in between and beyond
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


def precision(ckpt: Path, batch: int = 64, timesteps: tuple[int, ...] = ()) -> list[str]:
    """x0-prediction error on validation windows noised to a few timesteps, in world units.

    Splits plan steps into token-boundary steps (last frame of a token -> first of the next)
    and steps inside a token: a model whose error is a per-token offset makes smooth tokens
    that do not join up, i.e. warps at every 10th frame. Also: the error at the first and the
    last plan frame against the middle one, and how far the first plan frames move when the
    clean start token moves by one normalised unit (a model that ignores its start: ~0).
    """
    from fmctd_dist.data.dataset import load_dataset
    from fmctd_dist.data.tokens import tokens_to_frames
    from fmctd_dist.data.windows import train_data
    from fmctd_dist.diffusion.schedule import alphas_cumprod, make_betas

    model, manifest = load_checkpoint(ckpt)
    model.eval()
    cfg = config_from_dict(manifest["config"])
    data = train_data(cfg, load_dataset(cfg))
    x = torch.as_tensor(data.val_batches(1, batch)[0])
    fs, std = cfg.model.frame_stack, data.normaliser.std
    dc = cfg.diffusion
    ab = torch.as_tensor(alphas_cumprod(make_betas(dc.beta_schedule, dc.timesteps, dc.beta_start, dc.beta_end)),
                         dtype=torch.float32)
    stab = dc.stabilization - 1
    timesteps = timesteps or tuple(int(f * dc.timesteps) - 1 for f in (0.02, 0.1, 0.3))

    def frames(tok):  # [B, F, 2] world-unit plan frames (scaled, not shifted: differences only)
        return tokens_to_frames(tok[:, 1:].numpy(), fs) * std

    def steps(tok):  # -> (boundary steps, inside-token steps); with one frame per token all are boundaries
        st = np.linalg.norm(np.diff(frames(tok), axis=1), axis=-1)
        at_boundary = (np.arange(st.shape[1]) + 1) % fs == 0
        return st[:, at_boundary], st[:, ~at_boundary] if fs > 1 else st[:, at_boundary]

    b, i = steps(x)
    lines = [f"{ckpt.name}: {batch} validation windows; data steps: boundary mean {b.mean():.3f} max {b.max():.3f}, "
             f"inside mean {i.mean():.3f} max {i.max():.3f}",
             "| timestep | x0 RMS error | identity RMS error | error at first / middle / last frame | "
             "boundary step mean / max | inside step mean / max | first frames per unit of start |",
             "|---|---|---|---|---|---|---|"]
    gen = torch.Generator().manual_seed(0)
    for t in timesteps:
        tt = torch.full(x.shape[:2], t)
        tt[:, 0] = stab
        a = ab[tt][..., None]
        xn = a.sqrt() * x + (1 - a).sqrt() * torch.randn(x.shape, generator=gen)
        xn[:, 0] = ab[stab].sqrt() * x[:, 0]  # the clean context, as the sampler feeds it
        moved = xn.clone()
        moved[:, 0] += 1.0
        with torch.no_grad():
            x0, x0_moved = model(xn, tt), model(moved, tt)
        err = np.linalg.norm(frames(x0) - frames(x), axis=-1)  # [B, F]
        per_frame = np.sqrt((err ** 2).mean(0))
        ident = np.linalg.norm(frames(xn / a.sqrt()) - frames(x), axis=-1)
        sens = float((x0_moved - x0)[:, 1, :].abs().mean())  # first plan token, normalised units
        b, i = steps(x0)
        lines.append(f"| {t} | {np.sqrt((err ** 2).mean()):.3f} | {np.sqrt((ident ** 2).mean()):.3f} | "
                     f"{per_frame[0]:.2f} / {per_frame[len(per_frame) // 2]:.2f} / {per_frame[-1]:.2f} | "
                     f"{b.mean():.3f} / {b.max():.2f} | {i.mean():.3f} / {i.max():.2f} | {sens:.3f} |")
    return lines


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
    if argv and argv[0] == "--precision":
        for a in argv[1:]:
            print("\n".join(precision(Path(a))) + "\n")
        return
    # every shipped planning model (DF or Diffuser); other checkpoints (the ant expert) have no model_kind
    ckpts = [Path(a) for a in argv] or sorted(p.parent for p in (REPO_ROOT / "checkpoints").glob("*/manifest.json")
                                              if "model_kind" in json.loads(p.read_text()))
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
