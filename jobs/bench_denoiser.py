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
search has anything to work with (the measurements live in fmctd_dist.evaluation.plan_quality,
shared with jobs/bench_recipe.py). Throughput: guided DDIM transitions per second.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import torch

from fmctd_dist.config import REPO_ROOT
from fmctd_dist.diffusion.model import DFTransformer
from fmctd_dist.evaluation.plan_quality import plan_quality, precision


def precision_lines(ckpt: Path, batch: int = 64, timesteps: tuple[int, ...] = ()) -> list[str]:
    """The precision table of one checkpoint (fmctd_dist.evaluation.plan_quality.precision) as markdown."""
    p = precision(ckpt, batch, timesteps)
    d = p["data"]
    lines = [f"{p['checkpoint']}: {batch} validation windows; data steps: boundary mean {d['boundary_mean']:.3f} "
             f"max {d['boundary_max']:.3f}, inside mean {d['inside_mean']:.3f} max {d['inside_max']:.3f}",
             "| timestep | x0 RMS error | identity RMS error | error at first / middle / last frame | "
             "boundary step mean / max | inside step mean / max | first frames per unit of start |",
             "|---|---|---|---|---|---|---|"]
    for r in p["rows"]:
        lines.append(f"| {r['timestep']} | {r['x0_rms']:.3f} | {r['identity_rms']:.3f} | "
                     f"{r['first']:.2f} / {r['middle']:.2f} / {r['last']:.2f} | "
                     f"{r['boundary_mean']:.3f} / {r['boundary_max']:.2f} | {r['inside_mean']:.3f} / "
                     f"{r['inside_max']:.2f} | {r['start_sensitivity']:.3f} |")
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
            print("\n".join(precision_lines(Path(a))) + "\n")
        return
    # every shipped planning model (DF or Diffuser); other checkpoints (the ant expert) have no model_kind
    ckpts = [Path(a) for a in argv] or sorted(p.parent for p in (REPO_ROOT / "checkpoints").glob("*/manifest.json")
                                              if "model_kind" in json.loads(p.read_text()))
    print("| checkpoint | steps | params | val loss | train h | unguided: no warp / in free cells | "
          "guided: no warp / in free cells / within 2.0 of goal |")
    print("|---|---|---|---|---|---|---|")
    for ckpt in ckpts:
        r = plan_quality(ckpt)
        print(f"| {r['checkpoint']} | {r['steps']} | {r['params']:,} | {r['val_loss'] if r['val_loss'] is None else round(r['val_loss'], 4)} | {r['train_h']:.2f} | "
              f"{100 * r['unguided_no_warp']:.0f}% / {100 * r['unguided_in_free']:.1f}% | "
              f"{100 * r['guided_no_warp']:.0f}% / {100 * r['guided_in_free']:.1f}% / "
              f"{100 * r['guided_near_goal']:.0f}% |")


if __name__ == "__main__":
    main(sys.argv[1:])
