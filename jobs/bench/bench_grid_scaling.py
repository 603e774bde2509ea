"""Grid throughput over actor count (issue 55 item 4): the same episodes under each setting of runner x nodes x env
actors x denoiser actors x eval.in_flight, their rows compared bit for bit, and the grid projected on N GPUs.

    OMP_NUM_THREADS=1 python jobs/bench/bench_grid_scaling.py out=runs/bench/grid-scaling      # the default sweep
    python jobs/bench/bench_grid_scaling.py 'settings=[local:f1,ray:e2d2f1,cluster2:e2d2f1]' out=DIR <config words>

A setting is ``WHERE:e<E>d<D>f<F>``: WHERE is ``local`` (runner=local: one process, one in-process denoiser, F
episodes in flight pooled; only ``f<F>``), ``ray`` (runner=ray on a private local ``ray.init``: E env actors, D
denoiser actors, eval.in_flight=F) or ``cluster<N>`` (runner=ray on a simulated cluster in this machine,
``ray.cluster_utils.Cluster``: N nodes of ``node_cpus`` CPUs, the head one of them). The first setting is the
baseline. Each setting runs in its own process (a process holds one Ray connection), its rows to ``<out>/<setting>``.
Episodes per hour count from the moment the runner is ready (its model loaded in process; on Ray, every denoiser
actor loaded and every env actor and planner driver started) to its last row; the table shows the start apart and
grid.csv also has the rate with it. Ray workers run at the job's nice (``RAY_worker_niceness=0``).

Own words (the rest are config words, after these defaults: env=pointmaze-medium method=fast-mctd
method.budget=100 tasks=[1,2,3,4,5] seeds=[0,1]): ``settings=[...]``, ``out=`` (must be new or empty),
``node_cpus=1``, and for the projection ``gpus=[1,2,4,8]``, ``call_ms=5`` (Ray cost per search iteration on a GPU
node), ``host_cores=16`` (cores for trees and envs). Writes ``<out>/grid.csv``, ``<out>/scaling.md`` and
``<out>/scaling.png``; prints the tables. Rows are the same in every setting when their plan fields (success,
steps, expansions, iterations, plans, first plan, trajectory, config hash, checkpoint) hash the same per episode.
"""

from __future__ import annotations

import csv
import hashlib
import json
import os
import re
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from fmctd_dist.cli import run
from fmctd_dist.config import REPO_ROOT, load_config
from fmctd_dist.errors import ConfigError, ResultsError
from fmctd_dist.evaluation.results import ResultStore

DEFAULT_WORDS = ["env=pointmaze-medium", "method=fast-mctd", "method.budget=100", "tasks=[1,2,3,4,5]", "seeds=[0,1]"]
DEFAULT_SETTINGS = ("[local:f1,local:f2,local:f4,ray:e1d1f1,ray:e2d1f2,ray:e2d2f1,ray:e4d2f2,"
                    "cluster2:e2d2f1,cluster2:e4d2f2]")
OWN = {"settings": DEFAULT_SETTINGS, "out": "runs/bench/grid-scaling", "node_cpus": "1", "gpus": "[1,2,4,8]",
       "call_ms": "5", "host_cores": "16", "one": ""}
# What a plan decides: equal across settings when every setting gives the rows a lone in-process run gives.
PLAN_FIELDS = ("success", "timed_out", "env_steps", "expansions", "iterations", "plans", "plan_status", "plan_xy",
               "traj_xy", "traj_cubes", "config_hash", "checkpoint_digest")
SETTING = re.compile(r"^(local|ray|cluster(\d+)):(?:e(\d+))?(?:d(\d+))?f(\d+)$")


@dataclass(frozen=True)
class Setting:
    """One cell of the grid: where it runs and how many actors and trees."""

    text: str
    where: str  # local | ray | cluster
    nodes: int
    env_actors: int  # local: the F episode threads
    denoisers: int  # local: 0 (one in-process denoiser)
    in_flight: int

    @property
    def name(self) -> str:
        return self.text.replace(":", "-")

    def words(self, out: Path) -> list[str]:
        """The config words of this setting (after the user's)."""
        w = [f"eval.out={out}", f"eval.run={self.name}", f"eval.in_flight={self.in_flight}", "eval.threads=1"]
        if self.where == "local":
            return w + ["runner=local"]
        return w + ["runner=ray", f"ray.env_actors={self.env_actors}", f"ray.denoiser_actors={self.denoisers}"]


