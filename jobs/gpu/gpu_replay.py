"""Replay the committed call traces on a CUDA GPU: the H200 projection of docs/results.md, measured (issue 55).

    python3 jobs/gpu/gpu_replay.py OUT_DIR              # the device machine, < 5 minutes
    python3 jobs/gpu/gpu_replay.py OUT_DIR --dry-run    # CPU, the first call of two traces, seconds (tested)

Why: the paper's MCTD / Fast-MCTD ratios (16-110x) need a GPU, and our CPUs cannot show them;
``python jobs/bench/replay.py mode=project`` projects them from one full-budget plan's call trace per
method and maze (jobs/bench/traces/) and a throughput table. This script turns that projection into a
measurement in the first minutes of any GPU time. Standard library until the project is importable:

1. install: as jobs/gpu/gpu_train.py (the project on PYTHONPATH; omegaconf and its antlr4 runtime from a
   carried ``.whl/`` when the machine lacks them).
2. ``jobs/bench/replay.py mode=replay device=cuda weights=real envs=[giant,large,medium]`` on the traces and
   the shipped checkpoints (checkpoints/pointmaze-<maze>-h1 and -h5, carried), one process per step: MCTD and
   Fast-MCTD with each call as one batch (``batch=call``: the paper's setting), then S-MCTD and P-MCTD the same
   way, then Fast-MCTD and P-MCTD at their recorded micro-batch of 8 (``batch=trace``).
3. OUT_DIR/replay.md: per maze and method, projected (H200 table) beside measured (this GPU) model
   seconds and plan seconds (+ the search's recorded CPU seconds, the same on both sides), and per maze
   the MCTD / Fast-MCTD ratio projected, measured and the paper's; printed at the end too.
   OUT_DIR/detail.tar: each step's replay tables (<maze>/replay-cuda[-call].{md,json}) and log (the device
   tool returns at most 8 files).

The steps share one deadline (--budget-s, default 285 s after the start; projected model time of all
steps ~220 s on an H200), so the script ends inside the device call whatever happens; a step stopped by
it keeps the methods it finished.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tarfile
import time
from pathlib import Path

from gpu_train import REPO, install, log  # same folder: stdlib only until the project is importable

TRACES = "jobs/bench/traces"
MAZES = ("pointmaze-giant", "pointmaze-large", "pointmaze-medium")  # the paper's headline (110x) first
# (methods, batch), one replay.py process each over every maze: the important lines first, so a deadline
# cuts the least useful ones (and a process stopped by it keeps the methods it finished)
STEPS = (("methods=[fast-mctd,mctd]", "call"), ("methods=[s-mctd,p-mctd]", "call"),
         ("methods=[fast-mctd,p-mctd]", "trace"))
DRY = {"mazes": ("pointmaze-medium",), "steps": (("methods=[fast-mctd,mctd]", "call"),
                                                 ("methods=[fast-mctd]", "trace"))}


def step(i: int, methods: str, batch: str, mazes: tuple[str, ...], words: list[str], env: dict[str, str],
         work: Path, limit_s: float) -> bool:
    """One ``jobs/bench/replay.py mode=replay`` process over ``mazes`` into work/<maze>/, its output in
    work/log-<i>.txt."""
    t0 = time.time()
    cmd = [sys.executable, "jobs/bench/replay.py", "mode=replay", "weights=real", f"out={TRACES}", f"report={work}",
           f"envs=[{','.join(mazes)}]", methods, f"batch={batch}", "rounds=1", "eval.threads=1", *words]
    try:
        p = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=limit_s)
        text, ok = p.stdout + (f"\n(exit {p.returncode})\n{p.stderr[-3000:]}" if p.returncode else ""), not p.returncode
    except subprocess.TimeoutExpired as e:
        text = e.stdout.decode() if isinstance(e.stdout, bytes) else (e.stdout or "")
        text, ok = text + f"\n(stopped after its {limit_s:.0f} s limit)\n", False
    (work / f"log-{i}.txt").write_text(f"`{' '.join(cmd[1:])}`\n\n{text}")
    log(f"{methods} batch={batch}: {'ok' if ok else 'FAILED'} in {time.time() - t0:.0f}s")
    return ok


def side_by_side(out: Path, mazes: tuple[str, ...], device: str, machine: str) -> str:
    """OUT/replay.md: the projection beside what the replays on ``device`` measured (the replay JSONs found)."""
    sys.path[:0] = [str(REPO), str(REPO / "jobs" / "bench")]
    from projection import H200_SOURCE, call_seconds
    from fmctd_dist.denoiser.trace import load_trace
    from fmctd_dist.families.maze.paper import POINTMAZE

    lines = [f"Measured on {machine}, beside the projection from the H200 table ({H200_SOURCE}). Plan = model "
             "seconds + the search's own CPU seconds recorded with the trace (the same on both sides).", "",
             "| maze | method | batch | calls replayed | projected model (s) | measured model (s) | "
             "measured / projected | projected plan (s) | measured plan (s) |", "|---" * 9 + "|"]
    plans: dict[tuple[str, str], tuple[float, float]] = {}
    for maze in mazes:
        for batch in ("call", "trace"):
            path = out / maze / f"replay-{device}{'-call' if batch == 'call' else ''}.json"
            for row in json.loads(path.read_text()) if path.exists() else []:
                calls = load_trace(REPO / TRACES / maze, row["method"])["calls"]
                calls = calls[: row["calls"]] if row["calls"] > 0 else calls  # the ones replayed
                model = sum(call_seconds(c, batch) for c in calls)
                search = row["search_cpu_s"]  # the whole plan's, also when only its first calls were replayed
                if batch == "call":
                    plans[maze, row["method"]] = (model + search, row["replay_s"] + search)
                lines.append(f"| {maze} | {row['method']} | {batch} | {len(calls)} | {model:.2f} | "
                             f"{row['replay_s']:.2f} | {row['replay_s'] / max(model, 1e-12):.2f} | "
                             f"{model + search:.2f} | {row['replay_s'] + search:.2f} |")
    lines += ["", "| maze | MCTD / Fast-MCTD: projected | measured | paper |", "|---|---|---|---|"]
    for maze in mazes:
        if (maze, "mctd") in plans and (maze, "fast-mctd") in plans:
            (pm, mm), (pf, mf) = plans[maze, "mctd"], plans[maze, "fast-mctd"]
            paper = POINTMAZE["mctd"][maze.split("-")[-1]][2] / POINTMAZE["fast-mctd"][maze.split("-")[-1]][2]
            lines.append(f"| {maze} | {pm / pf:.1f}x | {mm / mf:.1f}x | {paper:.1f}x |")
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="folder for replay.md and one folder of replay tables per maze")
    ap.add_argument("--dry-run", action="store_true", help="CPU, the first call of each trace: the script end to end")
    ap.add_argument("--budget-s", type=float, default=285.0, help="common deadline for all steps (default 285)")
    args = ap.parse_args(argv)
    t0 = time.time()
    args.out.mkdir(parents=True, exist_ok=True)
    env = install({**os.environ, "PYTHONUNBUFFERED": "1"})
    mazes, steps, device = MAZES, STEPS, "cuda"
    if args.dry_run:
        env["OMP_NUM_THREADS"] = "1"
        mazes, steps, device = DRY["mazes"], DRY["steps"], "cpu"
        machine = "cpu (dry run: the first call of each trace only)"
    else:
        smi = subprocess.run(["nvidia-smi", "-L"], capture_output=True, text=True)
        machine = smi.stdout.strip() or smi.stderr.strip()
        log(f"GPU: {machine}")
    words = [f"device={device}"] + (["calls=1"] if args.dry_run else [])
    work = args.out / "detail"  # packed into OUT/detail.tar at the end: the device returns at most 8 files
    work.mkdir(exist_ok=True)
    ok = True
    for i, (methods, batch) in enumerate(steps):
        left = args.budget_s - (time.time() - t0)
        if left < 10:
            log(f"{methods} batch={batch}: skipped, the deadline is reached")
            ok = False
            continue
        ok &= step(i, methods, batch, mazes, words, env, work, left)
    text = side_by_side(work, tuple(sorted(mazes, key=MAZES.index, reverse=True)), device, machine)
    (args.out / "replay.md").write_text(text + "\n")
    with tarfile.open(args.out / "detail.tar", "w") as tar:
        tar.add(work, arcname="detail")
    shutil.rmtree(work)
    print(text)
    log(f"done in {time.time() - t0:.0f}s -> {args.out / 'replay.md'}, {args.out / 'detail.tar'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
