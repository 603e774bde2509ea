"""Train maze models on one CUDA GPU at the paper's batch, all concurrently, to one deadline.

    python3 jobs/gpu/gpu_train.py OUT_DIR                           # the H200 device: --set campaign, ~8.5 min
    python3 jobs/gpu/gpu_train.py OUT_DIR --set scratch             # the 3 sparse models from scratch (paper recipe)
    python3 jobs/gpu/gpu_train.py OUT_DIR --set ant                 # the six AntMaze models from the dense ant ones
    python3 jobs/gpu/gpu_train.py OUT_DIR --set visual              # the four [z, x, y] visual planners (carried data)
    python3 jobs/gpu/gpu_train.py OUT_DIR --set ant,visual          # both sets at once (10 models in 5 tars)
    python3 jobs/gpu/gpu_train.py OUT_DIR --train-until-s 300 train.precision=bf16   # extra words go to every run
    python3 jobs/gpu/gpu_train.py OUT_DIR --dry-run                 # CPU: tiny data and model, seconds (tested)
    python3 jobs/gpu/gpu_train.py OUT_DIR --set ant --only antmaze-giant-h5 --runs runs/gpu2 --continue-from runs/gpu
                                                                # a second call on the warm machine (below)

Made for a session lent the ``device`` tool's H200 (15 minutes in all, the machine's start
included, nothing downloadable there), so it uses only the standard library until the project
is importable:

1. install: the project goes on PYTHONPATH; packages the image lacks (omegaconf and its antlr4
   runtime; for dataset generation mujoco, mujoco-core, gymnasium, glfw,
   farama-notifications, ogbench) are installed from ``.whl/`` if that folder was carried (see
   the device README), into /tmp/site.
2. datasets: one jobs/make_dataset.py per maze, all at once (present ones are only verified),
   each with ``data.workers`` processes (the cores shared among the mazes; the bytes do not
   depend on it); each maze's models start the moment its dataset is ready, so the GPU is busy early.
3. training: every model of the set is a jobs/train.py subprocess at batch 1024 (the paper's),
   device=cuda, into runs/gpu/<name> (resumable like every run). Each gets the wall time left to
   the common deadline (--train-until-s after this script started, less a start-up margin) as
   train.time_budget_s with the LR decayed to 0 by a cosine over it, and one snapshot at half
   of it. Sets: ``campaign`` continues the six shipped PointMaze models
   (checkpoints/pointmaze-{medium,large,giant}-h{5,1}, carried; the campaign's lineages) with each one's own
   recipe levers (the boundary loss, the clean context); ``scratch`` trains the three sparse ones
   from scratch with the paper's recipe; ``ant`` trains the six AntMaze models from the carried dense
   ones (checkpoints/antmaze-{medium,large,giant}-h1; carry checkpoints/ant-expert too: its actions make
   the ant data);
   ``visual`` trains the visual maze's [z, x, y] planners (``visual-latent``: the latent ones) on
   carried latent stores (no rendering there). Sets joined by commas train at once; the dataset
   workers then get the cores the carried-data models leave.
4. output: one OUT_DIR/<name>.tar per model (its model.pt + manifest.json, and the half-way
   snapshot's; < 16 MiB for the 6 x 128 model) and OUT_DIR/train_logs.txt with each run's last
   lines and each dataset's sha256: at most 7 tars, inside the device tool's 8 files; with more
   than 7 models (sets joined by commas) they share tars, OUT_DIR/models-<i>.tar, without snapshots.
   A run that outlives the deadline by --grace-s is killed and its last checkpoint is packed.
5. a second call, while the machine is still warm (it goes back 30 s after a call): runs/, data/
   and the wheels installed in /tmp/site are still there, but checkpoints/ (left behind by
   ``jobs/gpu/device_tree.py slim``) and every carried path the call does not name again are gone.
   So carry again what the datasets' check needs (the ant set: checkpoints/ant-expert) and
   continue each model from the first call's weights with ``--continue-from runs/gpu``
   (session 33 did this by hand: docs/results.md section 4, "Session 33").
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tarfile
import threading
import time
from pathlib import Path


REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))  # the project's own folder: importable before it is installed
from fmctd_dist.cli_words import merge  # noqa: E402  standard library only, like this script until install()
ENVS = ("pointmaze-medium", "pointmaze-large", "pointmaze-giant")
NEEDED = ("omegaconf", "tqdm", "numpy", "torch")  # what jobs/train.py imports beyond the standard library
FOR_DATA = ("mujoco", "gymnasium", "ogbench", "glfw")  # jobs/make_dataset.py's too (gymnasium's MuJoCo imports glfw)
PAPER_BATCH = 1024
TAR_LIMIT = 16 * 2**20  # the device tool's per-file limit
START_MARGIN_S = 45.0  # a run's start (imports, CUDA, data) and its last checkpoint, outside its budget


BW, CC = "train.boundary_weight=3", "train.clean_context=0.5"  # the recipe levers the sets name
WALL = "train.wall_weight=0.1"  # the wall loss: sparse ant-large's guided valid plans 48 -> 68%, Fast-MCTD 26 -> 44%


def _campaign(maze: str, jump: int, *levers: str) -> tuple[str, list[str]]:
    name = f"pointmaze-{maze}-h{jump}"
    return name, [f"env=pointmaze-{maze}", f"jump={jump}", f"train.init_from=checkpoints/{name}", *levers]


def _ant(maze: str, jump: int) -> tuple[str, list[str]]:
    """An AntMaze model started from the carried dense ant model of its maze (checkpoints/antmaze-<maze>-h1),
    boundary loss on: the dense one continues it with its own levers (the clean context too), the sparse one
    takes its weights, as the best sparse ant models of docs/results.md 11.11 did (guided warp-free 80% / 72%
    on medium / large, against 48% / 65% from the PointMaze models), with the wall loss the shipped sparse large
    model was continued with on a CPU (antmaze.md 11.15); same architecture, only the jump differs."""
    levers = [BW, CC] if jump == 1 else [BW, WALL]
    return f"antmaze-{maze}-h{jump}", [f"env=antmaze-{maze}", f"jump={jump}",
                                       f"train.init_from=checkpoints/antmaze-{maze}-h1", *levers]


# the best sparse latent model of each maze, from its boundary-loss lineage (docs/results.md section 13.4):
# median boundary step from validation starts 4.90 -> 1.30 (medium), 6.31 -> 1.73 (large). Medium's is the
# shipped default (the former snapshot visual-pointmaze-medium-h5-s27, the same bytes); large's is not a default
# (checkpoints/README.md names it as kept for this set)
VISUAL_START = {"medium": "checkpoints/visual-pointmaze-medium-h5",
                "large": "checkpoints/visual-pointmaze-large-h5-s29"}


def _visual(maze: str, jump: int) -> tuple[str, list[str]]:
    """A visual-maze latent model continued (h5) or started (h1) from the maze's best sparse one, on the carried
    100-episode latent store (data/visual-pointmaze-<maze>-latents-...-n100-...; section 13.4), boundary loss on."""
    return f"visual-pointmaze-{maze}-h{jump}", [f"env=visual-pointmaze-{maze}", f"jump={jump}", "visual.episodes=100",
                                                f"train.init_from={VISUAL_START[maze]}", BW]


# the [z, x, y] planners (visual.plan_xy; results 13.4, sessions 31-33) continue the shipped ones (the dense
# large one was started from the sparse large one on session 33's lease: same width, only the jump differs)
XY_START = {("medium", 5): "checkpoints/visual-pointmaze-medium-h5-xy",
            ("medium", 1): "checkpoints/visual-pointmaze-medium-h1-xy",
            ("large", 5): "checkpoints/visual-pointmaze-large-h5-xy",
            ("large", 1): "checkpoints/visual-pointmaze-large-h1-xy"}
XY_RECIPE = ["visual.plan_xy=true", BW, "train.boundary_space=position", "train.position_weight=3"]


def _visual_xy(maze: str, jump: int) -> tuple[str, list[str]]:
    """A [z, x, y] visual planner on the carried 100-episode latent store, with the recipe its lineage used."""
    return f"visual-pointmaze-{maze}-h{jump}-xy", [f"env=visual-pointmaze-{maze}", f"jump={jump}",
                                                   "visual.episodes=100", f"train.init_from={XY_START[maze, jump]}",
                                                   *XY_RECIPE]


SETS: dict[str, list[tuple[str, list[str]]]] = {
    # each shipped PointMaze model (the campaign's) with the levers its manifest records (docs/results.md section 4)
    "campaign": [_campaign("medium", 5), _campaign("large", 5, BW), _campaign("giant", 5, BW),
                 _campaign("medium", 1, BW), _campaign("large", 1, BW, CC), _campaign("giant", 1, BW, CC)],
    "scratch": [(f"{e}-h5", [f"env={e}", "jump=5"]) for e in ENVS],
    # the six AntMaze models; their datasets (~15 min per maze on one core) are made there by
    # data.workers processes per maze; carry checkpoints/ant-expert with the three dense ant models
    "ant": [_ant(m, j) for j in (5, 1) for m in ("medium", "large", "giant")],
    # the four visual latent models; nothing is rendered there: carry each maze's VAE
    # (checkpoints/visual-pointmaze-<maze>-vae), its latent store and its VISUAL_START model
    "visual-latent": [_visual(m, j) for j in (5, 1) for m in ("medium", "large")],
    # the four [z, x, y] visual planners: carry each maze's VAE, estimator, latent store and XY_START models
    "visual": [_visual_xy(m, j) for j in (5, 1) for m in ("medium", "large")],
}
CARRIED_DATA = ("visual-",)  # env families whose data is carried (made on a CPU machine), never generated here
DRY = ["data.episodes=8", "data.episode_steps=301", "env.horizon=100", "data.train_window=100", "env.max_steps=100",
       "model.width=32", "model.layers=2", "model.heads=2", "model.ff=64", "train.batch_size=16",
       "train.val_batches=1", "train.warmup=10", "device=cpu", "train.threads=1"]


def log(msg: str) -> None:
    print(f"[gpu_train {time.strftime('%H:%M:%S')}] {msg}", flush=True)


SITE = Path("/tmp/site")  # where carried wheels go; a second call on the warm machine finds them still there
MARK = "gpu_train-installed"


def install(env: dict[str, str]) -> dict[str, str]:
    """PYTHONPATH with the project (and carried wheels); stop with a clear line if a package is still missing."""
    paths = [str(REPO)]
    wheels = sorted((REPO / ".whl").glob("*.whl")) if (REPO / ".whl").is_dir() else []
    if wheels and _missing(NEEDED + FOR_DATA, {**env, "PYTHONPATH": str(REPO)}):  # else the machine has them
        subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-index", "--no-deps", "--no-compile",
                        "--no-build-isolation", "--upgrade", "--target", str(SITE), *map(str, wheels)], check=True)
        (SITE / MARK).write_text("installed by jobs/gpu/gpu_train.py\n")
    if (SITE / MARK).exists():  # ours, from this call or an earlier one on the same machine
        paths.append(str(SITE))
    env = {**env, "PYTHONPATH": os.pathsep.join(paths + [p for p in [env.get("PYTHONPATH")] if p])}
    missing = _missing(NEEDED, env)
    if missing:
        raise SystemExit(f"error: packages missing: {' '.join(missing)}; carry their wheels in .whl/ (see "
                         "/work/.library/device/README.md) or pip install them")
    return env


def _missing(modules: tuple[str, ...], env: dict[str, str]) -> list[str]:
    probe = "import importlib.util as u, sys; print(' '.join(m for m in sys.argv[1:] if u.find_spec(m) is None))"
    return subprocess.run([sys.executable, "-c", probe, *modules], env=env, capture_output=True,
                          text=True).stdout.split()


def start(name: str, cmd: list[str], env: dict[str, str], logs: Path) -> subprocess.Popen:
    """The command in the background, its output in logs/<name>.log (the child keeps the file open)."""
    log(f"started {name}: {' '.join(cmd[1:])}")
    with open(logs / f"{name}.log", "w") as f:
        return subprocess.Popen(cmd, cwd=REPO, env=env, stdout=f, stderr=subprocess.STDOUT)


def tail(logs: Path, name: str, n: int = 10) -> str:
    path = logs / f"{name}.log"
    lines = path.read_text().replace("\r", "\n").strip().splitlines() if path.exists() else ["(no log)"]
    return "\n".join(lines[-n:])


class Deadline:
    """Seconds left to the common training deadline, counted from this script's start."""

    def __init__(self, t0: float, until_s: float):
        self.t0, self.until_s = t0, until_s

    def budget(self) -> float:
        return max(30.0, self.until_s - (time.time() - self.t0) - START_MARGIN_S)