def parse_setting(text: str) -> Setting:
    m = SETTING.match(text.strip())
    if not m:
        raise ConfigError(f"setting {text!r}: write WHERE:e<E>d<D>f<F> with WHERE local, ray or cluster<N> "
                          "(local: only f<F>), e.g. ray:e2d2f1")
    where = "cluster" if m[2] else m[1]
    f = int(m[5])
    if where == "local":
        if m[3] or m[4]:
            raise ConfigError(f"setting {text!r}: runner=local has one in-process denoiser and F episode threads; "
                              "write local:f<F>")
        return Setting(text.strip(), where, 1, f, 0, f)
    if not (m[3] and m[4]):
        raise ConfigError(f"setting {text!r}: a Ray setting names its env actors and denoiser actors, e.g. ray:e2d2f1")
    nodes = int(m[2]) if m[2] else 1
    e, d = int(m[3]), int(m[4])
    if min(nodes, e, d, f) < 1:
        raise ConfigError(f"setting {text!r}: nodes, actors and in_flight must be >= 1")
    return Setting(text.strip(), where, nodes, e, d, f)


def own_words(argv: list[str]) -> tuple[dict[str, str], list[str]]:
    """This bench's words with their defaults, and the user's config words."""
    split = [a.partition("=") for a in argv]
    mine = {**OWN, **{key: value for key, sep, value in split if sep and key in OWN}}
    return mine, [a for a, (key, sep, _) in zip(argv, split) if not (sep and key in OWN)]


def with_defaults(words: list[str]) -> list[str]:
    """The user's config words after each default word whose key they do not give (a key is given once)."""
    given = {w.partition("=")[0] for w in words}
    return [d for d in DEFAULT_WORDS if d.partition("=")[0] not in given] + words


def as_list(text: str) -> list[str]:
    return [x.strip() for x in text.strip("[]").split(",") if x.strip()]


# ---------------------------------------------------------------------------------------------- one setting (child)

def run_one(s: Setting, words: list[str], out: Path, node_cpus: float) -> dict[str, Any]:
    """Run the grid under one setting in this process; returns its timings (written to ``<out>/<setting>.json``)."""
    os.environ["RAY_AUTH_MODE"] = "disabled"  # a private cluster: no stale ~/.ray/auth_token can break it
    os.environ.pop("RAY_ADDRESS", None)  # never join a cluster someone else runs: the timing needs ours alone
    from fmctd_dist.denoiser.local import LocalDenoiser
    from fmctd_dist.evaluation.grid import prepare, run_local
    from fmctd_dist.families import hooks_for

    cfg = load_config(words + s.words(out))
    p = prepare(cfg, hooks_for)
    store = ResultStore(cfg.eval.out, cfg.eval.run)
    if s.where != "local":
        return run_one_on_ray(s, p, store, node_cpus)
    ready: list[float] = []  # when the in-process denoiser has its model loaded
    stamp_return(LocalDenoiser, "from_checkpoint", ready)
    t0 = time.perf_counter()
    run_local(p, store, progress=False, log=lambda line: None)
    return timings(t0, t0, ready[0], time.perf_counter(), 1, float(os.cpu_count() or 1))


