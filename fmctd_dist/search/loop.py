"""The one search loop behind MCTD, P-MCTD, S-MCTD and Fast-MCTD (docs/reference.md §3).

Sequential MCTD is K = 1; P-MCTD is K > 1 with virtual visits and redundancy-aware claims;
the sparse variants only change the schedule/codec/checkpoint handed in, which this loop
never inspects. Env families differ only in what is handed in too: the action set (child
slots: guidance scale + guided state dims, :mod:`search.actions`) and the plan value
(:class:`search.value_rule.PlanValue`; mazes by default). Per iteration: serial selection ->
deterministic node ids -> ONE batched expansion call -> ONE batched jumpy-simulation call
(+ batched bad-plan retries) -> values -> allocate nodes -> max backup -> early-stop check on
the new nodes' own plans.
All randomness comes from ``plan_seed``: the slot choice from one per-plan generator, the
initial noise of a depth-1 job from SeedSequence([plan_seed, node_id, attempt(, copy)]).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, fields
from typing import TYPE_CHECKING, Callable

import numpy as np

from fmctd_dist.tokens import PlanCodec
from fmctd_dist.denoiser.protocol import DenoiseBatch, Denoiser, pad_levels
from fmctd_dist.diffusion.schedule import PyramidSchedule
from fmctd_dist.search.actions import Actions, scale_actions
from fmctd_dist.search.select import backup, open_slots, select_batch
from fmctd_dist.search.tree import Assignment, Tree, add_nodes, assign_ids, empty_tree
from fmctd_dist.search.value import ACHIEVED, NOT_REACHED, barely_moves
from fmctd_dist.search.value_rule import MazeValue, PlanValue

if TYPE_CHECKING:  # config.py pulls in omegaconf; the search only needs the field names
    from fmctd_dist.config import MethodConfig

SELECT_TAG = 0x5E1EC7_0000_0001  # > 2**32: cannot collide with a [plan_seed, node, attempt] key
MAX_IDLE_BATCHES = 10_000  # consecutive batches without a job before the search gives up

# SearchResult.status values
EARLY_STOP = "early_stop"  # a new node's own (expansion-end) plan reached the goal
STATUS_ACHIEVED = "achieved"  # budget/time ran out; best simulated plan that reaches the goal
STATUS_PARTIAL = "partial"  # budget/time ran out; best simulated plan with a value > 0 short of the goal (cubes)
STATUS_NOT_REACHED = "not_reached"  # first non-warping simulated plan (value 0)
STATUS_STAY = "stay"  # no usable plan: the start repeated


@dataclass(frozen=True)
class SearchParams:
    """Search knobs; see MethodConfig for the meaning and the paper's values."""

    parallel: int = 200  # K: descents (expansion jobs) per iteration
    virtual_weight: float = 1.0  # w: weight of virtual visits in UCT
    redundancy_aware: bool = True  # an empty slot can be claimed once per batch
    leaf_parallel: bool = False  # a selected child gets A virtual visits instead of 1
    guidance_scales: tuple[float, ...] = (0.0, 0.1, 0.5, 1.0, 2.0)  # one child slot per scale (no actions given)
    budget: int = 500  # expansion jobs; no iteration starts at or above it
    warp_threshold: float = 2.0  # world units per plan frame (the default maze value rule)
    goal_radius: float = 2.0  # world units (the default maze value rule)
    bad_plan_tries: int = 10  # retries (after attempt 0) for plans that barely move
    bad_plan_step: float = 0.1  # "barely moves": every step below this (world units)
    uct_c: float = math.sqrt(2.0)
    early_stop: bool = True  # stop when a new node's own plan reaches the goal
    time_limit_s: float = 0.0  # wall-clock limit checked at the top of each iteration; 0 = none
    clip_noise: float = 20.0  # initial noise clipped to +-clip_noise

    def __post_init__(self) -> None:
        if self.parallel < 1 or self.budget < 1 or not self.guidance_scales or self.bad_plan_tries < 0:
            raise ValueError(f"invalid SearchParams: parallel={self.parallel} budget={self.budget} "
                             f"guidance_scales={self.guidance_scales} bad_plan_tries={self.bad_plan_tries}")

    @classmethod
    def from_method(cls, method: "MethodConfig", *, time_limit_s: float = 0.0,
                    clip_noise: float = 20.0) -> "SearchParams":
        """From a MethodConfig (time limit and noise clip live in eval/diffusion configs), cast to each field's type."""
        def cast(default: object, v: object) -> object:
            return tuple(float(s) for s in v) if isinstance(default, tuple) else type(default)(v)

        given = {"time_limit_s": time_limit_s, "clip_noise": clip_noise}
        return cls(**{f.name: cast(f.default, given[f.name] if f.name in given else getattr(method, f.name))
                      for f in fields(cls)})


