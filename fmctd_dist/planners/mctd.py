"""MCTD, P-MCTD, S-MCTD and Fast-MCTD: one search loop, four configs.

K (``method.parallel``), w, RAS, leaf parallelisation and H (``jump``, which also picks the
sparse checkpoint) are config, read once by :func:`fmctd_dist.planners.make_planner`; this class only wires the
schedule, codec and denoiser into :func:`fmctd_dist.search.loop.search`, with the action set and plan value the env
family's plan rules give for each call (handed in by the caller), and expands a sparse plan to one waypoint per
env step.
"""

from __future__ import annotations

import time

import numpy as np

from fmctd_dist.denoiser.protocol import Denoiser
from fmctd_dist.diffusion.schedule import PyramidSchedule
from fmctd_dist.family import PlanRules
from fmctd_dist.planners.base import PlanOutput, repeat_waypoints
from fmctd_dist.search.loop import SearchParams, search
from fmctd_dist.tokens import PlanCodec


class MCTDPlanner:
    def __init__(self, denoiser: Denoiser, schedule: PyramidSchedule, codec: PlanCodec, params: SearchParams,
                 rules: PlanRules, jump: int):
        self.denoiser, self.schedule, self.codec, self.params = denoiser, schedule, codec, params
        self.rules, self.jump = rules, jump
        self.last_result = None  # the SearchResult of the last call (tree, per-iteration stats)

    def plan(self, start: np.ndarray, goal: np.ndarray, seed: int) -> PlanOutput:
        t0 = time.perf_counter()
        start, goal = np.asarray(start, np.float64), np.asarray(goal, np.float64)
        actions, value = self.rules.tree(start, goal)
        r = search(self.denoiser, self.schedule, self.codec, start, goal, self.params, seed,
                   actions=actions, value=value)
        self.last_result = r
        same = ("status", "denoise_time_s", "expansions", "iterations", "denoise_calls", "retries", "timed_out",
                "denoise_call_s")
        return PlanOutput(waypoints=repeat_waypoints(r.plan, self.jump), plan_time_s=time.perf_counter() - t0,
                          extra={"stop_reason": r.stop_reason, "value": float(r.value)},
                          **{k: getattr(r, k) for k in same})
