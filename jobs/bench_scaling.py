"""Scaling of the Ray denoiser pool: throughput and Fast-MCTD planning time vs denoiser actors.

    python jobs/bench_scaling.py                                   # shipped pointmaze-medium-h5, 1..nproc actors
    python jobs/bench_scaling.py --actors 1,2 --repeats 3 checkpoint=/path/to/ckpt <config overrides...>

Side by side in one run: LocalDenoiser (no Ray) and a DenoiserPool of N actors for N in
--actors. Reports (1) denoiser throughput, jobs/s, on one fixed batch of --batch expansion
jobs (segment_transitions DDIM transitions each); (2) planning time of one Fast-MCTD plan
(task 1 start -> goal, fixed seed), its search iterations, the share of planning time spent
inside denoiser calls (wall time of the calls, seen by the tree owner), and the Ray overhead
per search iteration = (wall time in denoiser calls - model time / N) / iterations, i.e.
what the calls cost beyond the model work when the N actors split it evenly. All plans
are checked to be bitwise identical to the in-process one. Prints a Markdown table.
Actors started here share this machine's cores (and its one device, if any). A whole grid of episodes against env
actors x denoiser actors x eval.in_flight, locally and on simulated nodes: jobs/bench/bench_grid_scaling.py.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np
import torch

from fmctd_dist.config import load_config
from fmctd_dist.denoiser.local import LocalDenoiser
from fmctd_dist.denoiser.protocol import DenoiseBatch, DenoiseResult
from fmctd_dist.diffusion.checkpoint import normaliser_from_manifest, read_manifest
from fmctd_dist.diffusion.schedule import PyramidSchedule
from fmctd_dist.families.maze.geometry import maze_geometry
from fmctd_dist.evaluation.grid import prepare
from fmctd_dist.families import hooks_for
from fmctd_dist.planners import make_planner


class Timed:
    """Wraps a Denoiser; adds up the wall time of its calls as the tree owner sees them."""

    def __init__(self, inner):
        self.inner, self.wall_s, self.model_s, self.calls, self.retries = inner, 0.0, 0.0, 0, 0

    def denoise(self, batch: DenoiseBatch) -> DenoiseResult:
        t0 = time.perf_counter()
        res = self.inner.denoise(batch)
        self.wall_s += time.perf_counter() - t0
        self.model_s += res.denoise_time_s
        self.calls += 1
        self.retries += res.retries
        return res


def fixed_batch(cfg, n: int) -> DenoiseBatch:
    """n expansion jobs at tree depth 1 (one segment of DDIM transitions each), fixed noise."""
    sched = PyramidSchedule(cfg.plan_tokens, cfg.diffusion.levels, cfg.method.segment_transitions,
                            cfg.method.sim_skip)
    rows = sched.expansion(1)
    rng = np.random.default_rng(0)
    x = rng.standard_normal((n, cfg.n_tokens, cfg.token_dim)).astype(np.float32)
    x[:, 0] = 0.0
    return DenoiseBatch(x, np.broadcast_to(rows, (n, *rows.shape)).copy(), np.full(n, 1.0, np.float32),
                        np.zeros((n, 2), np.float32), np.ones((n, 2), np.float32))


def throughput(denoiser, batch: DenoiseBatch, repeats: int) -> float:
    denoiser.denoise(batch)  # warm-up
    t0 = time.perf_counter()
    for _ in range(repeats):
        denoiser.denoise(batch)
    return repeats * batch.size / (time.perf_counter() - t0)


def plan_stats(p, denoiser, repeats: int, n_actors: int = 1) -> dict:
    """Median plan time; shares of it in denoiser calls and in model work (summed over actors);
    overhead per iteration = (wall in calls - model time / n_actors) / iterations (even shards)."""
    cfg = p.cfg
    task = maze_geometry(cfg.env.name).tasks[0]
    timed = Timed(denoiser)
    planner = make_planner(cfg, timed, normaliser_from_manifest(read_manifest(p.checkpoint)), p.plan_rules(cfg))
    planner.plan(task.init_xy, task.goal_xy, 0)  # warm-up
    timed.wall_s = timed.model_s = 0.0
    times, out = [], None
    for _ in range(repeats):
        out = planner.plan(task.init_xy, task.goal_xy, 0)
        times.append(out.plan_time_s)
    plan_s = float(np.median(times))
    return {"plan_s": plan_s, "iterations": out.iterations, "expansions": out.expansions,
            "in_calls": timed.wall_s / sum(times), "model_share": timed.model_s / sum(times),
            "overhead_s": (timed.wall_s - timed.model_s / n_actors) / (repeats * max(out.iterations, 1)),
            "waypoints": out.waypoints, "retries": timed.retries}


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--actors", default="", help="comma list of pool sizes (default 1..os.cpu_count())")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--batch", type=int, default=0, help="jobs in the throughput batch (default method.parallel)")
    args, overrides = ap.parse_known_args(argv)
    cfg = load_config(overrides)
    p = prepare(cfg, hooks_for)
    cores = os.cpu_count() or 1
    actors = [int(a) for a in args.actors.split(",")] if args.actors else list(range(1, cores + 1))
    threads = max(1, int(cfg.ray.num_cpus))
    torch.set_num_threads(threads)
    batch = fixed_batch(cfg, args.batch or cfg.method.parallel)

    import ray

    from fmctd_dist.denoiser.ray_pool import DenoiserPool
    from fmctd_dist.evaluation.ray_runner import check_ray_config, connect

    local = LocalDenoiser.from_checkpoint(p.checkpoint, cfg, expect_digest=p.checkpoint_digest, guide_map=p.guide_map)
    rows = [("in-process (no Ray)", throughput(local, batch, args.repeats), plan_stats(p, local, args.repeats))]
    check_ray_config(p)
    started = connect(cfg.ray.address)
    try:
        for n in actors:
            pool = DenoiserPool.create(p, n)
            try:
                den = pool.denoiser()
                rows.append((f"Ray, {n} actor{'s' if n > 1 else ''}", throughput(den, batch, args.repeats),
                             plan_stats(p, den, args.repeats, n)))
                shared = "same node" if len({i["node_id"] for i in pool.infos}) == 1 else "several nodes"
                devices = sorted({i["device"] for i in pool.infos})
            finally:
                pool.shutdown()
                time.sleep(1.0)  # let the cluster release the actors' CPUs before the next pool
        res = ray.cluster_resources()
    finally:
        if started:
            ray.shutdown()

    base = rows[0][2]
    print(f"`python jobs/bench_scaling.py {' '.join(argv)}`")
    print(f"method={cfg.method.name} K={cfg.method.parallel} budget={cfg.method.budget} jump={cfg.jump} "
          f"M={cfg.ray.micro_batch} checkpoint={p.checkpoint.name} ({p.checkpoint_digest}); throughput batch "
          f"{batch.size} jobs x {batch.levels.shape[1] - 1} transitions; {cores} cores, torch threads per "
          f"denoiser {threads}; cluster {res.get('CPU', 0):g} CPU / {res.get('GPU', 0):g} GPU; actors on {shared}, "
          f"device {'/'.join(devices)}: {'they share the cores' if 'cpu' in devices else 'one device per actor'}")
    print()
    print("| denoiser | jobs/s | vs in-process | plan time (s) | vs in-process | iterations | in denoiser calls | "
          "model time (all actors) / plan time | call overhead / iteration (ms) | same plan |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, jps, st in rows:
        same = np.array_equal(st["waypoints"], base["waypoints"])
        print(f"| {name} | {jps:,.1f} | {jps / rows[0][1]:.2f}x | {st['plan_s']:.3f} | "
              f"{base['plan_s'] / st['plan_s']:.2f}x | {st['iterations']} | {100 * st['in_calls']:.0f}% | "
              f"{100 * st['model_share']:.0f}% | {1000 * st['overhead_s']:.1f} | {'yes' if same else 'NO'} |")
    serial = 1.0 - base["in_calls"]
    print()
    print(f"serial share of planning (outside denoiser calls, in-process): {100 * serial:.1f}%; Amdahl bound "
          "for N actors on N devices: " + ", ".join(f"N={n}: {1 / (serial + (1 - serial) / n):.2f}x"
                                                      for n in (2, 4, 8)) + f" (max {1 / serial:.1f}x)")


if __name__ == "__main__":
    from fmctd_dist.errors import FmctdError

    try:
        main(sys.argv[1:])
    except FmctdError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
