"""Recipe bench (issue 17): train recipe arms from the same seed for the same wall-clock, then
compare what a planner gets from each, side by side. A recipe is chosen from this table,
never from validation loss alone.

    OMP_NUM_THREADS=1 python jobs/bench/bench_recipe.py --tag h5 --budget-s 600 \\
        --arm base: --arm v:model.param=v --arm cos:train.lr_schedule=cosine \\
        --arm "v_net@v:diffusion.guidance_path=network" \\
        env=pointmaze-medium jump=5 train.warmup=250

``--arm NAME:WORDS`` (WORDS: space-separated key=value overrides on top of the common ones;
empty = the common config, i.e. the paper's recipe) trains runs/recipe/<tag>/<NAME> with
``jobs/train.py`` in a subprocess (``train.time_budget_s=--budget-s``, ``train.threads=1``,
``--parallel`` arms at once, one core each). ``NAME@OTHER:WORDS`` trains nothing: it evaluates
arm OTHER's checkpoint with WORDS added (sampling settings such as diffusion.guidance_path).

Each arm is then evaluated in a subprocess (``--evaluate``, one thread): plan quality and x0
precision (jobs/bench/plan_quality.py, as jobs/bench_denoiser.py) and Fast-MCTD on a
small fixed grid (``jobs/eval.py runner=local eval.threads=1`` into results/recipe-<tag>-<NAME>).
Its numbers go to <arm dir>/bench.json, so a rerun resumes: finished training returns at once
and evaluated arms are read back. The table is printed and appended, with the command, to the
"Recipe bench" record of docs/notebook/training-campaign.md (the end of the file) (``--doc ''``: not at all).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shlex
import subprocess
import sys
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

from fmctd_dist.cli_words import merge
from tqdm import tqdm

REPO = Path(__file__).resolve().parents[2]
NAME = re.compile(r"^[A-Za-z0-9_.+-]+$")
PRECISION_T = 19  # the lowest-noise timestep of the precision probe (2% of 1000): the last DDIM level
RUN_FOREVER = "train.max_steps=1000000"  # arms stop on their wall-clock budget, not a step count
SECTION = "### Recipe bench (issue 17)"
INTRO = ("Arms trained from the same seed for the same time budget (`train.time_budget_s`, one core each; "
         "with `train.budget_clock=cpu` the budget counts the training process's CPU seconds, which stays fair "
         "when other jobs share the machine), "
         "then measured side by side: `python jobs/bench/bench_recipe.py` (the exact command above each table). "
         "samples/s = steps x batch / recorded training wall time; x0 error and steps at timestep 19 "
         "(the last DDIM level) on 64 validation windows; plan quality from 100 unguided and 100 guided "
         "full-pyramid plans (section 4's measurement); Fast-MCTD on the listed grid, runner=local, one thread; "
         "core share = CPU seconds / wall seconds of the training process (below 1: other jobs took part of its "
         "core, so it did less work in the same wall-clock).")


class Arm:
    """One bench arm: a name, its override words, and (eval-only arms) the arm whose checkpoint it reuses."""

    def __init__(self, spec: str):
        head, _, words = spec.partition(":")
        name, _, base = head.partition("@")
        if not NAME.match(name) or (base and not NAME.match(base)):
            raise SystemExit(f"error: --arm {spec!r}: the name must be letters, digits, _ . + - (NAME:WORDS or "
                             "NAME@OTHER:WORDS)")
        self.name, self.base, self.words = name, base or None, shlex.split(words)
        bad = [w for w in self.words if "=" not in w]
        if bad:
            raise SystemExit(f"error: --arm {spec!r}: {bad[0]!r} is not key=value")

    @property
    def label(self) -> str:
        own = " ".join(self.words) or "(paper recipe)"
        return f"{own} on {self.base}'s model" if self.base else own


def arm_words(args: argparse.Namespace, arm: Arm, arms: dict[str, Arm]) -> list[str]:
    """Every override word an arm's training and evaluation configs get (common, its base arm's, its own)."""
    base = arms[arm.base].words if arm.base else []
    return merge(args.overrides, base, arm.words)


def finished(ckpt: Path, budget_s: float) -> bool:
    """ckpt holds a run that spent this budget (a rerun of the bench skips its training subprocess)."""
    path = ckpt / "manifest.json"
    if not path.exists():
        return False
    m = json.loads(path.read_text())
    used = m.get("cpu_time_s", 0.0) if m["config"]["train"].get("budget_clock") == "cpu" else m["wall_time_s"]
    return m["config"]["train"]["time_budget_s"] == budget_s and used >= budget_s


def evaluated(out: Path, ckpt: Path) -> bool:
    """out/bench.json holds the numbers of ckpt's current weights."""
    done, manifest = out / "bench.json", ckpt / "manifest.json"
    return (done.exists() and manifest.exists()
            and json.loads(done.read_text()).get("digest") == json.loads(manifest.read_text())["digest"])