@dataclass
class IterStats:
    """Cheap per-iteration record (one per iteration that ran jobs)."""

    iteration: int
    jobs: int  # expansion jobs (counted against the budget)
    new_nodes: int  # distinct nodes created (< jobs only with redundancy_aware off)
    descents: int  # selection attempts
    wasted: int  # descents that found nothing to claim
    resampled: int  # job re-runs for plans that barely moved
    denoise_calls: int
    denoise_time_s: float
    root_value: float  # after backup
    wall_s: float


@dataclass
class SearchResult:
    plan: np.ndarray  # [F', d] float32 world-unit waypoints (length varies with status)
    status: str  # EARLY_STOP | STATUS_ACHIEVED | STATUS_NOT_REACHED | STATUS_STAY
    value: float  # value of the returned plan (0 unless it reaches the goal)
    expansions: int  # expansion jobs run (budget units)
    iterations: int  # iterations that ran jobs
    denoise_calls: int  # Denoiser.denoise calls
    denoise_time_s: float  # sum of DenoiseResult.denoise_time_s (compute inside the denoiser)
    wall_time_s: float
    timed_out: bool
    stop_reason: str  # early_stop | budget | time | exhausted | stalled
    tree: Tree
    retries: int = 0  # sum of DenoiseResult.retries
    resampled: int = 0  # bad-plan job re-runs
    denoise_call_s: float = 0.0  # wall time inside Denoiser.denoise calls (compute + queueing + transport)
    stats: list[IterStats] = field(default_factory=list)


def initial_noise(plan_seed: int, node: int, attempt: int, copy: int, shape: tuple[int, ...],
                  clip: float) -> np.ndarray:
    """Clipped standard-normal float32 noise for one depth-1 job, a pure function of its key."""
    key = [plan_seed, node, attempt] + ([copy] if copy else [])
    z = np.random.default_rng(np.random.SeedSequence(key)).standard_normal(shape)
    return np.clip(z, -clip, clip).astype(np.float32)


def stack_levels(levels: list[np.ndarray]) -> np.ndarray:
    """[B, R_max+1, T] int64 from per-job [R_j+1, T] levels, short ones padded with no-op rows."""
    rows = max(lv.shape[0] for lv in levels)
    return np.concatenate([pad_levels(lv[None].astype(np.int64), rows) for lv in levels])


class _Runner:
    """Wraps the denoiser: builds batches, checks shapes, sums call counts and timings."""

    def __init__(self, denoiser: Denoiser, start_n: np.ndarray, goal_n: np.ndarray, clock: Callable[[], float]):
        self.denoiser, self.start_n, self.goal_n, self.clock = denoiser, start_n, goal_n, clock
        self.calls, self.time_s, self.call_s, self.retries = 0, 0.0, 0.0, 0

    def __call__(self, x: np.ndarray, levels: np.ndarray, acts: Actions) -> np.ndarray:
        b = x.shape[0]
        mask = None if acts.mask is None else np.ascontiguousarray(acts.mask, np.float32)
        batch = DenoiseBatch(x=np.ascontiguousarray(x, np.float32), levels=levels, scale=acts.scale.astype(np.float32),
                             start=np.repeat(self.start_n[None], b, 0), goal=np.repeat(self.goal_n[None], b, 0),
                             guide_mask=mask)
        t0 = self.clock()
        res = self.denoiser.denoise(batch)
        self.call_s += self.clock() - t0
        assert res.x.shape == batch.x.shape, f"denoiser returned {res.x.shape} for a batch of {batch.x.shape}"
        self.calls += 1
        self.time_s += float(res.denoise_time_s)
        self.retries += int(res.retries)
        return np.asarray(res.x, np.float32)


