"""The evaluation grid on Ray (docs/design.md §8): denoiser pool, one PlannerDriver per EnvActor.

    job process: prepare() (all checks) -> ray.init -> DenoiserPool (N DenoiserActors)
                 -> E EnvActors, each with its own PlannerDriver -> missing (task, seed) keys
                 fanned out over the EnvActors -> each finished row written here, at once
    EnvActor:    env + controller (run_episode); its planner is a proxy that asks the driver
    PlannerDriver: owns the tree of each plan call (selection/backup are serial, here) and
                 shards every expansion/simulation batch over the shared denoiser actors

Only the job process writes files and draws progress bars; actors return rows and timings, and
errors raised on purpose inside actors (FmctdError) reach the user as themselves. Faults (docs/design.md
§9): a dead denoiser actor's micro-batches are re-routed (RayDenoiser); an episode whose actors die or
hang past ``ray.episode_timeout_s`` is re-run on a new pair (:func:`run_ray`). A stopped job keeps the
rows it wrote; rerunning it runs only the missing keys.

Python entry point (joins a running cluster, or ``ray.init()`` first yourself)::

    import ray
    ray.init()
    from fmctd_dist.evaluation.ray_runner import evaluate
    from fmctd_dist.families import hooks_for
    rows = evaluate(["method=fast-mctd", "tasks=[1]", "seeds=[0]"], hooks_for)
"""

from __future__ import annotations

import dataclasses
import logging
import os
import time
from typing import Any, Callable

import numpy as np
import ray
from ray.exceptions import (
    LocalRayletDiedError, NodeDiedError, ObjectLostError, OwnerDiedError, RayActorError, RayTaskError,
    WorkerCrashedError,
)
from tqdm.auto import tqdm

from fmctd_dist.artifacts import first_line
from fmctd_dist.config import Config, load_config
from fmctd_dist.denoiser.ray_pool import DenoiserPool, RayDenoiser, auto_actors, kill_quietly, unwrap_ray_error, where
from fmctd_dist.errors import ConfigError, DeviceError
from fmctd_dist.evaluation.grid import Prepared, grid, missing, prepare, provenance
from fmctd_dist.evaluation.results import ResultStore, describe
from fmctd_dist.family import HooksFor
from fmctd_dist.planners.base import PlanOutput

__all__ = ["PlannerDriver", "EnvActor", "run_ray", "evaluate", "connect", "check_ray_config"]


def _one_thread() -> None:
    """Drivers and env actors do light serial work; leave the cores to the denoisers."""
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:  # pragma: no cover
        pass


@ray.remote(num_cpus=0)
class PlannerDriver:
    """Owns the search tree of each plan call; its denoiser is a RayDenoiser over the pool."""

    def __init__(self, prepared: Prepared, actors: list):
        from fmctd_dist.diffusion.checkpoint import normaliser_from_manifest, read_manifest
        from fmctd_dist.planners import make_planner

        _one_thread()
        cfg = prepared.cfg
        self.denoiser = RayDenoiser.from_config(actors, cfg)
        normaliser = normaliser_from_manifest(read_manifest(prepared.checkpoint))
        self.planner = make_planner(cfg, self.denoiser, normaliser, prepared.plan_rules(cfg),
                                    cfg.eval.episode_time_limit)

    def plan(self, start: np.ndarray, goal: np.ndarray, seed: int) -> PlanOutput:
        return self.planner.plan(np.array(start), np.array(goal), seed)

    def last_tree(self):
        """The SearchResult.tree of the last plan (tests compare payloads bitwise)."""
        r = getattr(self.planner, "last_result", None)
        return None if r is None else r.tree

    def info(self) -> dict[str, Any]:
        return where()


class _DriverPlanner:
    """Planner protocol for run_episode: every plan() is one call to the episode's PlannerDriver."""

    def __init__(self, driver):
        self.driver = driver

    def plan(self, start: np.ndarray, goal: np.ndarray, seed: int) -> PlanOutput:
        try:
            return ray.get(self.driver.plan.remote(np.array(start), np.array(goal), seed))
        except RayTaskError as e:
            raise unwrap_ray_error(e) from None


@ray.remote(num_cpus=0)
class EnvActor:
    """Runs whole episodes (the env family's env + controller) and returns their rows; prints nothing."""

    def __init__(self, prepared: Prepared, driver):
        _one_thread()
        self.cfg, self.prepared = prepared.cfg, prepared
        self.episodes = prepared.episodes(self.cfg)  # the family's env + controller
        self.planner = _DriverPlanner(driver)

    def run(self, task: int, seed: int) -> dict[str, Any]:
        from fmctd_dist.evaluation.grid import same_policy

        same_policy(self.prepared, self.episodes)  # an error of the task (not a lost actor): the run stops
        return self.episodes.run(self.planner, task, seed)

    def info(self) -> dict[str, Any]:
        return where()


