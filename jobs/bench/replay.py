"""Record the denoiser call traces of real plans, replay them on any device, project them onto a GPU (issue 55).

    python jobs/bench/replay.py env=pointmaze-medium method.budget=100          # record, then replay here
    python jobs/bench/replay.py mode=replay out=bench/replay device=cuda        # replay stored traces on a GPU
    python jobs/bench/replay.py mode=replay weights=random                      # same architecture, random weights
    python jobs/bench/replay.py mode=replay batch=call device=cuda              # each call as one batch (paper's GPU)
    python jobs/bench/replay.py mode=project out=jobs/bench/traces              # H200 projection of the stored traces
    python jobs/bench/replay.py --dry-run <tiny checkpoint overrides>           # seconds: budget 4, one round

``mode=record`` plans one plan per method (default ``methods=[mctd,p-mctd,s-mctd,fast-mctd]``): the first
plan of episode (``task=1``, ``seed=0``) of ``env=`` with the shipped checkpoint, through a TracingDenoiser
around the LocalDenoiser (denoiser.trace), after one untimed warm-up call; the episode stops there. Each
method's trace and plan times go to ``<out>/<env>/<method>.json`` (default ``out=bench/replay``; the committed
full-budget traces are under ``jobs/bench/traces``, large ones gzipped: both are read).
``mode=replay`` replays every call of the stored traces (the first ``calls=N`` only when N > 0): a batch of the
call's shape and model work (random tokens, the same levels pattern, the same guided share;
``trace.replay_batch``) through a LocalDenoiser with the ``weights=real|random`` of the checkpoint's
architecture on ``device=``, at the recorded micro-batch (``batch=trace``, the default) or each call as one batch
of all its jobs (``batch=call``: the paper's GPU setting, 200 rollouts in one batch). ``mode=both`` (the
default) does both, a plan then its replay, ``rounds=2`` times (the fastest of each counts, so a change in the
machine's load hits both alike); ``envs=[a,b]`` runs each env in turn (one process: one CUDA start). The table,
printed and written (with a JSON of its rows) to ``replay-<device>[-call].md`` in ``<out>/<env>`` (or in
``<report>/<env>`` when ``report=`` is given), gives per method: measured plan time,
the search's own overhead (plan - denoise), the replayed denoiser time, the replayed plan time (replayed
denoiser + measured overhead) and replayed / measured, which on the recording CPU should be ~1 (within 10%).
``mode=project`` needs no model: for every ``<out>/<env>`` folder (or ``envs=[...]``) it prices each stored
call with the H200 throughput table (``jobs/bench/projection.py``, a projection, not a measurement) and writes
``<report>/projection.md`` (default ``report=<out>``): per maze MCTD / Fast-MCTD, CPU, projected and the paper's.
Words not named here are config overrides (``method.budget=100``, ``eval.threads=1``), applied to every method.
"""

from __future__ import annotations

import json
import platform
import time
from pathlib import Path

import numpy as np
import torch

from fmctd_dist.cli import run
from fmctd_dist.config import load_config
from fmctd_dist.denoiser.local import LocalDenoiser
from projection import BATCHES, H200_SOURCE, project, search_cpu_s
from fmctd_dist.denoiser.trace import TracingDenoiser, as_one_batch, load_trace, replay_batch
from fmctd_dist.device import set_threads
from fmctd_dist.diffusion.checkpoint import (
    load_checkpoint, model_from_manifest, normaliser_from_manifest, read_manifest,
)
from fmctd_dist.errors import ConfigError
from fmctd_dist.evaluation.grid import prepare
from fmctd_dist.families import guide_map, hooks_for, plan_rules
from fmctd_dist.families.maze.paper import ANTMAZE, POINTMAZE
from fmctd_dist.planners import make_planner

METHODS = ["mctd", "p-mctd", "s-mctd", "fast-mctd"]
MODES = ("record", "replay", "both", "project")
DRY_RUN = ["method.budget=4", "method.early_stop=false"]  # a few expansions per method


class _Planned(Exception):
    """Raised by :class:`FirstPlan` once the episode's first plan is made: the rollout is not part of the bench."""


class FirstPlan:
    """The planner an episode sees: it keeps the first plan's output and ends the episode."""

    def __init__(self, planner):
        self.planner, self.out, self.cpu_s = planner, None, 0.0

    def plan(self, start, goal, seed):
        c0 = time.process_time()
        self.out = self.planner.plan(start, goal, seed)
        self.cpu_s = time.process_time() - c0
        raise _Planned


class FirstCall:
    """The denoiser of the warm-up plan: its first call runs, then the plan stops."""

    def __init__(self, inner):
        self.inner, self.micro_batch = inner, inner.micro_batch

    def denoise(self, batch):
        self.inner.denoise(batch)
        raise _Planned