class _Fallbacks:
    """What to return if no early stop: best ACHIEVED (or, for rules with partial credit, best
    value > 0) > first NOT_REACHED > stay (docs/reference.md §3.9). For the maze rule value > 0 iff ACHIEVED."""

    def __init__(self, goal: np.ndarray, rule: PlanValue):
        self.goal, self.rule = goal, rule
        self.best: tuple[float, np.ndarray, bool] | None = None  # (value, output plan, achieved)
        self.not_reached: np.ndarray | None = None  # [F', d] first non-warping plan

    def add(self, plans: np.ndarray, values: np.ndarray, status: np.ndarray, reach_t: np.ndarray) -> None:
        """Per-job results in job order; earlier jobs win ties."""
        for j in range(plans.shape[0]):
            if (status[j] == ACHIEVED or values[j] > 0) and (self.best is None or values[j] > self.best[0]):
                self.best = (float(values[j]), self.rule.output(plans[j], int(reach_t[j]), self.goal),
                             bool(status[j] == ACHIEVED))
            elif status[j] == NOT_REACHED and self.not_reached is None:
                self.not_reached = self.rule.output(plans[j], -1, self.goal)

    def pick(self, start: np.ndarray, frames: int) -> tuple[str, float, np.ndarray]:
        if self.best is not None:
            return STATUS_ACHIEVED if self.best[2] else STATUS_PARTIAL, self.best[0], self.best[1]
        if self.not_reached is not None:
            return STATUS_NOT_REACHED, 0.0, self.not_reached
        return STATUS_STAY, 0.0, np.repeat(start[None].astype(np.float32), max(frames, 1), axis=0)


