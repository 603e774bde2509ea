"""Train the sparse PointMaze models on one CUDA GPU at the paper's batch, in a fixed wall-clock.

    python3 jobs/gpu_train.py OUT_DIR                         # on a machine with a GPU (the H200 device)
    python3 jobs/gpu_train.py OUT_DIR --budget-s 240 train.precision=bf16   # extra words go to every run
    python3 jobs/gpu_train.py OUT_DIR --dry-run               # CPU: tiny data and model, seconds (tested)

Made for a session lent the ``device`` tool's H200 (15 minutes in all, the machine's start
included, nothing downloadable there), so it uses only the standard library until the project
is importable:

1. install: the project goes on PYTHONPATH (``pip install --no-deps -e .`` needs network-free
   setuptools, which is not worth the risk); packages the image lacks (omegaconf and its
   antlr4 runtime; for dataset generation also mujoco, gymnasium, ogbench) are installed from
   ``.whl/`` if that folder was carried (see the device README), into /tmp/site.
2. datasets: present ones (data.root) are verified by jobs/train.py; missing ones are made by
   jobs/make_dataset.py, all at once in parallel (about 2 min each on one core here).
3. training: pointmaze-{medium,large,giant}-h5 run concurrently on the one GPU, each a
   jobs/train.py subprocess at batch 1024 (the paper's) with train.time_budget_s=--budget-s
   (no boundary loss: at H=5 it traded Fast-MCTD success for warp-free plans, results 4; add
   train.boundary_weight=3 as an extra word to get it),
   device=cuda, into runs/gpu/<env>-h5 (resumable like every run).
4. output: model.pt + manifest.json of each model copied to OUT_DIR/<env>-h5/ (6 files of
   about 5 MB for the 6 x 128 model), plus OUT_DIR/train_logs.txt (7 files in all).

Budget: the defaults (datasets present, 420 s of training) end within ~8 minutes; with three
datasets to make first, give --budget-s 300.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
ENVS = ("pointmaze-medium", "pointmaze-large", "pointmaze-giant")
NEEDED = ("omegaconf", "tqdm", "numpy", "torch")  # what jobs/train.py imports beyond the standard library
PAPER_BATCH = 1024
DRY = ["data.episodes=8", "data.episode_steps=301", "env.horizon=100", "data.train_window=100", "env.max_steps=100",
       "model.width=32", "model.layers=2", "model.heads=2", "model.ff=64", "train.batch_size=16",
       "train.val_batches=1", "train.warmup=10", "device=cpu", "train.threads=1"]


def log(msg: str) -> None:
    print(f"[gpu_train {time.strftime('%H:%M:%S')}] {msg}", flush=True)


def install(env: dict[str, str]) -> dict[str, str]:
    """PYTHONPATH with the project (and carried wheels); stop with a clear line if a package is still missing."""
    paths = [str(REPO)]
    wheels = sorted((REPO / ".whl").glob("*")) if (REPO / ".whl").is_dir() else []
    if wheels:
        site = Path("/tmp/site")
        subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-index", "--no-deps", "--no-compile",
                        "--no-build-isolation", "--upgrade", "--target", str(site), *map(str, wheels)], check=True)
        paths.append(str(site))
    env = {**env, "PYTHONPATH": os.pathsep.join(paths + [p for p in [env.get("PYTHONPATH")] if p])}
    probe = "import importlib.util as u, sys; print(' '.join(m for m in sys.argv[1:] if u.find_spec(m) is None))"
    missing = subprocess.run([sys.executable, "-c", probe, *NEEDED], env=env, capture_output=True,
                             text=True).stdout.split()
    if missing:
        raise SystemExit(f"error: packages missing: {' '.join(missing)}; carry their wheels in .whl/ (see "
                         "/work/.library/device/README.md) or pip install them")
    return env


def run_all(cmds: dict[str, list[str]], env: dict[str, str], logs: Path) -> None:
    """Run the commands concurrently (one log each); stop with the failed one's log tail."""
    procs = {}
    for name, cmd in cmds.items():
        f = open(logs / f"{name}.log", "w")
        procs[name] = (subprocess.Popen(cmd, cwd=REPO, env=env, stdout=f, stderr=subprocess.STDOUT), f)
        log(f"started {name}: {' '.join(cmd[1:])}")
    failed = []
    for name, (p, f) in procs.items():
        rc = p.wait()
        f.close()
        log(f"{name} finished (exit {rc})")
        if rc:
            failed.append(name)
    if failed:
        tail = (logs / f"{failed[0]}.log").read_text().replace("\r", "\n").strip().splitlines()[-10:]
        raise SystemExit(f"error: {', '.join(failed)} failed; the end of {failed[0]}'s log:\n" + "\n".join(tail))


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="folder for <env>-h5/model.pt + manifest.json")
    ap.add_argument("--budget-s", type=float, default=420.0, help="training wall-clock per model (concurrent)")
    ap.add_argument("--envs", default=",".join(ENVS), help="comma-separated, default all three PointMaze mazes")
    ap.add_argument("--runs", type=Path, default=REPO / "runs" / "gpu", help="training dirs (resumable)")
    ap.add_argument("--dry-run", action="store_true", help="CPU, tiny data (in --runs) and model, 2 s each")
    ap.add_argument("overrides", nargs="*", help="extra key=value words for every training run")
    args = ap.parse_args(argv)
    t0 = time.time()
    envs = [e for e in args.envs.split(",") if e]
    env = install({**os.environ, "PYTHONUNBUFFERED": "1"})
    words = ["jump=5", f"train.batch_size={PAPER_BATCH}", "device=cuda", f"train.time_budget_s={args.budget_s}",
             "train.max_steps=1000000", "train.ckpt_every=1000"]
    if args.dry_run:
        words = [w for w in words if not w.startswith(("train.batch_size", "device", "train.time_budget_s"))]
        words += DRY + [f"data.root={args.runs / 'data'}", "train.time_budget_s=2"]
    words += args.overrides
    if not args.dry_run:
        smi = subprocess.run(["nvidia-smi", "-L"], capture_output=True, text=True)
        log(f"GPU: {smi.stdout.strip() or smi.stderr.strip()}")
    logs = args.runs / "logs"
    logs.mkdir(parents=True, exist_ok=True)

    data = {e: [sys.executable, "jobs/make_dataset.py", f"env={e}", *words] for e in envs}
    run_all({f"data-{e}": cmd for e, cmd in data.items()}, env, logs)  # verifies present datasets in seconds
    log(f"datasets ready after {time.time() - t0:.0f}s")

    train = {e: [sys.executable, "jobs/train.py", f"env={e}", *words, f"train.out={args.runs / (e + '-h5')}"]
             for e in envs}
    run_all({f"train-{e}": cmd for e, cmd in train.items()}, env, logs)
    log(f"training done after {time.time() - t0:.0f}s")

    args.out.mkdir(parents=True, exist_ok=True)
    for e in envs:
        dst = args.out / f"{e}-h5"
        dst.mkdir(exist_ok=True)
        for name in ("model.pt", "manifest.json"):
            shutil.copy2(args.runs / f"{e}-h5" / name, dst / name)
    with open(args.out / "train_logs.txt", "w") as f:
        for e in envs:
            text = (logs / f"train-{e}.log").read_text().replace("\r", "\n").strip().splitlines()
            f.write(f"== {e}\n" + "\n".join(text[-3:]) + "\n")
    log(f"wrote {args.out} after {time.time() - t0:.0f}s")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