def data_step(env_name: str, words: list[str], env: dict[str, str], args: argparse.Namespace, logs: Path) -> str:
    """'ok' once the maze's dataset exists (made here, or carried for CARRIED_DATA), else what failed."""
    if env_name.startswith(CARRIED_DATA):
        return "ok"  # each training run checks its carried store against its VAE, with one clear error
    cmd = [sys.executable, "jobs/make_dataset.py", f"env={env_name}", *words, f"data.workers={args.data_workers}"]
    if start(f"data-{env_name}", cmd, env, logs).wait():
        return "failed:\n" + tail(logs, f"data-{env_name}")
    return "ok"


def maze_chain(env_name: str, models: list[tuple[str, list[str]]], words: list[str], env: dict[str, str],
               args: argparse.Namespace, deadline: Deadline, status: dict[str, str]) -> None:
    """Make (or verify) one maze's dataset, then train its models concurrently to the deadline."""
    logs = args.runs / "logs"
    status[f"data-{env_name}"] = data_step(env_name, words, env, args, logs)
    if status[f"data-{env_name}"] != "ok":
        log(f"data-{env_name} {status[f'data-{env_name}']}")
        return
    budget = 2.0 if args.dry_run else deadline.budget()
    log(f"data-{env_name} ready after {time.time() - deadline.t0:.0f}s; its models get {budget:.0f}s each")
    timing = [f"train.time_budget_s={budget:.0f}", f"train.snapshot_every_s={budget / 2:.0f}"]
    procs = {name: start(name, [sys.executable, "jobs/train.py", *merge(model_words, words, timing,
                                                                         [f"train.out={args.runs / name}"])], env, logs)
             for name, model_words in models}
    hard_end = deadline.t0 + args.train_until_s + args.grace_s
    for name, p in procs.items():
        try:
            rc = p.wait(timeout=max(1.0, hard_end - time.time()))
            status[name] = f"exit {rc}"
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
            status[name] = "killed at the deadline (its last checkpoint is packed)"
        log(f"{name}: {status[name]}")


