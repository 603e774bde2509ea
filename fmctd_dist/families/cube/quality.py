"""Plan quality of a cube model without a search: the cube row of the denoiser-quality table.

What the cube planner (issue 20) will need from a model, measured on unguided plans (object-wise
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

import time
from pathlib import Path
from typing import Any

import numpy as np

from fmctd_dist.config import Config, config_from_dict
from fmctd_dist.tokens import PlanCodec
from fmctd_dist.denoiser.local import LocalDenoiser
from fmctd_dist.diffusion.checkpoint import load_checkpoint, normaliser_from_manifest
from fmctd_dist.families.maze.plan_quality import boundary_and_inside, sample_plans
from fmctd_dist.registry import require_family
from fmctd_dist.families.cube.data import load_cube_dataset
from fmctd_dist.families.cube.value import LEVEL, TABLE_Z, CubeValue

# the search's own support rule (families/cube/value.py), so the table measures what the value will demand
STACK_DZ = LEVEL
SUPPORT_TOL = CubeValue.support_tol
STACK_XY = CubeValue.stack_xy
MOVED = 1.0  # obs units (0.1 m): a cube that ends this far from its start was moved by the plan
N_STARTS = 100


def warp_threshold(jump: int) -> float:
    return 0.75 + 0.25 * jump


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
    return {"no_warp": float((worst.max(1) <= warp_threshold(jump)).mean()),
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
                           "train_h": manifest["wall_time_s"] / 3600, "warp": warp_threshold(cfg.jump)}
    row["model"] = plan_row(plans, starts, cfg.jump, cfg.model.frame_stack)
    row["data"] = plan_row(data, starts, cfg.jump, cfg.model.frame_stack)
    row["sample_s"] = time.perf_counter() - t0
    return row