def run_one_on_ray(s: Setting, p: Any, store: ResultStore, node_cpus: float) -> dict[str, Any]:
    """A Ray setting: start its cluster (local, or simulated nodes), run the grid, shut the cluster down."""
    import logging

    import ray

    import fmctd_dist.evaluation.ray_runner as rr
    from fmctd_dist.denoiser.ray_pool import DenoiserPool

    ready: list[float] = []  # when the pool has its model loaded, then when each episode pair has started
    stamp_return(DenoiserPool, "create", ready)
    make_pair = rr.episode_pair

    def ready_pair(prepared: Any, denoisers: list) -> tuple:
        """A new (env actor, planner driver) pair, returned once both have started (their info answers)."""
        pair = make_pair(prepared, denoisers)
        ray.get([a.info.remote() for a in pair])
        ready.append(time.perf_counter())
        return pair

    rr.episode_pair = ready_pair  # run_ray makes its pairs through this module global
    t_setup, cluster = time.perf_counter(), None
    if s.where == "cluster":
        from ray.cluster_utils import Cluster

        rr.local_cluster_env()  # the nodes' workers at the job's nice, as every cluster we start
        cluster = Cluster(initialize_head=True, connect=False,
                          head_node_args={"num_cpus": node_cpus, "include_dashboard": False})
        for _ in range(s.nodes - 1):
            cluster.add_node(num_cpus=node_cpus)
        cluster.wait_for_nodes()
        ray.init(address=cluster.address, logging_level=logging.ERROR, log_to_driver=False)
    else:
        rr.connect("local")
    try:
        nodes, cpus = len([n for n in ray.nodes() if n["Alive"]]), ray.cluster_resources().get("CPU", 0.0)
        t0 = time.perf_counter()
        rr.run_ray(p, store, progress=False, log=lambda line: None)
        t_end = time.perf_counter()
    finally:
        ray.shutdown()
        if cluster is not None:
            cluster.shutdown()
    pairs = min(s.env_actors, len(store.rows(p.cfg.method.name, p.cfg.env.name)))
    return timings(t_setup, t0, ready[pairs], t_end, nodes, cpus)  # the pool, then the first pairs (no re-runs)


def stamp_return(cls: Any, name: str, stamps: list[float]) -> None:
    """Wrap the classmethod ``cls.name`` (in this process only) so that the time it returns is recorded."""
    inner = getattr(cls, name).__func__

    def wrapped(klass: Any, *a: Any, **kw: Any) -> Any:
        got = inner(klass, *a, **kw)
        stamps.append(time.perf_counter())
        return got

    setattr(cls, name, classmethod(wrapped))


def timings(t_setup: float, t0: float, t_ready: float, t_end: float, nodes: int, cpus: float) -> dict[str, Any]:
    """cluster_s: starting the cluster; start_s: the runner's call until its model is loaded (Ray: the pool's actors,
    then every env actor and planner driver started); episodes_s: the rest of the call; wall_s: the whole call."""
    return {"cluster_s": t0 - t_setup, "start_s": t_ready - t0, "episodes_s": t_end - t_ready, "wall_s": t_end - t0,
            "nodes": nodes, "cluster_cpus": cpus}


def run_child(s: Setting, user_words: list[str], out: Path, node_cpus: str) -> dict[str, Any]:
    """One setting in a fresh process (its own Ray connection), importing this checkout's package (so do its Ray
    workers); its output goes to ``<out>/<setting>.log``."""
    path = os.pathsep.join(x for x in (str(REPO_ROOT), os.environ.get("PYTHONPATH", "")) if x)
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": path}
    cmd = [sys.executable, str(Path(__file__).resolve()), f"one={s.text}", f"out={out}", f"node_cpus={node_cpus}",
           *user_words]
    log = out / f"{s.name}.log"
    with log.open("w") as f:
        done = subprocess.run(cmd, env=env, stdout=f, stderr=subprocess.STDOUT)
    if done.returncode != 0:
        raise ResultsError(f"setting {s.text} failed (exit {done.returncode}); its output: {log}\n"
                           + "\n".join(log.read_text().splitlines()[-15:]))
    return json.loads((out / f"{s.name}.json").read_text())


# ---------------------------------------------------------------------------------------------- rows and table

