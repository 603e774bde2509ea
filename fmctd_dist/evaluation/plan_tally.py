"""What an episode's plans cost, summed over its replans: the planning columns every family's row shares.

Mazes (``episode.py``) and cubes (``cube_episode.py``) drive their robots differently but count
their plans the same way, so reports and tables read one set of columns from either.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from fmctd_dist.planners.base import PlanOutput


@dataclass
class PlanTally:
    plans: int = 0
    plan_time_s: float = 0.0
    denoise_time_s: float = 0.0
    denoise_call_s: float = 0.0
    expansions: int = 0
    iterations: int = 0
    retries: int = 0
    statuses: list[str] = field(default_factory=list)

    def add(self, out: PlanOutput) -> None:
        """Count one planner call."""
        self.plans += 1
        self.plan_time_s += out.plan_time_s
        self.denoise_time_s += out.denoise_time_s
        self.denoise_call_s += out.denoise_call_s
        self.expansions += out.expansions
        self.iterations += out.iterations
        self.retries += out.retries
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
