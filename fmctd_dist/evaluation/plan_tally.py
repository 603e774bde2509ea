"""An episode's plans: their seeds, its planning-time limit, and what they cost summed over its replans: the
columns every family's row starts with.

Mazes, cubes and the visual maze drive their robots differently but plan and count their plans the same
way, so reports and tables read one set of columns from any of them.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fmctd_dist.config import Config
from fmctd_dist.planners.base import Planner, PlanOutput, plan_seed


@dataclass
class PlanTally:
    method: str = ""  # the episode (see :meth:`episode`): the row's key, its plans' seeds and time limit
    env: str = ""
    keys: tuple[int, int, int] = (0, 0, 0)  # (config seed, task, episode seed)
    limit_s: float = 0.0  # planning seconds per episode, 0: none
    t0: float = field(default_factory=time.perf_counter)
    timed_out: bool = False
    first: Any = None  # the first plan's waypoints
    plans: int = 0
    plan_time_s: float = 0.0
    denoise_time_s: float = 0.0
    denoise_call_s: float = 0.0
    expansions: int = 0
    iterations: int = 0
    retries: int = 0
    statuses: list[str] = field(default_factory=list)

    @classmethod
    def episode(cls, cfg: Config, task: int, seed: int, time_limit_s: float | None = None) -> PlanTally:
        """The tally of one episode starting now (``time_limit_s``: default ``eval.episode_time_limit``)."""
        limit = cfg.eval.episode_time_limit if time_limit_s is None else time_limit_s
        return cls(cfg.method.name, cfg.env.name, (cfg.seed, task, seed), limit)

    def plan(self, planner: Planner, state: np.ndarray, goal: np.ndarray) -> PlanOutput | None:
        """Plan from ``state`` with the episode's next plan seed and count it -> the plan, or None (``timed_out``
        set) when the planner or the episode ran out of planning time."""
        out = planner.plan(state, goal, plan_seed(*self.keys, self.plans))
        self.add(out)
        self.first = out.waypoints if self.first is None else self.first
        if out.timed_out or (self.limit_s and self.plan_time_s > self.limit_s):
            self.timed_out = True
            return None
        return out

    def row(self, success: bool, env_steps: int) -> dict[str, Any]:
        """The columns every family's row starts with (then its own: trajectories, plans, ...)."""
        return {"method": self.method, "env": self.env, "task": int(self.keys[1]), "seed": int(self.keys[2]),
                "success": bool(success and not self.timed_out), "timed_out": self.timed_out, "env_steps": env_steps,
                **self.columns(), "episode_time_s": time.perf_counter() - self.t0}

    def add(self, out: PlanOutput) -> None:
        """Count one planner call."""
        self.plans += 1
        for k in ("plan_time_s", "denoise_time_s", "denoise_call_s", "expansions", "iterations", "retries"):
            setattr(self, k, getattr(self, k) + getattr(out, k))
        self.statuses.append(out.status)

    def columns(self) -> dict[str, Any]:
        """The row's planning columns (shares are of the planning time; 0 before any plan)."""
        t = self.plan_time_s
        return {"plan_time_s": t, "denoise_time_s": self.denoise_time_s, "overhead_s": t - self.denoise_time_s,
                "denoise_share": self.denoise_time_s / t if t > 0 else 0.0, "denoise_call_s": self.denoise_call_s,
                "call_share": self.denoise_call_s / t if t > 0 else 0.0, "expansions": self.expansions,
                "iterations": self.iterations, "retries": self.retries, "plans": self.plans,
                "plan_status": ",".join(self.statuses)}


def plan_statuses(row: Mapping[str, Any]) -> Counter[str]:
    """How each of a row's plans ended, counted (``{"stay": 3, "achieved": 1}``): the one reader of the
    ``plan_status`` column that :meth:`PlanTally.columns` writes, so tables and reports count it alike."""
    return Counter(s for s in str(row.get("plan_status") or "").split(",") if s)
