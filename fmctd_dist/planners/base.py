"""What every planner returns, and how plan seeds are derived (one visible place)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np


@dataclass
class PlanOutput:
    """waypoints: [F_env, d] planner states (maze x, y; cube xyz per cube), one per env step (sparse plans already
    repeated H times)."""

    waypoints: np.ndarray
    status: str
    plan_time_s: float
    denoise_time_s: float
    expansions: int = 0
    iterations: int = 0
    denoise_calls: int = 0
    retries: int = 0
    timed_out: bool = False
    denoise_call_s: float = 0.0  # wall time inside denoiser calls; > denoise_time_s by queueing/transport (Ray)
    extra: dict = field(default_factory=dict)


class Planner(Protocol):
    def plan(self, start: np.ndarray, goal: np.ndarray, seed: int) -> PlanOutput: ...


def plan_seed(*keys: int) -> int:
    """A 63-bit seed from integer keys, e.g. (config seed, task, episode seed, replan index)."""
    return int(np.random.SeedSequence([int(k) for k in keys]).generate_state(2, dtype=np.uint64)[0] >> np.uint64(1))


def repeat_waypoints(plan: np.ndarray, jump: int) -> np.ndarray:
    """[F, 2] coarse plan -> [F * jump, 2]: each waypoint held for ``jump`` env steps (S-MCTD)."""
    return np.repeat(np.asarray(plan), jump, axis=0)