def denoiser(cfg, weights: str, device: str) -> LocalDenoiser:
    """The checkpoint's denoiser (``weights=real``) or one of its architecture with seeded random weights."""
    path = cfg.checkpoint_dir()
    if weights == "real":
        model, manifest = load_checkpoint(path, cfg)
    else:
        manifest = read_manifest(path, cfg)
        torch.manual_seed(0)
        model = model_from_manifest(manifest)
    guide = guide_map(cfg.env.name)  # the family's guidance space (the visual maze), else None
    return LocalDenoiser(model, cfg.diffusion, device, cfg.ray.micro_batch, manifest["digest"],
                         None if guide is None else guide(cfg, manifest))


def record(method: str, overrides: list[str], task: int, seed: int) -> dict:
    """One traced plan of ``method``: its trace, plan and denoise seconds, and how it ran."""
    cfg = load_config(overrides + [f"method={method}"])
    prepared = prepare(cfg, hooks_for)
    set_threads(cfg.eval.threads)
    local = denoiser(cfg, "real", cfg.device)
    traced = TracingDenoiser(local)
    normaliser = normaliser_from_manifest(read_manifest(prepared.checkpoint))
    episodes = hooks_for(cfg.env.name).episodes(cfg)
    # the warm-up plan runs its first call only (lazy initialisation is not planning time); then the timed plan
    for den in (FirstCall(local), traced):
        planner = FirstPlan(make_planner(cfg, den, normaliser, plan_rules(cfg), cfg.eval.episode_time_limit))
        try:
            episodes.run(planner, task, seed)
        except _Planned:
            pass
    out = planner.out
    calls = traced.take()
    return {"method": method, "env": cfg.env.name, "task": task, "seed": seed, "overrides": overrides,
            "plan_s": out.plan_time_s, "denoise_s": out.denoise_time_s, "plan_cpu_s": planner.cpu_s,
            "status": out.status,
            "expansions": out.expansions, "iterations": out.iterations, "device": str(local.device),
            "torch_threads": torch.get_num_threads(), "cpu": cpu_name(),
            "checkpoint_digest": prepared.checkpoint_digest,
            "calls": calls}


def replay(trace: dict, weights: str, device: str, batch: str = "trace", calls: int = 0) -> tuple[float, float]:
    """Replaying the calls of ``trace`` once (the first ``calls`` of them when > 0), each at its recorded
    micro-batch (``batch=trace``) or as one batch of all its jobs (``batch=call``, ``trace.as_one_batch``):
    (seconds of model work, ``denoise_time_s``; CPU seconds of the calls)."""
    cfg = load_config(trace["overrides"] + [f"method={trace['method']}", f"device={device}"])
    set_threads(cfg.eval.threads)
    den = denoiser(cfg, weights, device)
    rng = np.random.default_rng(0)
    recs = trace["calls"][:calls] if calls > 0 else trace["calls"]
    recs = [as_one_batch(c) for c in recs] if batch == "call" else recs
    batches = [replay_batch(c, rng) for c in recs]
    if batches:  # warm-up, as when recording
        den.denoise(batches[0], micro_batch=recs[0]["micro_batch"])
    c0 = time.process_time()
    results = [den.denoise(b, micro_batch=c["micro_batch"]) for b, c in zip(batches, recs)]
    cpu = time.process_time() - c0
    made, want = sum(r.stats["model_calls"] for r in results), sum(c["model_calls"] for c in recs)
    if made != want:
        raise RuntimeError(f"{trace['method']}: the replay made {made} model calls, the trace {want}")
    return sum(r.denoise_time_s for r in results), cpu


def cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def table(rows: list[dict], device: str, weights: str, batch: str = "trace", calls: int = 0) -> str:
    """Wall seconds, and the same ratio in CPU seconds of this process (which other jobs on the cores do not
    stretch): CPU overhead = plan CPU - the calls' CPU, replayed plan CPU = the replayed calls' CPU + it.
    ``batch=call``: each call replayed as one batch (model calls: the whole call's); ``calls`` > 0: the first
    ``calls`` calls only, so the replayed times are not the plan's (a dry run's)."""
    how = "each call as one batch" if batch == "call" else "at the recorded micro-batch"
    part = f"; THE FIRST {calls} CALLS ONLY" if calls > 0 else ""
    lines = [f"replayed on {device} ({weights} weights, {how}{part}); recorded on {rows[0]['trace']['cpu']}", "",
             "| method | calls | jobs | model calls | plan (s) | overhead (s) | replayed denoiser (s) | "
             "replayed plan (s) | replayed / measured | the same in CPU s |", "|---" * 10 + "|"]
    for r in rows:
        t = r["trace"]
        overhead = t["plan_s"] - t["denoise_s"]
        plan = r["replay_s"] + overhead
        cpu = (r["replay_cpu_s"] + search_cpu_s(t)) / max(t["plan_cpu_s"], 1e-12)
        made = sum((as_one_batch(c) if batch == "call" else c)["model_calls"] for c in t["calls"])
        lines.append(f"| {t['method']} | {len(t['calls'])} | {sum(c['jobs'] for c in t['calls'])} | "
                     f"{made} | {t['plan_s']:.2f} | {overhead:.2f} | "
                     f"{r['replay_s']:.2f} | {plan:.2f} | {plan / max(t['plan_s'], 1e-12):.3f} | {cpu:.3f} |")
    return "\n".join(lines)


