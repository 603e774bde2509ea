"""Side-by-side planning speed: several methods on the same episodes, in one run.

    python jobs/bench_speed.py env=pointmaze-medium tasks=[1,2,3,4,5] seeds=[0,1]
    python jobs/bench_speed.py env=pointmaze-giant methods=[mctd,fast-mctd] eval.episode_time_limit=600
    python jobs/bench_speed.py env=pointmaze-medium seeds=[0,1] store=main   # also keep the rows
    python jobs/bench_speed.py env=cube-single methods=[mctd-replan,fast-mctd-replan] seeds=[0]   # robot arm
    python jobs/bench_speed.py env=pointmaze-medium methods=[fast-mctd,fast-mctd+compiled,fast-mctd+bf16+compiled]

A method may carry inference options after '+' (``bf16``, ``compiled``; denoiser.runtime): the same
method on the same episodes with ``diffusion.precision=bf16`` and/or ``diffusion.compile=true``, so
the time / fast-mctd column is the option's speed-up and the success column what it costs.

With ``store=<run>`` every episode is also written as a result row to ``<eval.out>/<run>/``
(the same rows jobs/eval.py writes with ``runner=local``), so the maze table can use them; a method
with options (below) writes to ``<eval.out>/<run>+<options>/`` (e.g. ``main+compiled``). The same
command run again resumes: episodes the store holds are read back, not re-run.

For each method (default: mctd, p-mctd, s-mctd, fast-mctd, diffuser) every episode is run in this
process with a LocalDenoiser on that method's checkpoint, interleaved per episode so load
on the machine hits all methods alike; the episode is the env family's (``families.hooks_for(env).episodes``:
mazes with their PD or ant controller, cubes with the arm's scripts and policy). Prints success,
mean planning time, the share of planning time inside the denoiser, and planning-time ratios
against Fast-MCTD (``fast-mctd``, else ``fast-mctd-replan``, else the last method) — ratios, not
seconds, are what compare across machines (the paper: MCTD / Fast-MCTD = 264.2 / 2.4 =
110x on PointMaze-giant; MCTD-Replan / Fast-MCTD-Replan = 9.2 / 3.0 = 3.1x on cube-single).
"""

from __future__ import annotations

import time

import numpy as np
import torch

from fmctd_dist.cli import run
from fmctd_dist.config import load_config
from fmctd_dist.denoiser.local import LocalDenoiser
from fmctd_dist.denoiser.runtime import option_overrides
from fmctd_dist.device import set_threads
from fmctd_dist.diffusion.checkpoint import load_checkpoint, normaliser_from_manifest
from fmctd_dist.evaluation.results import describe
from fmctd_dist.evaluation.grid import missing, prepare, provenance, same_policy
from fmctd_dist.evaluation.results import ResultStore
from fmctd_dist.families import hooks_for
from fmctd_dist.planners import make_planner

DEFAULT_METHODS = ["mctd", "p-mctd", "s-mctd", "fast-mctd", "diffuser"]
REFERENCES = ("fast-mctd", "fast-mctd-replan")  # the method the time ratios divide by, first present


def reference(methods: list[str]) -> str:
    return next((m for m in REFERENCES if m in methods), methods[-1])


def build(spec: str, overrides: list[str]):
    method, _, options = spec.partition("+")
    cfg = load_config(overrides + [f"method={method}"] + (option_overrides(options) if options else []))
    prepared = prepare(cfg, hooks_for)  # device, checkpoint present and uncorrupted
    model, manifest = load_checkpoint(prepared.checkpoint, cfg)
    denoiser = LocalDenoiser(model, cfg.diffusion, cfg.device, cfg.ray.micro_batch, manifest["digest"])
    planner = make_planner(cfg, denoiser, normaliser_from_manifest(manifest), prepared.plan_rules(cfg),
                           cfg.eval.episode_time_limit)
    return cfg, planner, prepared


