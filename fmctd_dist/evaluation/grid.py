"""The evaluation grid (tasks x seeds) for one (method, env): validate, resume, run, record.

``prepare`` does every check a user can fail in the job process, before any actor or episode starts; the
runners then only skip keys that already have a row and write one Parquet file per finished episode.
:class:`Prepared` carries the env family's hook functions (``hooks_for``), which pickle by reference.
"""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from tqdm.auto import tqdm

from fmctd_dist.config import Config, git_sha
from fmctd_dist.denoiser.runtime import check_compile
from fmctd_dist.device import resolve_device, set_threads
from fmctd_dist.diffusion.checkpoint import read_manifest, verify_checkpoint
from fmctd_dist.errors import CheckpointError, ResultsError
from fmctd_dist.evaluation.identity import config_hash, differences, identity_columns
from fmctd_dist.evaluation.results import ResultStore, describe
from fmctd_dist.family import Episodes, HooksFor, PlanRules


@dataclass(frozen=True)
class Prepared:
    """Everything validated up front; small and picklable so it can be shipped to actors."""

    cfg: Config
    checkpoint: Path
    checkpoint_digest: str
    device: str
    config_hash: str
    git_sha: str
    policy_digest: str = ""  # the robot's low-level policy (ant, arm); "" when it has none (PD)
    episodes: Callable[[Config], Episodes] | None = None  # the family's hooks (FamilyHooks), as functions
    plan_rules: Callable[[Config], PlanRules] | None = None
    guide_map: Callable[[Config, dict[str, Any]], Any] | None = None  # None: guidance on the state


def check_inputs(cfg: Config, hooks_for: HooksFor) -> tuple[str, str, dict[str, Any]]:
    """Everything a job reads, checked: (the low-level policy's digest, the device, the planner's manifest).

    What :func:`prepare` checks, without the provenance it adds; ``evaluation.job_upload`` watches these
    checks to learn which checkpoints a job reads."""
    policy = hooks_for(cfg.env.name).check_episodes(cfg)  # e.g. the ant's or the arm's policy exists and fits
    device = str(resolve_device(cfg.device))
    check_compile(cfg.diffusion.compile, device)  # a compiled denoiser's toolchain is there
    manifest = verify_checkpoint(cfg.checkpoint_dir(), cfg)  # exists, well-typed, agrees with the config, sha256
    return policy, device, manifest


def prepare(cfg: Config, hooks_for: HooksFor) -> Prepared:
    """Every check a user can fail; ``hooks_for`` finds the env family's hooks (``fmctd_dist.families``)."""
    hooks = hooks_for(cfg.env.name)
    policy, device, manifest = check_inputs(cfg, hooks_for)
    return Prepared(cfg, cfg.checkpoint_dir(), manifest["digest"], device, config_hash(cfg), git_sha(), policy,
                    hooks.episodes, hooks.plan_rules, getattr(hooks, "guide_map", None))


def same_policy(p: Prepared, episodes: Any) -> None:
    """The policy an episode runner loaded is the one the job checked (a policy retrained while a grid
    runs would otherwise mix into its rows): else one CheckpointError."""
    loaded = getattr(episodes, "policy_digest", "")
    if loaded != p.policy_digest:
        raise CheckpointError(f"env.policy changed while the job ran: checked {p.policy_digest or 'none'}, loaded "
                              f"{loaded or 'none'}; rerun once the policy stops changing (rows kept so far are "
                              "from the checked one)")


def grid(cfg: Config) -> list[tuple[int, int]]:
    return [(t, s) for t in cfg.eval.tasks for s in cfg.eval.seeds]


def missing(p: Prepared, store: ResultStore, log: Callable[[str], None] = print) -> list[tuple[int, int]]:
    """The (task, seed) keys of the grid without a row (unreadable row files count as missing, reported); one
    ResultsError listing what differs when the run holds rows of another config or checkpoint (docs/design.md
    §10: a run directory never mixes them)."""
    cfg = p.cfg
    rows = store.rows(cfg.method.name, cfg.env.name)
    for line in store.report():
        log(line)
    key = (p.config_hash, p.checkpoint_digest, p.policy_digest)
    # ray.micro_batch shapes bits (on the sparse models even at one torch thread) though the hash leaves the ray
    # section out: rows that record it must have this run's
    m = cfg.ray.micro_batch
    foreign = [r for r in rows
               if (r.get("config_hash"), r.get("checkpoint_digest"), r.get("policy_digest") or "") != key
               or r.get("micro_batch", m) != m]
    if foreign:
        diffs = list(dict.fromkeys(d for r in foreign for d in differences(r, cfg, p.checkpoint_digest,
                                                                                p.policy_digest)))
        diffs += [f"ray.micro_batch: {r['micro_batch']} there, {m} now" for r in foreign[:1]
                  if r.get("micro_batch", m) != m]
        raise ResultsError(
            f"{store.root / cfg.method.name / cfg.env.name} holds {len(foreign)} row(s) from another config or "
            f"checkpoint: {'; '.join(diffs[:12])}{' ...' if len(diffs) > 12 else ''}. Write to a new run with "
            f"eval.run=<new name>, or move {store.root / cfg.method.name / cfg.env.name} aside to replace them")
    done = {(int(r["task"]), int(r["seed"])) for r in rows}
    return [(t, s) for t, s in grid(cfg) if (t, s) not in done]