def paper_seconds(env: str, method: str) -> float | None:
    """The paper's GPU planning time of ``method`` on ``env`` (PointMaze and AntMaze tables), else None."""
    family, _, maze = env.partition("-")
    return {"pointmaze": POINTMAZE, "antmaze": ANTMAZE}.get(family, {}).get(method, {}).get(maze, (None,) * 3)[2]


def projection_tables(traces: dict[str, dict[str, dict]]) -> str:
    """The projection (env -> method -> trace) as two markdown tables: per maze MCTD / Fast-MCTD (CPU, projected,
    paper), then per method the model work and both GPU micro-batch settings (``jobs/bench/projection.py``)."""
    def ratio(a, b):
        return f"{a / b:.1f}x" if a is not None and b else "–"

    lines = [f"**Projection**, not a measurement: H200 throughput table ({H200_SOURCE}), log-log interpolated over "
             "tokens and batch; + the search's own CPU seconds as recorded. CPU seconds are this process's "
             "(one torch thread).", "",
             "| maze | MCTD: CPU plan (s) | Fast-MCTD: CPU plan (s) | CPU ratio | projected MCTD (s) | "
             "projected Fast-MCTD (s) | projected ratio | Fast-MCTD at its recorded M: projected (s), ratio | "
             "paper (GPU) |", "|---" * 9 + "|"]
    for env, by in traces.items():
        if not {"mctd", "fast-mctd"} <= by.keys():
            continue
        m, f = by["mctd"], by["fast-mctd"]
        pm, pf, pt = project(m)["plan_s"], project(f)["plan_s"], project(f, "trace")["plan_s"]
        qm, qf = paper_seconds(env, "mctd"), paper_seconds(env, "fast-mctd")
        paper = f"{qm} / {qf} = {ratio(qm, qf)}" if qm and qf else "–"
        lines.append(f"| {env} | {m['plan_cpu_s']:.1f} | {f['plan_cpu_s']:.2f} | "
                     f"{ratio(m['plan_cpu_s'], f['plan_cpu_s'])} | {pm:.2f} | {pf:.2f} | **{ratio(pm, pf)}** | "
                     f"{pt:.2f}, {ratio(pm, pt)} | {paper} |")
    lines += ["", "| maze | method | status | calls | jobs | tokens | model calls: recorded M / one batch per call "
              "| CPU plan (s) | search, CPU (s) | projected model (s): per call / at recorded M | "
              "projected plan (s) | paper (s) |", "|---" * 12 + "|"]
    for env, by in traces.items():
        for method, t in by.items():
            call, rec = project(t, "call"), project(t, "trace")
            tokens = sorted({c["tokens"] for c in t["calls"]})
            lines.append(
                f"| {env} | {method} | {t['status']} | {len(t['calls'])} | {sum(c['jobs'] for c in t['calls'])} | "
                f"{'/'.join(map(str, tokens))} | {sum(c['model_calls'] for c in t['calls']):,} / "
                f"{sum(as_one_batch(c)['model_calls'] for c in t['calls']):,} | {t['plan_cpu_s']:.2f} | "
                f"{call['overhead_s']:.2f} | {call['model_s']:.2f} / {rec['model_s']:.2f} | {call['plan_s']:.2f} | "
                f"{paper_seconds(env, method) or '–'} |")
    return "\n".join(lines)


def by_size(env: str) -> tuple:
    """Sort key: a family's mazes small to large (medium, large, giant), as the paper's tables list them."""
    family, _, size = env.rpartition("-")
    return family, {"medium": 0, "large": 1, "giant": 2}.get(size, 3), size


def project_mode(out: Path, methods: list[str], envs: list[str], report: Path) -> int:
    """``mode=project``: the projection of every stored trace of ``methods`` under ``out`` (or of ``envs``)."""
    envs = envs or sorted((p.name for p in out.iterdir() if p.is_dir()), key=by_size)
    traces = {e: {m: t for m in methods if (t := load_trace(out / e, m)) is not None} for e in envs}
    traces = {e: by for e, by in traces.items() if by}
    if not traces:
        raise ConfigError(f"no traces of {methods} under {out}; record them: python jobs/bench/replay.py "
                          f"mode=record env=<env> out={out}")
    text = projection_tables(traces)
    print(text)
    report.mkdir(parents=True, exist_ok=True)
    (report / "projection.md").write_text(text + "\n")
    return 0