def main(argv: list[str]) -> int:
    methods = DEFAULT_METHODS
    rest, store = [], None
    for a in argv:
        if a.startswith("methods="):
            methods = [m.strip() for m in a.split("=", 1)[1].strip("[]").split(",") if m.strip()]
        elif a.startswith("store="):
            store = a.split("=", 1)[1]
        else:
            rest.append(a)
    setups = {m: build(m, rest) for m in methods}  # every config and checkpoint checked up front
    cfg0 = next(iter(setups.values()))[0]
    # rows are keyed by (method, env, task, seed): an option arm keeps its rows in its own run, "<store>+<options>",
    # so that two configs of one method never share (or overwrite) a row file
    stores = {m: ResultStore(cfg0.eval.out, store + m[len(m.partition("+")[0]):]) for m in methods} if store else {}
    for m, st in stores.items():  # refuse a store holding rows of another config or checkpoint, before any episode
        missing(setups[m][2], st)
    # a killed run resumes: an episode whose row the store already holds (same identity, checked above) is read
    # back instead of planned again, so only the missing ones run
    stored = {m: {(int(r["task"]), int(r["seed"])): r for r in st.rows(setups[m][0].method.name, setups[m][0].env.name)}
              for m, st in stores.items()}
    n_stored = sum((t, s) in stored.get(m, {}) for m in methods for t in cfg0.eval.tasks for s in cfg0.eval.seeds)
    if n_stored:
        print(f"resuming: {n_stored} episode(s) read back from store={store}, not run again", flush=True)
    set_threads(cfg0.eval.threads)
    episodes = {}  # per method: the family's env + controller (a method may set env.* or its policy)
    for m, (cfg, _, prepared) in setups.items():
        episodes[m] = prepared.episodes(cfg)
        same_policy(prepared, episodes[m])
    for m, (cfg, planner, _) in setups.items():  # compilation is a one-off cost, not planning time
        if cfg.diffusion.compile:
            t = time.time()
            episodes[m].run(planner, cfg0.eval.tasks[0], cfg0.eval.seeds[0])
            print(f"{m}: warm-up episode (compilation) {time.time() - t:.0f}s, not counted", flush=True)
    rows: dict[str, list[dict]] = {m: [] for m in methods}
    t0 = time.time()
    for task in cfg0.eval.tasks:
        for seed in cfg0.eval.seeds:
            for m, (cfg, planner, prepared) in setups.items():
                if (task, seed) in stored.get(m, {}):
                    rows[m].append(stored[m][(task, seed)])
                    continue
                row = episodes[m].run(planner, task, seed)
                rows[m].append(row)
                if store:
                    stores[m].write({**row, **provenance(prepared, 0)})
                print(describe(row), flush=True)
    ref = reference(methods)
    ref_time = np.mean([r["plan_time_s"] for r in rows[ref]])
    print(f"\n{cfg0.env.name}, tasks {cfg0.eval.tasks} x seeds {cfg0.eval.seeds}, torch threads "
          f"{torch.get_num_threads()}, {time.time() - t0:.0f}s total\n")
    print(f"| method | success (%) | planning time (s) | time / {ref} | in denoiser | expansions | iterations |")
    print("|---|---|---|---|---|---|---|")
    for m, rs in rows.items():
        t = np.array([r["plan_time_s"] for r in rs])
        share = np.sum([r["denoise_time_s"] for r in rs]) / max(t.sum(), 1e-12)
        timed_out = sum(r["timed_out"] for r in rs)
        print(f"| {m} | {100 * np.mean([r['success'] for r in rs]):.0f}"
              f"{f' ({timed_out} timed out)' if timed_out else ''} | "
              f"{t.mean():.2f} ± {t.std():.2f} | "
              f"{t.mean() / ref_time:.1f}x | {100 * share:.1f}% | {np.mean([r['expansions'] for r in rs]):.0f} | "
              f"{np.mean([r['iterations'] for r in rs]):.1f} |")
    return 0


if __name__ == "__main__":
    run(main)
