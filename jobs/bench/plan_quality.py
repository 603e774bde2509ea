"""Plan quality of a checkpoint without a search: what a planner has to work with.

    OMP_NUM_THREADS=1 python jobs/bench/plan_quality.py checkpoints/pointmaze-medium-h5 [more]   # a JSON row each

The measurements of jobs/bench_denoiser.py (docs/results.md section 4), jobs/bench/bench_recipe.py
(the recipe bench, issue 17), jobs/bench/quality_curve.py and jobs/probes/warp_sites.py, which import
this file (from jobs/bench, put on sys.path where they live elsewhere). Maze models:

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

Cube models (:func:`cube_plan_quality`, the cube row of the denoiser-quality table):
what the cube planner (issue 20) needs from a model, measured on unguided plans (object-wise
guidance is issue 20's): start states are 100 seeded (episode, step) points of the *validation*
play data, one plan each from the full Diffusion Forcing schedule, the same for the data's own
windows from those starts as the reference.

- **no warp**: no step moves any cube by more than the warp threshold (docs/reference.md §13: 1.0
  obs units dense, 2.0 at H=5; 0.75 + 0.25 H in between, as the mazes).
- **supported at the end**: every cube at the plan's last frame rests on the table (z within
  SUPPORT_TOL of 0.2) or on another cube (xy within STACK_XY, z one level, 0.4, higher): the
  value rule "not mid-air" applied where a plan hands over to the next.
- **one mover**: at most one cube ends more than MOVED from its start (the authors guide one cube
  and pin the others; an unguided model that moves two at once breaks that rule).
- **moved**: some cube ends more than MOVED from its start (a plan that does something).
- boundary / inside step: the mean per-cube step across token boundaries and inside tokens.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from fmctd_dist.cli import run
from fmctd_dist.config import Config, config_from_dict
from fmctd_dist.denoiser.local import LocalDenoiser
from fmctd_dist.denoiser.protocol import DenoiseBatch
from fmctd_dist.diffusion.checkpoint import load_checkpoint, normaliser_from_manifest, read_manifest
from fmctd_dist.diffusion.schedule import PyramidSchedule
from fmctd_dist.families import guide_map
from fmctd_dist.families.cube.data import load_cube_dataset
from fmctd_dist.families.cube.value import LEVEL, TABLE_Z, CubeValue
from fmctd_dist.families.maze.geometry import maze_geometry
from fmctd_dist.planners.fixed import uniform_levels
from fmctd_dist.registry import family, require_family
from fmctd_dist.tokens import PlanCodec

SAMPLES_PER_TASK = 20
GOAL_RADIUS = 2.0  # "within 2.0 of the goal": the value function's goal radius
# the cube search's own support rule (families/cube/value.py), so the table measures what the value will demand
STACK_DZ = LEVEL
SUPPORT_TOL = CubeValue.support_tol
STACK_XY = CubeValue.stack_xy
MOVED = 1.0  # obs units (0.1 m): a cube that ends this far from its start was moved by the plan
N_STARTS = 100


def warp_limit(jump: int) -> float:
    """The authors' 1.0 (H=1) and 2.0 (H=5), linear in between and beyond."""
    return 0.75 + 0.25 * jump


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
    guide = guide_map(cfg.env.name)  # the family's guide map (method.wall_guidance's wall term), else None
    denoiser = LocalDenoiser(model, cfg.diffusion, "cpu", micro_batch=micro_batch,
                             guide_map=None if guide is None else guide(cfg, manifest))
    geo = maze_geometry(cfg.env.name)
    starts = np.repeat(np.stack([t.init_xy for t in geo.tasks]), samples_per_task, 0)
    goals = np.repeat(np.stack([t.goal_xy for t in geo.tasks]), samples_per_task, 0)
    warp = warp_limit(cfg.jump)
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
    from fmctd_dist.data.windows import train_data
    from fmctd_dist.diffusion.schedule import alphas_cumprod, make_betas
    from fmctd_dist.families.maze.data import load_dataset
    from fmctd_dist.tokens import tokens_to_frames

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