def words_list(value: str) -> list[str]:
    return [m.strip() for m in value.strip("[]").split(",") if m.strip()]


def main(argv: list[str]) -> int:
    words = {"methods": ",".join(METHODS), "out": "bench/replay", "task": "1", "seed": "0", "weights": "real",
             "mode": "both", "rounds": "2", "batch": "trace", "calls": "0", "report": "", "envs": ""}
    overrides, dry = [], "--dry-run" in argv
    for a in argv:
        key, eq, value = a.partition("=")
        if eq and key in words:
            words[key] = value
        elif a != "--dry-run":
            overrides.append(a)
    if words["mode"] not in MODES or words["weights"] not in ("real", "random") or words["batch"] not in BATCHES:
        raise ConfigError(f"mode={words['mode']} weights={words['weights']} batch={words['batch']}: mode is one of "
                          f"{MODES}, weights real or random, batch one of {BATCHES}")
    methods = words_list(words["methods"])
    if words["mode"] == "project":
        return project_mode(Path(words["out"]), methods, words_list(words["envs"]),
                            Path(words["report"] or words["out"]))
    given = {o.partition("=")[0] for o in overrides}
    overrides += [o for o in DRY_RUN if dry and o.partition("=")[0] not in given]
    words["rounds"] = "1" if dry and not any(a.startswith("rounds=") for a in argv) else words["rounds"]
    for env in words_list(words["envs"]) or [""]:  # one env (``env=``, or the default), or each of ``envs=``
        run_env(overrides + [f"env={env}"] * bool(env), methods, words)
    return 0


def run_env(overrides: list[str], methods: list[str], words: dict[str, str]) -> None:
    """``mode=record|replay|both`` of ``methods`` on the env ``overrides`` name (main's docstring)."""
    cfg = load_config(overrides)
    folder = Path(words["out"]) / cfg.env.name
    rows, mode, batch, calls = [], words["mode"], words["batch"], int(words["calls"])
    for m in methods:
        stored = load_trace(folder, m) if mode == "replay" else None
        if mode == "replay" and stored is None:
            raise ConfigError(f"no trace {folder / m}.json; record it first: python jobs/bench/replay.py "
                              f"mode=record env={cfg.env.name} methods=[{m}] out={words['out']}")
        best, replayed = stored, (float("inf"), float("inf"))
        # rounds alternate plan and replay, and the fastest of each counts: a change in the machine's load
        # hits both alike
        for _ in range(int(words["rounds"])):
            trace = stored or record(m, overrides, int(words["task"]), int(words["seed"]))
            if best is None or trace["plan_s"] < best["plan_s"]:
                best = trace
            if mode != "record":
                replayed = tuple(map(min, replayed, replay(trace, words["weights"], cfg.device, batch, calls)))
        if mode != "replay":
            folder.mkdir(parents=True, exist_ok=True)
            (folder / f"{m}.json").write_text(json.dumps(best))
            print(f"{m}: recorded {len(best['calls'])} calls, plan {best['plan_s']:.2f}s", flush=True)
        if mode != "record":
            rows.append({"trace": best, "replay_s": replayed[0], "replay_cpu_s": replayed[1]})
            # written after each method: a run stopped by a time limit keeps the rows it finished
            write_report(rows, Path(words["report"]) / cfg.env.name if words["report"] else folder, cfg.device,
                         words["weights"], batch, calls)
    if rows:
        print(table(rows, cfg.device, words["weights"], batch, calls))


def write_report(rows: list[dict], report: Path, device: str, weights: str, batch: str, calls: int) -> None:
    """``replay-<device>[-call].md`` (the table) and ``.json`` (its rows, for jobs/gpu/gpu_replay.py) in ``report``."""
    report.mkdir(parents=True, exist_ok=True)
    name = f"replay-{device}" + ("" if batch == "trace" else f"-{batch}")
    (report / f"{name}.md").write_text(table(rows, device, weights, batch, calls) + "\n")
    (report / f"{name}.json").write_text(json.dumps(
        [{"method": r["trace"]["method"], "env": r["trace"]["env"], "batch": batch, "calls": calls,
          "replay_s": r["replay_s"], "replay_cpu_s": r["replay_cpu_s"], "plan_s": r["trace"]["plan_s"],
          "search_cpu_s": search_cpu_s(r["trace"]), "device": device} for r in rows], indent=1))


if __name__ == "__main__":
    run(main)
