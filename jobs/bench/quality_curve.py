"""Quality against training time (issue 17): how much compute a model needs on this machine.

    OMP_NUM_THREADS=1 python jobs/bench/quality_curve.py runs/campaign/pointmaze-medium-h5 [--plot docs/figures/x.png]

Measures every snapshot a run kept (``train.snapshot_every_s``, under <run>/snapshots/) and the
run itself with the plan-level numbers of the denoiser-quality table (maze models: unguided and
guided warp-free share, guided valid share (warp-free and crossing no wall), guided boundary
step, x0 error at the last level; cube models: the cube row), prints one markdown table, row per
snapshot, and draws warp-free share against CPU hours.
Each measurement is cached in <snapshot>/quality.json under the checkpoint's digest, so a rerun
measures only new snapshots (and maze rows cached before the valid-plan fields existed).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from fmctd_dist.diffusion.checkpoint import lineage, read_manifest
from fmctd_dist.resume import SNAPSHOTS
from fmctd_dist.registry import family

CACHE = "quality.json"


def measure(ckpt: Path) -> dict[str, Any]:
    """One curve point for a checkpoint dir (cached under its digest), with the training behind the
    weights through every train.init_from ancestor (from the manifest, not the cache, so rows cached
    before that field existed get it too)."""
    manifest = read_manifest(ckpt)
    total = lineage(manifest)
    behind = {"total_steps": total["lineage_steps"], "total_samples": total["lineage_samples"],
              "total_cpu_h": None if total["lineage_cpu_s"] is None else total["lineage_cpu_s"] / 3600}
    cache = ckpt / CACHE
    if cache.exists():
        row = json.loads(cache.read_text())
        if row.get("digest") == manifest["digest"] and (family(row["env"]) == "cube" or "guided_valid" in row):
            return {**row, **behind}
    return {**_measured(ckpt, manifest), **behind}


def _measured(ckpt: Path, manifest: dict[str, Any]) -> dict[str, Any]:
    """The plan-level numbers of one checkpoint, written to its cache."""
    import torch

    torch.set_num_threads(1)
    cache = ckpt / CACHE
    env = manifest["config"]["env"]["name"]
    row: dict[str, Any] = {"digest": manifest["digest"], "steps": manifest["train_steps"], "env": env,
                           "cpu_h": manifest.get("cpu_time_s", manifest["wall_time_s"]) / 3600,
                           "wall_h": manifest["wall_time_s"] / 3600, "val_loss": manifest["final_losses"]["val"]}
    if family(env) == "cube":
        from plan_quality import cube_plan_quality

        q = cube_plan_quality(ckpt)["model"]
        row.update(unguided_no_warp=q["no_warp"], boundary_step=q["boundary_step"], supported_end=q["supported_end"])
    else:
        from plan_quality import plan_quality, precision

        q = plan_quality(ckpt)
        p = precision(ckpt, timesteps=(19,))
        row.update(unguided_no_warp=q["unguided_no_warp"], guided_no_warp=q["guided_no_warp"],
                   guided_boundary_step=q["guided_boundary_step"], guided_in_free=q["guided_in_free"],
                   guided_first_step=q["guided_first_step"], guided_first_warp=q["guided_first_warp"],
                   unguided_valid=q["unguided_valid"], guided_valid=q["guided_valid"],
                   x0_rms=p["rows"][0]["x0_rms"], boundary_max=p["rows"][0]["boundary_max"],
                   data_boundary_mean=p["data"]["boundary_mean"])
    cache.write_text(json.dumps(row, indent=1) + "\n")
    return row


def points(run: Path) -> list[tuple[str, dict[str, Any]]]:
    snaps = sorted((p for p in (run / SNAPSHOTS).glob("k*-step*") if (p / "manifest.json").exists()),
                   key=lambda p: int(p.name.rsplit("-step", 1)[1]))
    out = [(p.name, measure(p)) for p in snaps]
    if (run / "manifest.json").exists():
        latest = read_manifest(run)["digest"]
        if all(r["digest"] != latest for _, r in out):
            out.append(("latest", measure(run)))
    return out


def table(run: Path, rows: list[tuple[str, dict[str, Any]]]) -> str:
    pct = lambda v: "-" if v is None else f"{100 * v:.0f}%"  # noqa: E731
    num = lambda v: "-" if v is None else f"{v:.4g}"  # noqa: E731
    hours = lambda v: "?" if v is None else f"{v:.2f}"  # noqa: E731
    millions = lambda v: "?" if v is None else f"{v / 1e6:.1f}M"  # noqa: E731
    lines = [f"{run}:", "| snapshot | steps (with ancestors) | samples with ancestors | CPU h (with ancestors) | "
             "val loss | unguided no warp | guided no warp | guided valid (no warp, no wall) | "
             "guided: warp at the first step | guided first step | guided boundary step | "
             "x0 error (t=19) | boundary max (t=19) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, r in rows:
        lines.append(f"| {name} | {r['steps']} ({r['total_steps']}) | {millions(r.get('total_samples'))} | "
                     f"{r['cpu_h']:.2f} ({hours(r['total_cpu_h'])}) | {num(r['val_loss'])} | "
                     f"{pct(r['unguided_no_warp'])} | "
                     f"{pct(r.get('guided_no_warp'))} | {pct(r.get('guided_valid'))} | "
                     f"{pct(r.get('guided_first_warp'))} | {num(r.get('guided_first_step'))} | "
                     f"{num(r.get('guided_boundary_step'))} | {num(r.get('x0_rms'))} | "
                     f"{num(r.get('boundary_max'))} |")
    return "\n".join(lines)


def plot(runs: dict[str, list[tuple[str, dict[str, Any]]]], out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 3.8))
    # CPU hours with the train.init_from ancestors where every point knows them, else the run's own
    total = all(r.get("total_cpu_h") is not None for rows in runs.values() for _, r in rows)
    for name, rows in runs.items():
        h = [r["total_cpu_h"] if total else r["cpu_h"] for _, r in rows]
        ax.plot(h, [100 * r["unguided_no_warp"] for _, r in rows], "o-", label=f"{name}: unguided")
        if rows and rows[0][1].get("guided_no_warp") is not None:
            ax.plot(h, [100 * r["guided_no_warp"] for _, r in rows], "s--", label=f"{name}: guided")
        if rows and rows[0][1].get("guided_valid") is not None:
            ax.plot(h, [100 * r["guided_valid"] for _, r in rows], "^:", label=f"{name}: guided, no wall either")
    ax.set_xlabel("training CPU hours (one core)" + (", with the weights' ancestors" if total else ", this run"))
    ax.set_ylabel("warp-free plans (%)")
    ax.set_ylim(-2, 102)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", type=Path, help="training run dirs (train.out)")
    ap.add_argument("--plot", type=Path, default=None, help="figure of warp-free share against CPU hours")
    args = ap.parse_args(argv)
    curves = {}
    for run in args.runs:
        curves[run.name] = points(run)
        print(table(run, curves[run.name]) + "\n")
    if args.plot:
        plot(curves, args.plot)
        print(f"figure: {args.plot}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
