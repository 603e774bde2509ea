"""Plan quality of a checkpoint without a search: what a planner has to work with.

Two measurements, shared by jobs/bench_denoiser.py (docs/results.md section 4) and
jobs/bench/bench_recipe.py (the recipe bench, issue 17):

- :func:`plan_quality`: 100 unguided and 100 guided plans (20 per task start, the full
  schedule = plain Diffusion Forcing sampling; Diffuser: all tokens together, start
  inpainted): share without a warp (a step over 0.75 + 0.25 H), share of points in free maze
  cells, share of plans whose whole path (start included, 10 points per step) crosses no
  wall, share both warp-free and wall-free ("valid": the value's warp test sees jumps, not
  walls), share of guided plans within 2.0 of the goal, the mean step across token
  boundaries / inside tokens (a model whose error is a per-token offset jumps at boundaries),
  and the first step (start -> first plan frame: mean, and share of plans that warp there).
- :func:`precision`: x0 error on validation windows noised to a few timesteps, in world
  units, split into token-boundary and inside-token steps, plus the start sensitivity.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from fmctd_dist.config import Config, config_from_dict
from fmctd_dist.tokens import PlanCodec
from fmctd_dist.denoiser.local import LocalDenoiser
from fmctd_dist.denoiser.protocol import DenoiseBatch
from fmctd_dist.diffusion.checkpoint import load_checkpoint, normaliser_from_manifest
from fmctd_dist.diffusion.schedule import PyramidSchedule
from fmctd_dist.families.maze.geometry import maze_geometry
from fmctd_dist.planners.fixed import uniform_levels

SAMPLES_PER_TASK = 20
GOAL_RADIUS = 2.0  # "within 2.0 of the goal": the value function's goal radius


def full_levels(cfg: Config) -> np.ndarray:
    """[R+1, T] the whole denoising schedule of a plan: the pyramid (DF) or all tokens together (Diffuser)."""
    if cfg.model.kind == "diffuser":
        return uniform_levels(cfg.plan_tokens, cfg.diffusion.levels)
    return PyramidSchedule(cfg.plan_tokens, cfg.diffusion.levels).full()


def sample_plans(denoiser: LocalDenoiser, cfg: Config, codec: PlanCodec, start: np.ndarray, goal: np.ndarray,
                 scale: float, seed: int) -> np.ndarray:
    """[n, F, 2] world plans from the full schedule, one noise seed per sample (start, goal: [n, 2])."""
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


def boundary_and_inside(steps: np.ndarray, frame_stack: int) -> tuple[np.ndarray, np.ndarray]:
    """Split plan steps [n, F] (step j: point j -> j+1, point 0 = the start) into the steps that
    cross a token boundary (j % frame_stack == 0, the first one from the start) and the rest.
    With one frame per token every step is a boundary step (returned for both)."""
    at_boundary = np.arange(steps.shape[1]) % frame_stack == 0
    return steps[:, at_boundary], steps[:, ~at_boundary] if frame_stack > 1 else steps[:, at_boundary]


def plan_quality(ckpt: Path, cfg: Config | None = None, samples_per_task: int = SAMPLES_PER_TASK,
                 micro_batch: int = 50) -> dict[str, Any]:
    """One row of plan-quality numbers for a checkpoint (see the module docstring).

    ``cfg`` (default: the manifest's) gives the sampling settings (diffusion.guidance_path,
    method.guidance_scale); it must agree with the checkpoint.
    """
    model, manifest = load_checkpoint(ckpt, cfg)
    cfg = cfg or config_from_dict(manifest["config"])
    codec = PlanCodec(normaliser_from_manifest(manifest), cfg.model.frame_stack)
    denoiser = LocalDenoiser(model, cfg.diffusion, "cpu", micro_batch=micro_batch)
    geo = maze_geometry(cfg.env.name)
    starts = np.repeat(np.stack([t.init_xy for t in geo.tasks]), samples_per_task, 0)
    goals = np.repeat(np.stack([t.goal_xy for t in geo.tasks]), samples_per_task, 0)
    warp = 0.75 + 0.25 * cfg.jump  # the authors' 1.0 (H=1) and 2.0 (H=5), linear in between and beyond
    row = {"checkpoint": ckpt.name, "steps": manifest["train_steps"], "params": manifest["param_count"],
           "val_loss": manifest["final_losses"]["val"], "train_h": manifest["wall_time_s"] / 3600}
    for name, scale in (("unguided", 0.0), ("guided", cfg.method.guidance_scale)):
        t0 = time.perf_counter()
        plans = sample_plans(denoiser, cfg, codec, starts, goals, scale, seed=0)
        path = np.concatenate([starts[:, None], plans], 1)
        steps = np.linalg.norm(np.diff(path, axis=1), axis=-1)
        boundary, inside = boundary_and_inside(steps, cfg.model.frame_stack)
        no_warp, wall_free = steps.max(1) <= warp, geo.path_in_free(path)
        row[f"{name}_no_warp"] = float(no_warp.mean())
        row[f"{name}_in_free"] = float(geo.in_free_cell(plans).mean())
        row[f"{name}_wall_free"] = float(wall_free.mean())
        row[f"{name}_valid"] = float((no_warp & wall_free).mean())  # what a robot could follow
        row[f"{name}_near_goal"] = float((np.linalg.norm(plans - goals[:, None], axis=-1).min(1) < GOAL_RADIUS).mean())
        row[f"{name}_first_step"] = float(steps[:, 0].mean())  # start -> first plan frame (the value checks it too)
        row[f"{name}_first_warp"] = float((steps[:, 0] > warp).mean())
        row[f"{name}_boundary_step"] = float(boundary.mean())
        row[f"{name}_inside_step"] = float(inside.mean())
        row[f"{name}_s"] = time.perf_counter() - t0
    return row


def precision(ckpt: Path, batch: int = 64, timesteps: tuple[int, ...] = ()) -> dict[str, Any]:
    """x0-prediction error on ``batch`` validation windows noised to ``timesteps`` (default 2%, 10%,
    30% of the schedule), in world units.

    Returns {"checkpoint", "data": {boundary/inside step mean/max of the windows themselves},
    "rows": [one dict per timestep]}: x0 RMS error, the identity's (returning the noisy input),
    the error at the first / middle / last plan frame, the boundary and inside steps of x0_hat,
    and how far the first plan token moves when the clean start token moves by one normalised
    unit (a model that ignores its start: ~0).
    """
    from fmctd_dist.families.maze.data import load_dataset
    from fmctd_dist.tokens import tokens_to_frames
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

    def steps(tok):  # -> (boundary steps, inside-token steps) between plan frames (frame 10k-1 -> 10k)
        st = np.linalg.norm(np.diff(frames(tok), axis=1), axis=-1)
        at_boundary = (np.arange(st.shape[1]) + 1) % fs == 0
        return st[:, at_boundary], st[:, ~at_boundary] if fs > 1 else st[:, at_boundary]

    b, i = steps(x)
    out = {"checkpoint": ckpt.name, "batch": batch,
           "data": {"boundary_mean": float(b.mean()), "boundary_max": float(b.max()),
                    "inside_mean": float(i.mean()), "inside_max": float(i.max())}, "rows": []}
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
        b, i = steps(x0)
        out["rows"].append({
            "timestep": t, "x0_rms": float(np.sqrt((err ** 2).mean())),
            "identity_rms": float(np.sqrt((ident ** 2).mean())),
            "first": float(per_frame[0]), "middle": float(per_frame[len(per_frame) // 2]), "last": float(per_frame[-1]),
            "boundary_mean": float(b.mean()), "boundary_max": float(b.max()),
            "inside_mean": float(i.mean()), "inside_max": float(i.max()),
            "start_sensitivity": float((x0_moved - x0)[:, 1, :].abs().mean()),  # first plan token, normalised units
        })
    return out
