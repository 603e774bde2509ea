"""Record the denoiser call traces of real plans, and replay them on any device (issue 55).

    python jobs/bench/replay.py env=pointmaze-medium method.budget=100          # record, then replay here
    python jobs/bench/replay.py mode=replay out=bench/replay device=cuda        # replay stored traces on a GPU
    python jobs/bench/replay.py mode=replay weights=random                      # same architecture, random weights
    python jobs/bench/replay.py --dry-run <tiny checkpoint overrides>           # seconds: budget 4, one round

``mode=record`` plans one plan per method (default ``methods=[mctd,p-mctd,s-mctd,fast-mctd]``): the first
plan of episode (``task=1``, ``seed=0``) of ``env=`` with the shipped checkpoint, through a TracingDenoiser
around the LocalDenoiser (denoiser.trace), after one untimed warm-up call; the episode stops there. Each
method's trace and plan times go to ``<out>/<env>/<method>.json`` (default ``out=bench/replay``).
``mode=replay`` replays every call of the stored traces: a batch of the call's shape and model work (random
tokens, the same levels pattern, the same guided share; ``trace.replay_batch``) through a LocalDenoiser with
the ``weights=real|random`` of the checkpoint's architecture on ``device=``. ``mode=both`` (the default) does
both, a plan then its replay, ``rounds=2`` times (the fastest of each counts, so a change in the machine's
load hits both alike). The table, printed and written to ``<out>/<env>/replay-<device>.md``, gives per
method: measured plan time, the search's own overhead (plan - denoise), the replayed denoiser time, the
replayed plan time (replayed denoiser + measured overhead) and replayed / measured, which on the recording
CPU should be ~1 (within 10%). Words not named here are config overrides (``method.budget=100``,
``eval.threads=1``), applied to every method.
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
from fmctd_dist.denoiser.trace import TracingDenoiser, replay_batch
from fmctd_dist.device import set_threads
from fmctd_dist.diffusion.checkpoint import (
    load_checkpoint, model_from_manifest, normaliser_from_manifest, read_manifest,
)
from fmctd_dist.errors import ConfigError
from fmctd_dist.evaluation.grid import prepare
from fmctd_dist.families import guide_map, hooks_for, plan_rules
from fmctd_dist.planners import make_planner

METHODS = ["mctd", "p-mctd", "s-mctd", "fast-mctd"]
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


def replay(trace: dict, weights: str, device: str) -> tuple[float, float]:
    """Replaying every call of ``trace`` once: (seconds of model work, ``denoise_time_s``; CPU seconds of the calls)."""
    cfg = load_config(trace["overrides"] + [f"method={trace['method']}", f"device={device}"])
    set_threads(cfg.eval.threads)
    den = denoiser(cfg, weights, device)
    rng = np.random.default_rng(0)
    batches = [replay_batch(c, rng) for c in trace["calls"]]
    if batches:  # warm-up, as when recording
        den.denoise(batches[0], micro_batch=trace["calls"][0]["micro_batch"])
    c0 = time.process_time()
    results = [den.denoise(b, micro_batch=c["micro_batch"]) for b, c in zip(batches, trace["calls"])]
    cpu = time.process_time() - c0
    made, want = sum(r.stats["model_calls"] for r in results), sum(c["model_calls"] for c in trace["calls"])
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


def table(rows: list[dict], device: str, weights: str) -> str:
    """Wall seconds, and the same ratio in CPU seconds of this process (which other jobs on the cores do not
    stretch): CPU overhead = plan CPU - the calls' CPU, replayed plan CPU = the replayed calls' CPU + it."""
    lines = [f"replayed on {device} ({weights} weights); recorded on {rows[0]['trace']['cpu']}", "",
             "| method | calls | jobs | model calls | plan (s) | overhead (s) | replayed denoiser (s) | "
             "replayed plan (s) | replayed / measured | the same in CPU s |", "|---" * 10 + "|"]
    for r in rows:
        t = r["trace"]
        overhead = t["plan_s"] - t["denoise_s"]
        plan = r["replay_s"] + overhead
        cpu = (r["replay_cpu_s"] + t["plan_cpu_s"] - sum(c["cpu_s"] for c in t["calls"])) / max(t["plan_cpu_s"], 1e-12)
        lines.append(f"| {t['method']} | {len(t['calls'])} | {sum(c['jobs'] for c in t['calls'])} | "
                     f"{sum(c['model_calls'] for c in t['calls'])} | {t['plan_s']:.2f} | {overhead:.2f} | "
                     f"{r['replay_s']:.2f} | {plan:.2f} | {plan / max(t['plan_s'], 1e-12):.3f} | {cpu:.3f} |")
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    words = {"methods": ",".join(METHODS), "out": "bench/replay", "task": "1", "seed": "0", "weights": "real",
             "mode": "both", "rounds": "2"}
    overrides, dry = [], "--dry-run" in argv
    for a in argv:
        key, eq, value = a.partition("=")
        if eq and key in words:
            words[key] = value
        elif a != "--dry-run":
            overrides.append(a)
    if words["mode"] not in ("record", "replay", "both") or words["weights"] not in ("real", "random"):
        raise ConfigError(f"mode={words['mode']} weights={words['weights']}: mode is record, replay or both; "
                          "weights is real or random")
    given = {o.partition("=")[0] for o in overrides}
    overrides += [o for o in DRY_RUN if dry and o.partition("=")[0] not in given]
    words["rounds"] = "1" if dry and not any(a.startswith("rounds=") for a in argv) else words["rounds"]
    cfg = load_config(overrides)
    folder = Path(words["out"]) / cfg.env.name
    methods = [m.strip() for m in words["methods"].strip("[]").split(",") if m.strip()]
    rows, mode = [], words["mode"]
    for m in methods:
        path = folder / f"{m}.json"
        if mode == "replay" and not path.exists():
            raise ConfigError(f"no trace {path}; record it first: python jobs/bench/replay.py mode=record "
                              f"env={cfg.env.name} methods=[{m}] out={words['out']}")
        stored = json.loads(path.read_text()) if mode == "replay" else None
        best, replayed = stored, (float("inf"), float("inf"))
        # rounds alternate plan and replay, and the fastest of each counts: a change in the machine's load
        # hits both alike
        for _ in range(int(words["rounds"])):
            trace = stored or record(m, overrides, int(words["task"]), int(words["seed"]))
            if best is None or trace["plan_s"] < best["plan_s"]:
                best = trace
            if mode != "record":
                replayed = tuple(map(min, replayed, replay(trace, words["weights"], cfg.device)))
        if mode != "replay":
            folder.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(best))
            print(f"{m}: recorded {len(best['calls'])} calls, plan {best['plan_s']:.2f}s", flush=True)
        if mode != "record":
            rows.append({"trace": best, "replay_s": replayed[0], "replay_cpu_s": replayed[1]})
    if not rows:
        return 0
    text = table(rows, cfg.device, words["weights"])
    print(text)
    (folder / f"replay-{cfg.device}.md").write_text(text + "\n")
    return 0


if __name__ == "__main__":
    run(main)