MAX_TARS = 7  # the device returns 8 files: the tars and train_logs.txt
TOTAL_LIMIT = 60 * 2**20  # of the 64 MiB it returns in all


def pack_all(names: list[str], runs: Path, out: Path) -> list[str]:
    """The runs' weights in at most MAX_TARS tars: OUT/<name>.tar each, with its first half-way snapshot, while
    that fits the device's limits; more models share tars (OUT/models-<i>.tar) and leave their snapshots behind.
    Every tar holds <name>/model.pt + manifest.json per model, so unpacking is the same either way."""
    members = {n: [runs / n / "model.pt", runs / n / "manifest.json"] for n in names}
    lines = {n: "no model.pt" for n in names if not (runs / n / "model.pt").exists()}
    ready = [n for n in names if n not in lines]
    if len(ready) <= MAX_TARS:
        with_snap = {n: members[n] + _first_snapshot(runs / n) for n in ready}
        if all(_size(v) < TAR_LIMIT - 2**20 for v in with_snap.values()) and sum(
                map(_size, with_snap.values())) < TOTAL_LIMIT:
            members.update(with_snap)
        groups = [(f"{n}.tar", [n]) for n in ready]
    else:
        k = -(-len(ready) // MAX_TARS)  # models per tar
        groups = [(f"models-{i}.tar", ready[j:j + k]) for i, j in enumerate(range(0, len(ready), k))]
    for tar_name, group in groups:
        with tarfile.open(out / tar_name, "w") as tar:
            for n in group:
                for p in members[n]:
                    tar.add(p, arcname=f"{n}/{p.relative_to(runs / n).as_posix()}")
        for n in group:
            m = json.loads((runs / n / "manifest.json").read_text())
            lines[n] = (f"{n}: {m.get('train_steps')} steps, digest {m.get('digest')}, final losses "
                        f"{m.get('final_losses')}, {len(members[n]) // 2} checkpoint(s) in {tar_name}")
    return [lines[n] for n in names]


def _first_snapshot(run: Path) -> list[Path]:
    snaps = sorted((run / "snapshots").glob("k*")) if (run / "snapshots").is_dir() else []
    return [snaps[0] / "model.pt", snaps[0] / "manifest.json"] if snaps else []


def _size(paths: list[Path]) -> int:
    return sum(p.stat().st_size for p in paths)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="folder for <name>.tar per model and train_logs.txt")
    ap.add_argument("--set", default="campaign",
                    help=f"which models, one set or several joined by commas: {', '.join(SETS)} (default campaign)")
    ap.add_argument("--only", default="", help="comma-separated model names of the set (default all)")
    ap.add_argument("--train-until-s", type=float, default=470.0,
                    help="every run stops training this many seconds after the script started")
    ap.add_argument("--grace-s", type=float, default=40.0, help="a run still going this long after it is killed")
    ap.add_argument("--data-workers", type=int, default=0,
                    help="processes per maze's dataset (default: the cores shared among the mazes)")
    ap.add_argument("--runs", type=Path, default=REPO / "runs" / "gpu", help="training dirs (resumable)")
    ap.add_argument("--continue-from", type=Path, default=None,
                    help="each model starts from <dir>/<name> (an earlier call's --runs), not from its set's start")
    ap.add_argument("--dry-run", action="store_true", help="CPU, tiny data (in --runs) and model, 2 s each")
    ap.add_argument("overrides", nargs="*", help="extra key=value words for every training run")
    args = ap.parse_intermixed_args(argv)  # words may follow the options
    t0 = time.time()
    unknown = [name for name in args.set.split(",") if name not in SETS]
    if unknown:
        raise SystemExit(f"error: --set {args.set!r}: no set {', '.join(unknown)}; the sets are {', '.join(SETS)}")
    in_sets = [model for name in args.set.split(",") for model in SETS[name]]
    models = [(n, w) for n, w in in_sets if not args.only or n in args.only.split(",")]
    if not models:
        raise SystemExit(f"error: --only {args.only!r} names no model of set {args.set!r} "
                         f"({', '.join(n for n, _ in in_sets)})")
    if args.continue_from:
        missing = [n for n, _ in models if not (args.continue_from / n / "model.pt").exists()]
        if missing:
            raise SystemExit(f"error: --continue-from {args.continue_from}: no model.pt for {', '.join(missing)}; "
                             "name the --runs folder of the call that trained them")
    env = install({**os.environ, "PYTHONUNBUFFERED": "1"})
    words = [f"train.batch_size={PAPER_BATCH}", "device=cuda", "train.lr_schedule=cosine", "train.budget_clock=wall",
             "train.max_steps=1000000", "train.ckpt_every=1000", "train.threads=1"]
    if args.dry_run:
        words = merge(words, DRY, [f"data.root={args.runs / 'data'}"])
        models = [(n, [w for w in mw if not w.startswith("train.init_from")]) for n, mw in models]  # tiny shapes
    else:
        smi = shutil.which("nvidia-smi")
        gpus = subprocess.run([smi, "-L"], capture_output=True, text=True) if smi else None
        log(f"GPU: {(gpus.stdout.strip() or gpus.stderr.strip()) if gpus else 'no nvidia-smi'}")
    if args.continue_from:
        models = [(n, merge(mw, [f"train.init_from={args.continue_from / n}"])) for n, mw in models]
    words = merge(words, args.overrides)
    (args.runs / "logs").mkdir(parents=True, exist_ok=True)

    by_maze: dict[str, list[tuple[str, list[str]]]] = {}
    for name, model_words in models:
        maze = next(w.split("=", 1)[1] for w in model_words if w.startswith("env="))
        by_maze.setdefault(maze, []).append((name, model_words))
    # the cores go to the datasets made here, less one per model that trains at once on carried data
    made = [m for m in by_maze if not m.startswith(CARRIED_DATA)]
    carried_models = sum(len(ms) for m, ms in by_maze.items() if m.startswith(CARRIED_DATA))
    args.data_workers = args.data_workers or max(1, ((os.cpu_count() or 1) - carried_models) // max(1, len(made)))
    deadline, status = Deadline(t0, args.train_until_s), {}
    chains = [threading.Thread(target=maze_chain, args=(maze, ms, words, env, args, deadline, status))
              for maze, ms in by_maze.items()]
    for c in chains:
        c.start()
    for c in chains:
        c.join()
    log(f"training done after {time.time() - t0:.0f}s")

    args.out.mkdir(parents=True, exist_ok=True)
    report = [f"set {args.set}; words {' '.join(words)}"]
    root = args.runs / "data" if args.dry_run else REPO / "data"
    for maze in by_maze:
        sha = [json.loads(p.read_text()).get("sha256") for p in sorted(root.glob(f"{maze}-*/manifest.json"))]
        report.append(f"data-{maze}: {status.get('data-' + maze)}; sha256 {sha}")
    for (name, _), line in zip(models, pack_all([n for n, _ in models], args.runs, args.out)):
        report.append(line + f" [{status.get(name, 'not started')}]")
        report.append(tail(args.runs / "logs", name, 3))
    (args.out / "train_logs.txt").write_text("\n".join(report) + "\n")
    print("\n".join(report), flush=True)
    log(f"wrote {args.out} after {time.time() - t0:.0f}s")
    return 0 if all(s.startswith(("ok", "exit 0")) for s in status.values()) and len(status) == len(models) + len(
        by_maze) else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