def row_digest(row: dict[str, Any]) -> str:
    """sha256 of what the plan decided in this episode (PLAN_FIELDS present in the row)."""
    blob = json.dumps([[k, row[k]] for k in PLAN_FIELDS if k in row], default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def digests(out: Path, s: Setting, method: str, env: str) -> dict[tuple[int, int], str]:
    return {(int(r["task"]), int(r["seed"])): row_digest(r) for r in ResultStore(out, s.name).rows(method, env)}


def summarise(out: Path, settings: list[Setting], times: list[dict], method: str, env: str,
              expected: int) -> list[dict[str, Any]]:
    """One record per setting: episodes/h, against the baseline (the first), rows identical to the baseline's."""
    base = digests(out, settings[0], method, env)
    recs = []
    for s, t in zip(settings, times):
        got = digests(out, s, method, env)
        rows = ResultStore(out, s.name).rows(method, env)
        same = "yes" if got == base and len(got) == expected else (
            f"no: {len(got)} of {expected} rows" if len(got) != expected else
            f"no: {sum(got[k] != base.get(k) for k in got)} of {len(got)} differ")
        eph = 3600.0 * len(rows) / t["episodes_s"]
        recs.append({"setting": s.text, "runner": "local" if s.where == "local" else "ray",
                     "cluster": {"local": "none", "ray": "local ray.init"}.get(
                         s.where, f"simulated, {t['nodes']} nodes"),
                     "nodes": t["nodes"], "cluster_cpus": t["cluster_cpus"], "env_actors": s.env_actors,
                     "denoiser_actors": s.denoisers, "in_flight": s.in_flight, "episodes": len(rows),
                     "successes": sum(bool(r["success"]) for r in rows),
                     **{k: round(t[k], 2) for k in ("cluster_s", "start_s", "episodes_s", "wall_s")},
                     "episodes_per_hour": round(eph, 1), "vs_baseline": 0.0,
                     "episodes_per_hour_with_start": round(3600.0 * len(rows) / t["wall_s"], 1),
                     "rows_identical": same})
    for r in recs:
        r["vs_baseline"] = round(r["episodes_per_hour"] / recs[0]["episodes_per_hour"], 3)
    return recs


def grid_table(recs: list[dict[str, Any]]) -> str:
    lines = ["| setting | runner | cluster | env actors | denoiser actors | in flight | episodes (solved) | "
             "start (s) | episodes (s) | episodes / h | vs baseline | rows identical |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in recs:
        local = r["runner"] == "local"
        env_a = f"{r['env_actors']} thread{'s' if r['env_actors'] > 1 else ''}" if local else r["env_actors"]
        den = "1 in-process" if local else r["denoiser_actors"]
        where = f"one process, {r['cluster_cpus']:g} cores" if local else f"{r['cluster']}, {r['cluster_cpus']:g} CPUs"
        lines.append(f"| `{r['setting']}` | {r['runner']} | {where} | {env_a} | "
                     f"{den} | {r['in_flight']} | {r['episodes']} ({r['successes']}) | {r['start_s']:.1f} | "
                     f"{r['episodes_s']:.1f} | "
                     f"{r['episodes_per_hour']:,.0f} | {r['vs_baseline']:.2f}x | {r['rows_identical']} |")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------- projection on N GPUs

# Guided DDIM job-transitions per second at 11 tokens against the batch (jobs in one call), fp32, one thread:
# docs/results.md "Why our ratios are smaller" (H200) and issue 55 (the 2-core Intel Xeon: batch 1/4/8/25).
GPU_RATE = {1: 176.0, 25: 4739.0, 200: 38049.0, 1000: 179165.0}
CPU_RATE = {1: 123.0, 4: 325.0, 8: 429.0, 25: 706.0}


def rate(table: dict[int, float], batch: float) -> float:
    """Job-transitions per second at ``batch`` jobs per call: piecewise linear, flat beyond the last batch."""
    xs = sorted(table)
    return float(np.interp(batch, xs, [table[x] for x in xs]))


@dataclass(frozen=True)
class GridModel:
    """One lone in-process episode, measured: host seconds (tree + env), denoiser model seconds, iterations; and the
    job shapes: K jobs per call, M the CPU micro-batch the model seconds were measured at."""

    host_s: float
    model_s: float
    iterations: float
    jobs_per_call: int
    cpu_micro_batch: int


def grid_model(rows: list[dict[str, Any]], jobs_per_call: int, micro_batch: int) -> GridModel:
    host = [r["episode_time_s"] - r["denoise_time_s"] for r in rows]
    return GridModel(float(np.mean(host)), float(np.mean([r["denoise_time_s"] for r in rows])),
                     float(np.mean([r["iterations"] for r in rows])), jobs_per_call, micro_batch)


# Hook: per-episode GPU denoiser seconds at F trees per actor, from a better model than the rate table.
# TODO(issue 55 item 3): jobs/bench/replay.py projects each recorded call of a plan's trace onto a GPU; once it
# exposes that per episode, pass ``gpu_model_s=lambda model, f: <its seconds for F pooled trees>`` to projected_eph.
GpuModelS = Callable[[GridModel, int], float]


def rate_gpu_model_s(m: GridModel, f: int) -> float:
    """Seconds one tree waits on the GPU per episode when F trees share an actor: its calls (the episode's
    job-transitions, model seconds x the CPU's rate at its micro-batch, over K jobs per call), each the time of
    one GPU call of F x K jobs (never less than one of K jobs: the measured rates are noisy at small batches)."""
    k, calls = m.jobs_per_call, m.model_s * rate(CPU_RATE, m.cpu_micro_batch) / m.jobs_per_call
    return calls * max(f * k / rate(GPU_RATE, f * k), k / rate(GPU_RATE, k))


def projected_eph(m: GridModel, n_gpus: int, f: int, call_s: float, host_cores: float,
                  gpu_model_s: GpuModelS = rate_gpu_model_s) -> float:
    """Episodes per hour with N denoiser actors on N GPUs, F trees each (docs/scaling.md, "Projection on N GPUs"):
    3600 N F / T with T = host + iterations x call cost + GPU wait, capped by the host cores' tree and env work."""
    t = m.host_s + m.iterations * call_s + gpu_model_s(m, f)
    return min(3600.0 * n_gpus * f / t, 3600.0 * host_cores / m.host_s)


def projection_table(m: GridModel, gpus: list[int], flights: list[int], call_s: float,
                     host_cores: float) -> tuple[str, dict[int, list[float]]]:
    curves = {f: [projected_eph(m, n, f, call_s, host_cores) for n in gpus] for f in flights}
    lines = ["| trees per actor (in flight) | " + " | ".join(f"{n} GPU{'s' if n > 1 else ''}" for n in gpus) + " |",
             "|---|" + "---|" * len(gpus)]
    lines += [f"| {f} | " + " | ".join(f"{v:,.0f}" for v in curves[f]) + " |" for f in flights]
    return "\n".join(lines), curves


# ---------------------------------------------------------------------------------------------- plot

def plot(recs: list[dict[str, Any]], gpus: list[int], curves: dict[int, list[float]], title: str, path: Path) -> bool:
    """Measured episodes/h per setting (left) and the projection on N GPUs (right); False without matplotlib."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 0.45 * len(recs) + 2.5), gridspec_kw={"width_ratios": [3, 2]})
    colour = {"none": "tab:blue", "local ray.init": "tab:orange"}
    y = np.arange(len(recs))[::-1]
    for yi, r in zip(y, recs):
        ax.barh(yi, r["episodes_per_hour"], color=colour.get(r["cluster"], "tab:green"),
                hatch="" if r["rows_identical"] == "yes" else "xx", edgecolor="black", linewidth=0.5)
        ax.text(r["episodes_per_hour"], yi, f" {r['vs_baseline']:.2f}x", va="center", fontsize=8)
    ax.axvline(recs[0]["episodes_per_hour"], color="grey", linestyle=":", linewidth=1)
    ax.set_yticks(y, [r["setting"] for r in recs], fontsize=8)
    ax.set_xlabel("episodes per hour (measured, start excluded)")
    ax.set_xlim(0, 1.18 * max(r["episodes_per_hour"] for r in recs))
    handles = [plt.Rectangle((0, 0), 1, 1, color=c) for c in ("tab:blue", "tab:orange", "tab:green")]
    fig.legend(handles, ["runner=local", "ray, local ray.init", "ray, simulated nodes"], fontsize=8, ncol=3,
               loc="lower left")
    ax.set_title("this machine; hatched = rows differ from the baseline (top)", fontsize=9)
    for f, ys in curves.items():
        bx.plot(gpus, ys, marker="o", label=f"{f} tree{'s' if f > 1 else ''} per actor")
    bx.set_xscale("log", base=2)
    bx.set_yscale("log")
    bx.set_xticks(gpus, [str(n) for n in gpus])
    bx.set_xlabel("GPUs (one denoiser actor each)")
    bx.set_ylabel("episodes per hour (projected)")
    bx.set_title("projection (model, not a measurement)", fontsize=9)
    bx.legend(fontsize=8)
    bx.grid(True, which="both", alpha=0.3)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout(rect=(0, 0.35 / fig.get_figheight(), 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


# ---------------------------------------------------------------------------------------------- main

def main(argv: list[str]) -> int:
    mine, rest = own_words(argv)
    words, out = with_defaults(rest), Path(mine["out"])
    if mine["one"]:
        t = run_one(parse_setting(mine["one"]), words, out, float(mine["node_cpus"]))
        (out / f"{parse_setting(mine['one']).name}.json").write_text(json.dumps(t))
        return 0
    settings = [parse_setting(x) for x in as_list(mine["settings"])]
    if len({s.name for s in settings}) != len(settings):
        raise ConfigError(f"settings={mine['settings']} names a setting twice")
    if out.exists() and any(out.iterdir()):  # a timing needs every setting run now, not resumed
        raise ResultsError(f"{out} is not empty; point out= at a new folder")
    out.mkdir(parents=True, exist_ok=True)
    cfg = load_config(words)
    gpus = [int(x) for x in as_list(mine["gpus"])]
    t_start = time.perf_counter()
    times = []
    for s in settings:
        times.append(run_child(s, rest, out, mine["node_cpus"]))
        print(f"{s.text}: " + ", ".join(f"{k} {v:.1f}" for k, v in times[-1].items() if k.endswith("_s")),
              flush=True)
    expected = len(cfg.eval.tasks) * len(cfg.eval.seeds)
    recs = summarise(out, settings, times, cfg.method.name, cfg.env.name, expected)
    with (out / "grid.csv").open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(recs[0]))
        w.writeheader()
        w.writerows(recs)

    lone = next((s for s in settings if s.where == "local" and s.in_flight == 1), settings[0])
    model = grid_model(ResultStore(out, lone.name).rows(cfg.method.name, cfg.env.name), cfg.method.parallel,
                       cfg.ray.micro_batch)
    flights = sorted({1, *(s.in_flight for s in settings)})
    proj, curves = projection_table(model, gpus, flights, float(mine["call_ms"]) / 1000, float(mine["host_cores"]))
    cmd = "python jobs/bench/bench_grid_scaling.py " + " ".join(argv)
    head = (f"{cfg.method.name} on {cfg.env.name}, K={cfg.method.parallel}, budget={cfg.method.budget}, "
            f"M={cfg.ray.micro_batch}, {expected} episodes per setting")
    text = "\n".join([
        f"`{cmd}`", "", head + f"; {os.cpu_count()} cores; sweep {time.perf_counter() - t_start:.0f} s", "",
        grid_table(recs), "",
        f"Projection on N GPUs (model, docs/scaling.md; from `{lone.text}`: host {model.host_s:.2f} s, model "
        f"{model.model_s:.2f} s, {model.iterations:.1f} iterations per episode; Ray {mine['call_ms']} ms per "
        f"iteration, {mine['host_cores']} host cores), episodes per hour:", "", proj, ""])
    (out / "scaling.md").write_text(text)
    drew = plot(recs, gpus, curves, head, out / "scaling.png")
    print(text + ("" if drew else "\n(no matplotlib: no plot)"))
    return 0 if all(r["rows_identical"] == "yes" for r in recs) else 1


if __name__ == "__main__":
    run(main)