def run_logged(cmd: list[str], log: Path) -> tuple[float, float]:
    """Run cmd with its output in ``log`` (one thread: OMP_NUM_THREADS=1) -> (wall s, CPU s of that process).

    The CPU seconds say how much of a core the arm really had: arms share the machine with
    other jobs, so equal wall-clock is equal compute only when this ratio is alike.
    Raises with the log's tail on failure.
    """
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "PYTHONUNBUFFERED": "1"}
    t0 = time.time()
    with open(log, "a") as f:
        f.write(f"$ {shlex.join(cmd)}\n")
        f.flush()
        proc = subprocess.Popen(cmd, cwd=REPO, stdout=f, stderr=subprocess.STDOUT, env=env)
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode:
        tail = log.read_text().replace("\r", "\n").strip().splitlines()[-15:]
        raise RuntimeError(f"{cmd[1]} exited {proc.returncode}; the end of {log}:\n" + "\n".join(tail))
    return time.time() - t0, usage.ru_utime + usage.ru_stime


def do_arm(args: argparse.Namespace, arm: Arm, arms: dict[str, Arm]) -> dict[str, Any]:
    """Train (unless eval-only) and evaluate one arm in subprocesses; its bench.json row."""
    runs = REPO / args.runs_dir / args.tag  # (an absolute --runs-dir stays as it is)
    out, ckpt = runs / arm.name, runs / (arm.base or arm.name)
    out.mkdir(parents=True, exist_ok=True)
    words = arm_words(args, arm, arms)
    if arm.base is None and not finished(ckpt, args.budget_s):
        train_words = merge([RUN_FOREVER], words, [f"train.out={ckpt}", f"train.time_budget_s={args.budget_s}",
                                                    "train.threads=1"])
        wall, cpu = run_logged([sys.executable, "jobs/train.py", *train_words], out / "train.log")
        (out / "train_process.json").write_text(json.dumps({"wall_s": wall, "cpu_s": cpu}) + "\n")
        tqdm.write(f"[{arm.name}] trained in {wall:.0f}s, {cpu:.0f} CPU s (log {out / 'train.log'})")
    t0 = time.time()
    if not evaluated(out, ckpt):
        run_logged([sys.executable, __file__, "--evaluate", str(out), "--checkpoint", str(ckpt), "--tag", args.tag,
                    "--name", arm.name, "--tasks", args.tasks, "--seeds", args.seeds, "--results-out", args.results_out,
                    "--episode-limit-s", str(args.episode_limit_s), *words], out / "eval.log")
    row = json.loads((out / "bench.json").read_text())
    proc = ckpt / "train_process.json"  # absent when the training ran before this bench (then "?")
    usage = json.loads(proc.read_text()) if proc.exists() else None
    row["core_share"] = usage["cpu_s"] / usage["wall_s"] if usage else None
    tqdm.write(f"[{arm.name}] evaluated in {time.time() - t0:.0f}s: Fast-MCTD {row['fast_mctd_success']}/"
               f"{row['fast_mctd_episodes']}, guided no-warp {100 * row['guided_no_warp']:.0f}%")
    return row


def after(first: Future | None, fn: Callable[..., Any], *fn_args: Any) -> Any:
    """fn(*fn_args) once ``first`` (if any) has finished (re-raising its error)."""
    if first is not None:
        first.result()
    return fn(*fn_args)