def search(denoiser: Denoiser, schedule: PyramidSchedule, codec: PlanCodec, start: np.ndarray, goal: np.ndarray,
           params: SearchParams, plan_seed: int, *, actions: Actions | None = None, value: PlanValue | None = None,
           clock: Callable[[], float] = time.perf_counter) -> SearchResult:
    """Plan from ``start`` [d] to ``goal`` [d] (world units); see the module docstring.

    ``actions``: the child slots (default: one per ``params.guidance_scales``, every dim
    guided). ``value``: the plan value rule (default: the maze's, with ``params.warp_threshold``
    and ``params.goal_radius``); it also decides the early stop and the returned plan.
    """
    t0 = clock()
    start = np.asarray(start, np.float64).reshape(-1)
    goal = np.asarray(goal, np.float64).reshape(-1)
    d = start.shape[0]
    acts = scale_actions(params.guidance_scales) if actions is None else actions  # [A] child slots
    rule: PlanValue = MazeValue(params.warp_threshold, params.goal_radius) if value is None else value
    if acts.mask is not None and acts.mask.shape[1] != d:
        raise ValueError(f"action masks cover {acts.mask.shape[1]} state dims but the start has {d}")
    p_tokens = schedule.plan_tokens
    frames = p_tokens * codec.frame_stack
    k = int(params.parallel)
    tree = empty_tree(1 + params.budget + k, acts.size, p_tokens + 1, codec.frame_stack * d,
                      frames, schedule.terminal_depth, d)
    rng = np.random.default_rng(np.random.SeedSequence([plan_seed, SELECT_TAG]))
    ctx = codec.context(start[None])[0]  # [1, D]
    run = _Runner(denoiser, codec.normaliser.normalise(start), codec.normaliser.normalise(goal), clock)

    def expand(asg: Assignment, idx: np.ndarray, attempt: np.ndarray) -> np.ndarray:
        depth = tree.depth[asg.parent[idx]] + 1  # [B]
        x = tree.x[asg.parent[idx]].copy()  # [B, T, D]
        for b, j in enumerate(idx):
            if depth[b] == 1:
                noise = initial_noise(plan_seed, int(asg.node[j]), int(attempt[j]), int(asg.copy[j]),
                                      (p_tokens, x.shape[2]), params.clip_noise)
                x[b] = np.concatenate([ctx, noise])
        levels = stack_levels([schedule.expansion(int(dd)) for dd in depth])
        return run(x, levels, acts.take(asg.slot[idx]))

    def simulate(asg: Assignment, idx: np.ndarray, x: np.ndarray) -> np.ndarray:
        depth = tree.depth[asg.parent[idx]] + 1
        levels = stack_levels([schedule.simulation(int(dd)) for dd in depth])
        return run(x, levels, acts.take(asg.slot[idx]))

    fallback = _Fallbacks(goal, rule)
    early: tuple[float, np.ndarray] | None = None
    stats: list[IterStats] = []
    expansions = iterations = resampled = idle = 0
    timed_out = False
    stop_reason = "budget"
    while True:
        if expansions >= params.budget:
            stop_reason = "budget"
            break
        if params.time_limit_s > 0 and clock() - t0 >= params.time_limit_s:
            timed_out, stop_reason = True, "time"
            break
        it_t0, calls0, time0 = clock(), run.calls, run.time_s
        cand = select_batch(tree, k, rng, c=params.uct_c, w=params.virtual_weight,
                            redundancy_aware=params.redundancy_aware, leaf_parallel=params.leaf_parallel)
        if cand.parents.shape[0] == 0:
            idle += 1
            if open_slots(tree) == 0 or params.virtual_weight == 0 or idle >= MAX_IDLE_BATCHES:
                stop_reason = "exhausted" if open_slots(tree) == 0 else "stalled"
                break
            continue  # virtual visits from the wasted descents steer the next batch elsewhere
        idle = 0
        asg = assign_ids(tree, cand.parents, cand.slots)
        jobs = np.arange(asg.size)
        attempt = np.zeros(asg.size, np.int64)  # [J]
        ex_x = expand(asg, jobs, attempt)  # [J, T, D]
        sim_x = simulate(asg, jobs, ex_x)  # [J, T, D]
        job_acts = acts.take(asg.slot)  # [J] actions in job order
        plans = rule.prepare(codec.decode(sim_x), start, job_acts)  # [J, F, d]
        # Retries only for depth-1 jobs: deeper expansions are a pure function of the parent.
        bad = barely_moves(plans, params.bad_plan_step) & (tree.depth[asg.parent] == 0)  # [J]
        n_resampled = 0
        for a in range(1, params.bad_plan_tries + 1):
            redo = np.flatnonzero(bad)
            if redo.size == 0:
                break
            attempt[redo] = a
            ex_x[redo] = expand(asg, redo, attempt)
            sim_x[redo] = simulate(asg, redo, ex_x[redo])
            plans[redo] = rule.prepare(codec.decode(sim_x[redo]), start, job_acts.take(redo))
            bad[redo] = barely_moves(plans[redo], params.bad_plan_step)
            n_resampled += redo.size
        values, status, reach_t = rule.values(plans, start, goal, job_acts)
        fallback.add(plans, values, status, reach_t)
        add_nodes(tree, asg, ex_x, values, status, plans, attempt, iterations)
        backup(tree, asg.parent)
        expansions += asg.size
        resampled += n_resampled
        if params.early_stop:
            new = asg.new_nodes
            new_acts = acts.take(tree.slot[new])
            own = rule.prepare(codec.decode(tree.x[new]), start, new_acts)  # [U, F, d] expansion-end plans
            ev, es, et = rule.values(own, start, goal, new_acts)
            if np.any(es == ACHIEVED):
                i = int(np.argmax(np.where(es == ACHIEVED, ev, -1.0)))  # earliest reach, lowest id
                early = (float(ev[i]), rule.output(own[i], int(et[i]), goal))
        stats.append(IterStats(iterations, asg.size, int(asg.new_nodes.shape[0]), cand.attempts, cand.wasted,
                               n_resampled, run.calls - calls0, run.time_s - time0, float(tree.value[0]),
                               clock() - it_t0))
        iterations += 1
        if early is not None:
            stop_reason = EARLY_STOP
            break

    if early is not None:
        status_out, value_out, plan = EARLY_STOP, early[0], early[1]
    else:
        status_out, value_out, plan = fallback.pick(start, frames - 1)
    return SearchResult(plan=plan, status=status_out, value=value_out, expansions=expansions, iterations=iterations,
                        denoise_calls=run.calls, denoise_time_s=run.time_s, wall_time_s=clock() - t0,
                        timed_out=timed_out, stop_reason=stop_reason, tree=tree, retries=run.retries,
                        resampled=resampled, denoise_call_s=run.call_s, stats=stats)