def cube_steps(plans: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """[n, F, 3N] plans, [n, 3N] starts -> [n, F, N] per-cube step lengths (step 0: start -> frame 0)."""
    pts = np.concatenate([starts[:, None], plans], 1)
    d = np.diff(pts, axis=1)
    return np.linalg.norm(d.reshape(*d.shape[:2], -1, 3), axis=-1)


def supported(frame: np.ndarray) -> np.ndarray:
    """[n, 3N] cube xyz -> [n] every cube rests on the table or on another cube."""
    xyz = frame.reshape(len(frame), -1, 3)
    on_table = np.abs(xyz[..., 2] - TABLE_Z) < SUPPORT_TOL  # [n, N]
    dxy = np.linalg.norm(xyz[:, :, None, :2] - xyz[:, None, :, :2], axis=-1)  # [n, i, j]
    dz = xyz[:, :, None, 2] - xyz[:, None, :, 2]  # z_i - z_j
    n = xyz.shape[1]
    on_cube = ((dxy < STACK_XY) & (np.abs(dz - STACK_DZ) < SUPPORT_TOL) & ~np.eye(n, dtype=bool)).any(2)
    return (on_table | on_cube).all(1)


def plan_row(plans: np.ndarray, starts: np.ndarray, jump: int, frame_stack: int) -> dict[str, float]:
    """The quality numbers of plans [n, F, 3N] from starts [n, 3N] (see the module docstring)."""
    steps = cube_steps(plans, starts)  # [n, F, N]
    worst = steps.max(2)  # [n, F]: the largest cube step at each frame
    boundary, inside = boundary_and_inside(worst, frame_stack)
    moved = np.linalg.norm((plans[:, -1] - starts).reshape(len(starts), -1, 3), axis=-1) > MOVED  # [n, N]
    return {"no_warp": float((worst.max(1) <= warp_limit(jump)).mean()),
            "supported_end": float(supported(plans[:, -1]).mean()),
            "one_mover": float((moved.sum(1) <= 1).mean()),
            "moved": float(moved.any(1).mean()),
            "boundary_step": float(boundary.mean()), "inside_step": float(inside.mean()),
            "max_step": float(worst.max())}


def validation_starts(cfg: Config, n: int = N_STARTS, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """n seeded (episode, step) points of the validation split -> (starts [n, 3N], the data's own
    following horizon, subsampled every jump steps [n, F, 3N])."""
    val = load_cube_dataset(cfg).val  # [E, S, 3N]
    rng = np.random.default_rng([seed, 0xC0BE])
    ep = rng.integers(0, val.shape[0], n)
    off = rng.integers(0, val.shape[1] - cfg.env.horizon, n)
    idx = off[:, None] + np.arange(cfg.jump, cfg.env.horizon + 1, cfg.jump)[None]
    return val[ep, off], val[ep[:, None], idx]


def cube_plan_quality(ckpt: Path, cfg: Config | None = None, n: int = N_STARTS,
                      micro_batch: int = 50) -> dict[str, Any]:
    """One row for a cube checkpoint: unguided model plans beside the data's own windows."""
    model, manifest = load_checkpoint(ckpt, cfg)
    cfg = cfg or config_from_dict(manifest["config"])
    require_family(cfg.env.name, ("cube",), "the cube plan-quality measure")
    codec = PlanCodec(normaliser_from_manifest(manifest), cfg.model.frame_stack)
    denoiser = LocalDenoiser(model, cfg.diffusion, "cpu", micro_batch=micro_batch)
    starts, data = validation_starts(cfg, n)
    t0 = time.perf_counter()
    plans = sample_plans(denoiser, cfg, codec, starts, starts, 0.0, seed=0)
    row: dict[str, Any] = {"checkpoint": ckpt.name, "steps": manifest["train_steps"],
                           "params": manifest["param_count"], "val_loss": manifest["final_losses"]["val"],
                           "train_h": manifest["wall_time_s"] / 3600, "warp": warp_limit(cfg.jump)}
    row["model"] = plan_row(plans, starts, cfg.jump, cfg.model.frame_stack)
    row["data"] = plan_row(data, starts, cfg.jump, cfg.model.frame_stack)
    row["sample_s"] = time.perf_counter() - t0
    return row


def main(argv: list[str]) -> int:
    torch.set_num_threads(1)
    if not argv:
        print(__doc__)
        return 2
    for ckpt in map(Path, argv):
        env = read_manifest(ckpt)["config"]["env"]["name"]
        print(json.dumps(cube_plan_quality(ckpt) if family(env) == "cube" else plan_quality(ckpt)), flush=True)
    return 0


if __name__ == "__main__":
    run(main)