# What a dead actor, worker process or node looks like to its caller (not an error of the episode).
LOST = (RayActorError, NodeDiedError, OwnerDiedError, ObjectLostError, WorkerCrashedError, LocalRayletDiedError)


def actor_lost(e: BaseException) -> bool:
    """True when ``e`` (or what it wraps: an env actor sees its driver die) says an actor or node is gone."""
    if isinstance(e, RayTaskError):
        cause = getattr(e, "cause", None)
        return isinstance(cause, BaseException) and actor_lost(cause)
    return isinstance(e, LOST)


def episode_pair(p: Prepared, denoisers: list) -> tuple:
    """A new (EnvActor, PlannerDriver) for one episode at a time, spread over the cluster's nodes.

    No restarts of their own: when one dies its episode is re-run on a new pair (run_ray), which
    also covers a driver whose env actor died mid-plan.
    """
    opts = {"scheduling_strategy": "SPREAD", "max_restarts": 0}
    driver = PlannerDriver.options(**opts).remote(p, denoisers)
    return EnvActor.options(**opts).remote(p, driver), driver


def check_ray_config(p: Prepared) -> None:
    """Checks that need no cluster (run before ray.init)."""
    r = p.cfg.ray
    if p.device.startswith("cuda") and r.num_gpus <= 0:
        raise DeviceError(f"device={p.cfg.device!r} (resolved {p.device}) but ray.num_gpus={r.num_gpus}: the denoiser "
                          "actors would see no GPU; set ray.num_gpus=1 (one GPU per actor) or device=cpu")
    if r.num_cpus < 0:
        raise ConfigError(f"ray.num_cpus={r.num_cpus} must be >= 0")


def pool_size(p: Prepared) -> tuple[int, int]:
    """(denoiser actors, env actors) for the connected cluster: ``ray.denoiser_actors=0`` is :func:`auto_actors`,
    ``ray.env_actors=0`` runs ``eval.in_flight`` episodes at once per denoiser actor; explicit values win."""
    r = p.cfg.ray
    n = r.denoiser_actors or auto_actors(r)
    return n, r.env_actors or n * p.cfg.eval.in_flight


def check_cluster(p: Prepared, n_actors: int) -> None:
    """After ray.init, before any actor: the cluster must hold what the pool asks for."""
    r, res = p.cfg.ray, ray.cluster_resources()
    for kind, each, fix in (("GPU", r.num_gpus, "lower ray.denoiser_actors or add GPU nodes"),
                            ("CPU", r.num_cpus, "lower ray.denoiser_actors or ray.num_cpus")):
        need, have = n_actors * each, res.get(kind, 0.0)
        if need > have:
            raise DeviceError(f"{n_actors} denoiser actor(s) x ray.num_{kind.lower()}s={each} need {need:g} {kind}(s) "
                              f"but the Ray cluster has {have:g}; {fix}")


# Environment of a Ray cluster this process starts itself. Ray runs its workers at nice 15, so on
# a shared machine a denoiser actor gets a few percent of a core whenever two nice-0 jobs run: one
# Fast-MCTD plan took 162 s on Ray against 3.3 s in process (docs/results.md section 11.5). A cluster
# we start runs its workers at the driver's priority; a cluster we join keeps its own setting.
LOCAL_CLUSTER_ENV = {"RAY_worker_niceness": "0"}


def local_cluster_env() -> None:
    """Set LOCAL_CLUSTER_ENV before starting a local cluster (a value the user exported wins)."""
    for key, value in LOCAL_CLUSTER_ENV.items():
        os.environ.setdefault(key, value)


def connect(address: str = "") -> bool:
    """Join ``address``, else a running cluster (RAY_ADDRESS / ``ray job submit`` / ``ray start``),
    else start a local one; ``address="local"`` always starts a private one (workers at nice 0, as
    every cluster we start). Returns True when this call started Ray (the caller shuts it down)."""
    if ray.is_initialized():
        return False
    quiet = {"logging_level": logging.ERROR, "log_to_driver": False}
    if address == "local":  # a fresh private cluster, even beside a running one: ours, so nice 0 and shut down after
        local_cluster_env()
        ray.init(address="local", include_dashboard=False, **quiet)
        return True
    if address or os.environ.get("RAY_ADDRESS"):
        ray.init(address=address or None, **quiet)
        return False
    try:
        ray.init(address="auto", **quiet)
        return False
    except ConnectionError:
        local_cluster_env()
        ray.init(include_dashboard=False, **quiet)
        return True