def evaluate(args: argparse.Namespace) -> None:
    """(--evaluate) One arm's numbers into <dir>/bench.json; skipped if it holds this checkpoint's already."""
    import pyarrow.parquet as pq
    import torch

    from fmctd_dist.config import load_config
    from fmctd_dist.diffusion.checkpoint import read_manifest
    from plan_quality import plan_quality, precision

    torch.set_num_threads(1)
    out, ckpt = Path(args.evaluate), Path(args.checkpoint)
    manifest = read_manifest(ckpt)
    if evaluated(out, ckpt):
        return
    words = merge(args.overrides, [f"checkpoint={ckpt}"])
    cfg = load_config(words)  # method fast-mctd: the sampling settings the grid below plans with
    done = out / "bench.json"
    row: dict[str, Any] = {"arm": args.name, "words": args.overrides, "digest": manifest["digest"],
                           "batch_size": manifest["config"]["train"]["batch_size"],
                           "wall_time_s": manifest["wall_time_s"], "train_steps": manifest["train_steps"]}
    row["samples_per_s"] = row["train_steps"] * row["batch_size"] / max(row["wall_time_s"], 1e-9)
    t0 = time.time()
    row.update(plan_quality(ckpt, cfg))
    p = precision(ckpt, timesteps=(PRECISION_T,))
    row["precision"], row["data_steps"] = p["rows"][0], p["data"]
    row["quality_s"] = time.time() - t0
    run = f"recipe-{args.tag}-{args.name}"
    method = "fast-mctd" if cfg.jump > 1 else "p-mctd"  # a dense (H=1) arm searches as P-MCTD, the paper's dense twin
    row["search_method"] = method
    grid = merge(words, [f"method={method}", "runner=local", f"tasks=[{args.tasks}]", f"seeds=[{args.seeds}]",
                         "eval.threads=1", f"eval.run={run}", f"eval.out={args.results_out}",
                         f"eval.episode_time_limit={args.episode_limit_s}"])
    t0 = time.time()
    subprocess.run([sys.executable, "jobs/eval.py", *grid], cwd=REPO, check=True)
    files = sorted((REPO / args.results_out / run / method / cfg.env.name).glob("task=*/seed=*.parquet"))
    rows = [pq.read_table(f, columns=["success", "plan_time_s"]).to_pylist()[0] for f in files]
    row["fast_mctd_success"] = sum(bool(r["success"]) for r in rows)
    row["fast_mctd_episodes"] = len(rows)
    row["fast_mctd_plan_s"] = sum(r["plan_time_s"] for r in rows) / max(len(rows), 1)
    row["grid_s"] = time.time() - t0
    row["grid"] = f"tasks [{args.tasks}] x seeds [{args.seeds}] on {cfg.env.name}, rows in {args.results_out}/{run}"
    done.write_text(json.dumps(row, indent=2, sort_keys=True) + "\n")


def table(rows: list[dict[str, Any]], arms: dict[str, Arm]) -> str:
    """The side-by-side markdown table, one line per arm."""
    d = rows[0]["data_steps"]
    head = ("| arm | overrides | steps | samples/s | val loss | x0 RMS error | boundary step mean / max | "
            "inside step mean / max | unguided: no warp / in free cells | guided: no warp / in free cells / near goal "
            "| guided boundary / inside step | Fast-MCTD success | plan s | core share |\n|" + "---|" * 14)
    lines = [head]
    for r in rows:
        p = r["precision"]
        lines.append(
            f"| {r['arm']} | {arms[r['arm']].label} | {r['train_steps']} | {r['samples_per_s']:.0f} | "
            f"{r['val_loss']:.4f} | {p['x0_rms']:.3f} | {p['boundary_mean']:.2f} / {p['boundary_max']:.2f} | "
            f"{p['inside_mean']:.2f} / {p['inside_max']:.2f} | {100 * r['unguided_no_warp']:.0f}% / "
            f"{100 * r['unguided_in_free']:.1f}% | {100 * r['guided_no_warp']:.0f}% / "
            f"{100 * r['guided_in_free']:.1f}% / "
            f"{100 * r['guided_near_goal']:.0f}% | {r['guided_boundary_step']:.2f} / {r['guided_inside_step']:.2f} | "
            f"{r['fast_mctd_success']}/{r['fast_mctd_episodes']} | {r['fast_mctd_plan_s']:.1f} | "
            f"{'?' if r.get('core_share') is None else format(r['core_share'], '.2f')} |")
    lines.append(f"\n(x0 error and steps at timestep {PRECISION_T}, world units; the data's own steps: boundary "
                 f"{d['boundary_mean']:.2f} / {d['boundary_max']:.2f}, inside {d['inside_mean']:.2f} / "
                 f"{d['inside_max']:.2f}. Fast-MCTD: {rows[0]['grid'].replace(rows[0]['arm'], '<arm>')}.)")
    return "\n".join(lines)


