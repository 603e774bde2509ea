"""Where a maze model's plans warp (issue 17): the first step, token boundaries or inside tokens.

    OMP_NUM_THREADS=1 python jobs/probes/warp_sites.py checkpoints/pointmaze-large-h1 [more checkpoints]

The value zeroes a plan with any step over the warp limit (0.75 + 0.25 H), and its first step is
start -> first plan frame (docs/reference.md §4). For each checkpoint, on the noise of the quality table
(20 plans per task start, unguided and guided; jobs/bench/plan_quality.py, sample_plans):
the share of warp-free plans, where the warps sit (first step, later token boundaries, inside
tokens), the plans whose only warp is the first step, and per task the warp-free share. Then the
first step from starts the tasks do not pick: 100 seeded validation-window starts (beside the
data's own next frame) and every free cell centre (task starts are cell centres). A model that
does not hold its first frame to the start shows here, not in the token loss.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np

from fmctd_dist.cli import run
from fmctd_dist.config import Config, config_from_dict
from fmctd_dist.tokens import PlanCodec
from fmctd_dist.denoiser.local import LocalDenoiser
from fmctd_dist.diffusion.checkpoint import load_checkpoint, normaliser_from_manifest
from fmctd_dist.families.maze.geometry import maze_geometry

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))  # jobs/bench/plan_quality.py
from plan_quality import SAMPLES_PER_TASK, sample_plans, warp_limit  # noqa: E402

VAL_STARTS = 100


def plan_steps(start: np.ndarray, plans: np.ndarray) -> np.ndarray:
    """[n, F] step lengths of plans [n, F, 2] from starts [n, 2]; step 0 is start -> first frame."""
    return np.linalg.norm(np.diff(np.concatenate([start[:, None], plans], 1), axis=1), axis=-1)


def sites(steps: np.ndarray, warp: float, frame_stack: int) -> dict[str, float]:
    """Shares of plans: warp-free, warping at the first step, at a later token boundary, inside a token,
    and warping only at the first step (the ones a held start would make warp-free)."""
    w = steps > warp
    col = np.arange(steps.shape[1])
    later_boundary = w[:, (col % frame_stack == 0) & (col > 0)].any(1)
    inside = w[:, col % frame_stack != 0].any(1) if frame_stack > 1 else np.zeros(len(w), bool)
    return {"no_warp": float((~w.any(1)).mean()), "first": float(w[:, 0].mean()),
            "later_boundary": float(later_boundary.mean()), "inside": float(inside.mean()),
            "only_first": float((w[:, 0] & ~w[:, 1:].any(1)).mean())}


def first_steps(denoiser: LocalDenoiser, cfg: Config, codec: PlanCodec, starts: np.ndarray,
                goal: np.ndarray) -> np.ndarray:
    """[n] unguided first-step lengths from ``starts`` [n, 2] (any goal: unguided plans ignore it)."""
    plans = sample_plans(denoiser, cfg, codec, starts, np.repeat(goal[None], len(starts), 0), 0.0, seed=0)
    return plan_steps(starts, plans)[:, 0]


def warp_sites(ckpt: Path, samples_per_task: int = SAMPLES_PER_TASK, val_starts: int = VAL_STARTS) -> dict[str, Any]:
    model, manifest = load_checkpoint(ckpt)
    cfg = config_from_dict(manifest["config"])
    codec = PlanCodec(normaliser_from_manifest(manifest), cfg.model.frame_stack)
    denoiser = LocalDenoiser(model, cfg.diffusion, "cpu", micro_batch=50)
    geo = maze_geometry(cfg.env.name)
    warp = warp_limit(cfg.jump)
    n = samples_per_task
    starts = np.repeat(np.stack([t.init_xy for t in geo.tasks]), n, 0).astype(np.float32)
    goals = np.repeat(np.stack([t.goal_xy for t in geo.tasks]), n, 0).astype(np.float32)
    out: dict[str, Any] = {"checkpoint": str(ckpt), "digest": manifest["digest"], "warp": warp}
    for name, scale in (("unguided", 0.0), ("guided", cfg.method.guidance_scale)):
        steps = plan_steps(starts, sample_plans(denoiser, cfg, codec, starts, goals, scale, seed=0))
        out[name] = sites(steps, warp, cfg.model.frame_stack)
        out[name]["first_step"] = float(steps[:, 0].mean())
        out[name]["per_task"] = [float((steps[k * n:(k + 1) * n].max(1) <= warp).mean()) for k in range(len(geo.tasks))]

    from fmctd_dist.families.maze.data import load_dataset

    val = load_dataset(cfg).val  # [E, S, d] positions
    rng = np.random.default_rng(0)
    ep = rng.integers(0, val.shape[0], val_starts)
    off = rng.integers(0, val.shape[1] - cfg.jump, val_starts)
    s = val[ep, off, :2].astype(np.float32)
    d = first_steps(denoiser, cfg, codec, s, geo.tasks[0].goal_xy.astype(np.float32))
    data = np.linalg.norm(val[ep, off + cfg.jump, :2] - s, axis=1)
    out["val_starts"] = {"n": val_starts, "median": float(np.median(d)), "p90": float(np.percentile(d, 90)),
                         "over_warp": float((d > warp).mean()), "data_median": float(np.median(data))}
    centres = np.stack([geo.cell_to_xy(ij) for ij in geo.free_cells()]).astype(np.float32)
    d = first_steps(denoiser, cfg, codec, centres, geo.tasks[0].goal_xy.astype(np.float32))
    out["cell_centres"] = {"n": len(centres), "median": float(np.median(d)), "p90": float(np.percentile(d, 90)),
                           "over_warp": float((d > warp).mean())}
    return out


def lines(r: dict[str, Any]) -> list[str]:
    pct = lambda v: f"{100 * v:.0f}%"  # noqa: E731
    out = [f"{r['checkpoint']} (`{r['digest']}`), warp limit {r['warp']:.2f}",
           "| plans | warp-free | warp at the first step | at a later boundary | inside a token | "
           "only at the first step | mean first step | warp-free per task |", "|---|---|---|---|---|---|---|---|"]
    for name in ("unguided", "guided"):
        s = r[name]
        out.append(f"| {name} | {pct(s['no_warp'])} | {pct(s['first'])} | {pct(s['later_boundary'])} | "
                   f"{pct(s['inside'])} | {pct(s['only_first'])} | {s['first_step']:.2f} | "
                   f"{' / '.join(pct(v) for v in s['per_task'])} |")
    v, c = r["val_starts"], r["cell_centres"]
    out.append(f"first step (unguided) from {v['n']} validation starts: median {v['median']:.2f} "
               f"(the data's next frame: {v['data_median']:.2f}), p90 {v['p90']:.2f}, "
               f"over the limit {pct(v['over_warp'])}; "
               f"from the {c['n']} free cell centres: median {c['median']:.2f}, p90 {c['p90']:.2f}, "
               f"over the limit {pct(c['over_warp'])}")
    return out


def main(argv: list[str]) -> int:
    import torch

    torch.set_num_threads(1)
    if not argv:
        print(__doc__)
        return 2
    for a in argv:
        print("\n".join(lines(warp_sites(Path(a)))) + "\n", flush=True)
    return 0


if __name__ == "__main__":
    run(main)