def run_ray(p: Prepared, store: ResultStore, progress: bool = True,
            log: Callable[[str], None] = print) -> list[dict[str, Any]]:
    """All missing episodes of the grid on Ray; rows written here as they finish."""
    cfg = p.cfg
    todo = missing(p, store, log)
    if not todo:
        return []
    check_ray_config(p)
    started = connect(cfg.ray.address)
    actors: list = []
    pool = None
    try:
        n_denoisers, n_env_actors = pool_size(p)
        check_cluster(p, n_denoisers)
        pool = DenoiserPool.create(p, n_denoisers)
        log(f"{len(pool.actors)} denoiser actor(s): " + "; ".join(
            f"pid {i['pid']} device {i['device']} gpu_ids {i['gpu_ids']} cuda devices {i['cuda_device_count']}"
            for i in pool.infos))
        for warning in dict.fromkeys(i.get("warning") for i in pool.infos if i.get("warning")):
            log(warning)
        n_envs = min(n_env_actors, len(todo))
        pairs = [episode_pair(p, pool.actors) for _ in range(n_envs)]
        actors = [a for pair in pairs for a in pair]
        rows: list[dict[str, Any]] = []
        queue, free = list(todo), list(pairs)
        pending: dict = {}  # ref -> (pair, key, deadline)
        reruns: dict[tuple[int, int], int] = {}  # episodes re-run because an actor died or timed out
        bar = tqdm(total=len(todo), desc=f"{cfg.method.name} {cfg.env.name} (ray)", unit="ep", disable=not progress)
        say = bar.write if progress else log

        def rerun(pair: tuple, key: tuple[int, int], why: str) -> None:
            """Its env actor or planner driver died (killed, OOM, node gone) or hung: the half-run episode
            left no row, so run it again from the start on a new pair, at most ray.max_restarts times (counted
            in the row's ``retries``). A plan is a pure function of (config, checkpoint, seed): the rerun's
            row is the one a fault-free run writes."""
            n = reruns[key] = reruns.get(key, 0) + 1
            if n > cfg.ray.max_restarts:
                raise DeviceError(
                    f"task {key[0]} seed {key[1]}: {why}, {n} time(s); ray.max_restarts={cfg.ray.max_restarts} "
                    "re-runs are allowed per episode; check the nodes (`ray status`, `ray logs`), or raise "
                    "ray.episode_timeout_s if the episodes are just slow, and rerun to resume (finished "
                    "episodes are kept)") from None
            say(f"task {key[0]} seed {key[1]}: {why}; re-running it ({n}/{cfg.ray.max_restarts})")
            kill_quietly(pair)
            pair = episode_pair(p, pool.actors)
            actors.extend(pair)
            queue.insert(0, key)
            free.append(pair)

        while queue or pending:
            while queue and free:
                pair, key = free.pop(), queue.pop(0)
                pending[pair[0].run.remote(*key)] = (pair, key, time.monotonic() + cfg.ray.episode_timeout_s)
            first = min(pending, key=lambda ref: pending[ref][2])
            ready, _ = ray.wait(list(pending), num_returns=1, timeout=max(0.0, pending[first][2] - time.monotonic()))
            if not ready:  # alive but silent past its deadline: a hung env actor or driver
                pair, key, _ = pending.pop(first)
                rerun(pair, key, f"its episode ran past ray.episode_timeout_s={cfg.ray.episode_timeout_s:g}")
                continue
            pair, key, _ = pending.pop(ready[0])
            try:
                row = ray.get(ready[0])
            except (RayTaskError, RayActorError) as e:
                if not actor_lost(e):
                    raise unwrap_ray_error(e) from None
                rerun(pair, key, f"an actor of its episode died ({first_line(e)})")
                continue
            row = {**row, **provenance(p, len(pool.actors))}
            row["retries"] = int(row.get("retries", 0)) + reruns.get(key, 0)
            store.write(row)
            rows.append(row)
            free.append(pair)
            bar.update(1)
            bar.set_postfix(success=f"{sum(r['success'] for r in rows)}/{len(rows)}")
            say(describe(row))
        bar.close()
        return rows
    finally:
        kill_quietly(actors)
        if pool is not None:
            pool.shutdown()
        if started:
            ray.shutdown()


def evaluate(overrides: list[str] | Config, hooks_for: HooksFor, progress: bool = True) -> list[dict[str, Any]]:
    """Evaluate on Ray (whatever ``eval.runner`` says; a cluster as :func:`connect` finds one) and return one row
    per (task, seed) of the grid, resumed rows included. ``overrides``: the words of ``jobs/eval.py`` or a
    Config; ``hooks_for``: env name -> its family's hook module (``fmctd_dist.families.hooks_for``)."""
    cfg = overrides if isinstance(overrides, Config) else load_config(list(overrides))
    cfg = dataclasses.replace(cfg, eval=dataclasses.replace(cfg.eval, runner="ray"))
    p = prepare(cfg, hooks_for)
    store = ResultStore(cfg.eval.out, cfg.eval.run)
    run_ray(p, store, progress=progress)
    keys = set(grid(cfg))
    return [r for r in store.rows(cfg.method.name, cfg.env.name) if (r["task"], r["seed"]) in keys]