def append_to_doc(doc: Path, block: str) -> None:
    """Add ``block`` at the end of section 4's "Recipe bench" subsection (made if missing), before section 5."""
    text = doc.read_text() if doc.exists() else ""
    if SECTION not in text:
        block = f"{SECTION}\n\n{INTRO}\n\n{block}"
    m = re.search(r"^## 5\.", text, flags=re.M)
    at = m.start() if m else len(text)
    before = text[:at].rstrip("\n")
    doc.write_text((before + "\n\n" if before else "") + block.rstrip("\n") + "\n\n" + text[at:])


def parse(argv: list[str]) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--arm", action="append", default=[], help="NAME:WORDS or NAME@OTHER:WORDS (repeatable)")
    ap.add_argument("--tag", default="bench", help="runs go to <runs-dir>/<tag>/<arm>")
    ap.add_argument("--budget-s", type=float, default=600.0, help="training wall-clock per arm (train.time_budget_s)")
    ap.add_argument("--parallel", type=int, choices=(1, 2), default=1, help="arms trained at once (one core each)")
    ap.add_argument("--tasks", default="1,2,3,4,5", help="Fast-MCTD grid tasks, e.g. 1,2,3,4,5")
    ap.add_argument("--seeds", default="0", help="Fast-MCTD grid seeds, e.g. 0")
    ap.add_argument("--episode-limit-s", type=float, default=120.0, help="eval.episode_time_limit of the grid")
    ap.add_argument("--runs-dir", default="runs/recipe")
    ap.add_argument("--results-out", default="results", help="eval.out of the Fast-MCTD grid")
    ap.add_argument("--doc", default="docs/notebook/training-campaign.md",
                    help="file the table is appended to; '' = none")
    ap.add_argument("--evaluate", help=argparse.SUPPRESS)  # internal: evaluate one arm dir
    ap.add_argument("--checkpoint", help=argparse.SUPPRESS)
    ap.add_argument("--name", help=argparse.SUPPRESS)
    ap.add_argument("overrides", nargs="*", help="common key=value overrides, e.g. env=pointmaze-medium jump=5")
    return ap.parse_args(argv)


def main(argv: list[str]) -> int:
    args = parse(argv)
    if args.evaluate:
        evaluate(args)
        return 0
    arms = {a.name: a for a in map(Arm, args.arm or ["base:"])}
    order = list(arms)
    for a in arms.values():
        if a.base and (a.base not in arms or order.index(a.base) > order.index(a.name) or arms[a.base].base):
            raise SystemExit(f"error: --arm {a.name}@{a.base}: {a.base!r} must be a trained arm given before it")
    command = "OMP_NUM_THREADS=1 python jobs/bench/bench_recipe.py " + shlex.join(argv)
    print(f"{len(arms)} arms, {args.budget_s:.0f}s of training each, {args.parallel} at a time: {command}", flush=True)
    t0 = time.time()
    rows: dict[str, dict[str, Any]] = {}
    with ThreadPoolExecutor(args.parallel) as pool, tqdm(total=len(arms), desc="arms", dynamic_ncols=True) as bar:
        futures: dict[str, Any] = {}
        for name, arm in arms.items():  # an eval-only arm waits for its base arm's training (submitted before it)
            base = futures.get(arm.base)
            futures[name] = pool.submit(after, base, do_arm, args, arm, arms)
        for name, fut in futures.items():
            rows[name] = fut.result()
            bar.update(1)
    text = table([rows[n] for n in arms], arms)
    print(text)
    print(f"bench wall time {time.time() - t0:.0f}s")
    if args.doc:
        stamp = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
        append_to_doc(REPO / args.doc, f"{stamp}, {args.budget_s:.0f} s of training per arm:\n\n```bash\n{command}\n"
                                       f"```\n\n{text}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