def provenance(p: Prepared, n_actors: int) -> dict[str, Any]:
    """Run-level fields of a row: where it ran, and the search knobs the ablation tables group by."""
    m = p.cfg.method
    return {"n_denoiser_actors": n_actors, "device": p.device, "git_sha": p.git_sha,
            "checkpoint_digest": p.checkpoint_digest, "policy_digest": p.policy_digest, **identity_columns(p.cfg),
            "parallel": m.parallel, "virtual_weight": m.virtual_weight, "redundancy_aware": m.redundancy_aware,
            "leaf_parallel": m.leaf_parallel, "jump": p.cfg.jump, "budget": m.budget,
            "episode_time_limit": p.cfg.eval.episode_time_limit,
            "precision": p.cfg.diffusion.precision, "compiled": p.cfg.diffusion.compile,
            "micro_batch": p.cfg.ray.micro_batch, "in_flight": p.cfg.eval.in_flight}


class PlanTicker:
    """A planner that shows each plan on the progress bar: a replanning episode can run for most of an hour
    (MCTD-Replan on the visual maze: 10 full searches, ~40 min on one CPU core), so the bar says which plan of
    which episode is done, and how it ended, not only how many episodes are. Plans pass through unchanged."""

    def __init__(self, planner: Any, bar: Any):
        self.planner, self.bar = planner, bar
        self.episode, self.plans, self.success = "", 0, ""

    def start(self, task: int, seed: int, success: str) -> None:
        """A new episode: its plan count restarts."""
        self.episode, self.plans, self.success = f"{task}/{seed}", 0, success

    def plan(self, start: Any, goal: Any, seed: int) -> Any:
        out = self.planner.plan(start, goal, seed)
        self.plans += 1
        self.bar.set_postfix(success=self.success, episode=self.episode, plans=self.plans, last=out.status)
        return out


class InPool:
    """A tree's planner whose plans tell the pool they run, so each round waits for a call of every planning tree
    (:meth:`PooledDenoiser.planning`)."""

    def __init__(self, planner: Any, pool: Any):
        self.planner, self.pool = planner, pool

    def plan(self, start: Any, goal: Any, seed: int) -> Any:
        with self.pool.planning():
            return self.planner.plan(start, goal, seed)


def _successes(rows: list[dict[str, Any]]) -> str:
    """``solved/done`` of the episodes this run has finished, for the progress bar."""
    return f"{sum(r['success'] for r in rows)}/{len(rows)}"


def run_local(p: Prepared, store: ResultStore, progress: bool = True,
              log: Callable[[str], None] = print) -> list[dict[str, Any]]:
    """All missing episodes of the grid in this process (LocalDenoiser, no Ray). ``eval.in_flight`` episodes run
    at once, each in its own thread with its own env and tree, their denoiser calls pooled (PooledDenoiser) at the
    configured micro-batch, so every row is the one a lone episode gets (docs/design.md §6)."""
    from fmctd_dist.denoiser.local import LocalDenoiser
    from fmctd_dist.denoiser.pool import PooledDenoiser
    from fmctd_dist.diffusion.checkpoint import normaliser_from_manifest
    from fmctd_dist.planners import make_planner

    cfg = p.cfg
    todo = missing(p, store, log)
    if not todo:
        return []
    set_threads(cfg.eval.threads)
    inner = LocalDenoiser.from_checkpoint(p.checkpoint, cfg, expect_digest=p.checkpoint_digest,
                                          guide_map=p.guide_map)
    denoiser = inner if cfg.eval.in_flight == 1 else PooledDenoiser(inner, inner.micro_batch)
    normaliser = normaliser_from_manifest(read_manifest(p.checkpoint))
    bar = tqdm(total=len(todo), desc=f"{cfg.method.name} {cfg.env.name}", unit="ep", disable=not progress)
    rows: list[dict[str, Any]] = []
    mine = threading.local()  # per thread: the family's env + controller and a tree, built once

    def episode(key: tuple[int, int]) -> dict[str, Any]:
        if not hasattr(mine, "ticker"):
            mine.episodes = p.episodes(cfg)
            same_policy(p, mine.episodes)
            planner = make_planner(cfg, denoiser, normaliser, p.plan_rules(cfg), cfg.eval.episode_time_limit)
            mine.ticker = PlanTicker(planner if denoiser is inner else InPool(planner, denoiser), bar)
        mine.ticker.start(*key, success=_successes(rows))
        return {**mine.episodes.run(mine.ticker, *key), **provenance(p, 0)}

    def record(row: dict[str, Any]) -> None:
        store.write(row)
        rows.append(row)
        bar.update()
        bar.set_postfix(success=_successes(rows))
        log(describe(row))

    if cfg.eval.in_flight == 1:
        for key in todo:
            record(episode(key))
    else:
        with ThreadPoolExecutor(cfg.eval.in_flight, thread_name_prefix="episode") as pool:
            for done in as_completed([pool.submit(episode, key) for key in todo]):
                record(done.result())
    bar.close()
    order = {key: i for i, key in enumerate(todo)}
    return sorted(rows, key=lambda r: order[(r["task"], r["seed"])])
