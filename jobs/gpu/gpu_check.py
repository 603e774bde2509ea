"""The speed check for a session lent a CUDA GPU (issue 22): throughput per option, then plans.

    python3 jobs/gpu/gpu_check.py OUT_DIR              # on the H200 device machine (< 8 minutes)
    python3 jobs/gpu/gpu_check.py OUT_DIR --dry-run    # CPU, tiny sizes, about a minute (tested)

1. install: as jobs/gpu/gpu_train.py (the project on PYTHONPATH, carried wheels from ``.whl/``).
2. ``OUT_DIR/throughput.md``: ``jobs/bench_denoiser.py --throughput`` on device=cuda, batches
   1 / 25 / 200 / 1000, tokens 11 / 21 / 51 / 101, options fp32 and bf16, with utilisation against
   the GPU's measured matmul peak; ``OUT_DIR/compiled.md``: the compiled options beside fp32 at 21
   tokens, batches 1 / 200 / 1000 (each cell compiles once, so fewer cells). Rows are printed as
   they are measured: a step stopped by its limit keeps the rows it finished.
3. ``OUT_DIR/plans.md``: ``jobs/bench_speed.py`` MCTD and Fast-MCTD on PointMaze-giant task 1
   seed 0 side by side (shipped checkpoints, device=cuda, one plan each, capped at 120 s).

Every step has its own time limit, so the script ends inside the device tool's 10-minute call
whatever happens, and writes what it measured so far.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

from gpu_train import REPO, install, log  # same folder: stdlib only until the project is importable

FULL = {"throughput": ["--throughput", "device=cuda", "batches=1,25,200,1000", "tokens=11,21,51,101",
                       "options=fp32,bf16", "rounds=3"],
        # compiled options cost one compilation per cell (tens of seconds of triton each): giant's sparse
        # token count only, the batches a tree search uses on a GPU
        "compiled": ["--throughput", "device=cuda", "batches=1,200,1000", "tokens=21",
                     "options=fp32,compiled,bf16+compiled", "rounds=3"],
        "plans": ["methods=[mctd,fast-mctd]", "env=pointmaze-giant", "device=cuda", "tasks=[1]", "seeds=[0]",
                  "eval.episode_time_limit=120", "ray.micro_batch=200"]}
# the dry run's models have 1 layer: the same code end to end, a fraction of the compile time (the real run: 6)
DRY = {"throughput": ["--throughput", "device=cpu", "batches=2,4", "tokens=3", "options=fp32,bf16", "rounds=1",
                      "layers=1"],
       "compiled": ["--throughput", "device=cpu", "batches=2", "tokens=3", "options=fp32,compiled", "rounds=1",
                    "layers=1"],
       "plans": ["methods=[mctd,fast-mctd]", "env=pointmaze-medium", "device=cpu", "tasks=[1]", "seeds=[0]",
                 "method.budget=4", "eval.threads=1", "eval.episode_time_limit=60"]}
LIMITS_S = {"throughput": 150, "compiled": 150, "plans": 150}


def step(name: str, cmd: list[str], env: dict[str, str], out: Path) -> bool:
    """Run one measurement into OUT/<name>.md (its output, whatever it printed before a time-out)."""
    t0 = time.time()
    try:
        p = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=LIMITS_S[name])
        text, ok = p.stdout + (f"\n(exit {p.returncode})\n{p.stderr[-2000:]}"
                               if p.returncode else ""), p.returncode == 0
    except subprocess.TimeoutExpired as e:
        text, ok = (e.stdout or b"").decode() if isinstance(e.stdout, bytes) else (e.stdout or ""), False
        text += f"\n(stopped after its {LIMITS_S[name]} s limit)\n"
    (out / f"{name}.md").write_text(f"`{' '.join(cmd[1:])}`\n\n{text}")
    log(f"{name}: {'ok' if ok else 'FAILED'} in {time.time() - t0:.0f}s -> {out / (name + '.md')}")
    return ok


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="folder for throughput.md, compiled.md and plans.md")
    ap.add_argument("--dry-run", action="store_true", help="CPU and tiny sizes: checks the script end to end")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    env = install({**os.environ, "PYTHONUNBUFFERED": "1"})
    if args.dry_run:  # one torch thread: on a loaded CPU spinning OpenMP threads made a tiny bf16 cell run minutes
        env["OMP_NUM_THREADS"] = "1"
    else:
        smi = subprocess.run(["nvidia-smi", "-L"], capture_output=True, text=True)
        log(f"GPU: {smi.stdout.strip() or smi.stderr.strip()}")
    words = DRY if args.dry_run else FULL
    ok = step("throughput", [sys.executable, "jobs/bench_denoiser.py", *words["throughput"]], env, args.out)
    ok &= step("compiled", [sys.executable, "jobs/bench_denoiser.py", *words["compiled"]], env, args.out)
    ok &= step("plans", [sys.executable, "jobs/bench_speed.py", *words["plans"]], env, args.out)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
