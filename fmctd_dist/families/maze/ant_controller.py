"""Execute an x, y plan on the ant: a :class:`SubgoalTracker` picks the subgoal, a goal-conditioned policy walks to it.

The authors' AntMaze controller (docs/reference.md §7): the subgoal is the plan point 10 steps
ahead, moved 10 further each time the ant comes within 1.0 of it, held at the plan's last
point; a low-level policy maps (ant state, subgoal) to torques. The policy is any callable
``(obs [29], subgoal [2]) -> torques [8]`` (:class:`fmctd_dist.control.policy.checkpoint.GoalPolicy`, or
the expert via :func:`fmctd_dist.families.maze.ant_reach.expert_controller`), so this module needs no
torch and tests can drive it with fakes.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from fmctd_dist.families.maze.subgoal import SubgoalTracker

SUBGOAL_INTERVAL = 10  # plan points between subgoals (authors' sub_goal_interval)
ADVANCE_RADIUS = 1.0  # distance at which the subgoal moves on

Policy = Callable[[np.ndarray, np.ndarray], np.ndarray]


class AntLikeEnv(Protocol):
    """What :func:`run_plan` needs: AntMaze's surface."""

    def observation(self) -> np.ndarray: ...

    def step(self, action: np.ndarray) -> tuple[np.ndarray, bool]: ...


class AntPlanController:
    """plan [F, 2] (one x, y per env step) + policy -> ``act(obs [29]) -> torques [8]``, one call per env step."""

    def __init__(self, plan: np.ndarray, policy: Policy, interval: int = SUBGOAL_INTERVAL,
                 radius: float = ADVANCE_RADIUS):
        self.tracker = SubgoalTracker(plan, interval, radius)
        self.policy = policy
        self.advances = 0

    @property
    def subgoal(self) -> np.ndarray:
        return self.tracker.subgoal

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Update the subgoal from the ant's x, y (obs[:2]), then ask the policy for torques towards it."""
        obs = np.asarray(obs, dtype=np.float64)
        before = self.tracker.index
        subgoal = self.tracker.update(obs[:2])
        self.advances += self.tracker.index != before
        return np.asarray(self.policy(obs, subgoal), dtype=np.float64)


@dataclass
class PlanRun:
    """What one :func:`run_plan` episode did."""

    success: bool  # the env reported success after some step (AntMaze: within 0.5 of its goal)
    steps: int  # env steps taken
    advances: int  # subgoal moves along the plan
    subgoal_index: int  # plan index of the last subgoal
    positions: np.ndarray = field(repr=False)  # [steps + 1, 2] x, y, start included
    subgoals: np.ndarray = field(repr=False)  # [steps, 2] the subgoal used at each step


def run_plan(env: AntLikeEnv, plan: np.ndarray, policy: Policy, max_steps: int, interval: int = SUBGOAL_INTERVAL,
             radius: float = ADVANCE_RADIUS, stop_on_success: bool = True) -> PlanRun:
    """Drive ``env`` (already reset) along ``plan`` for up to ``max_steps`` env steps, open loop in time."""
    ctrl = AntPlanController(plan, policy, interval, radius)
    obs = np.asarray(env.observation(), dtype=np.float64)
    positions, subgoals = [obs[:2].copy()], []
    success, steps = False, 0
    for _ in range(max_steps):
        action = ctrl.act(obs)
        subgoals.append(ctrl.subgoal.copy())
        obs, reached = env.step(action)
        obs = np.asarray(obs, dtype=np.float64)
        positions.append(obs[:2].copy())
        steps += 1
        success = success or bool(reached)
        if reached and stop_on_success:
            break
    return PlanRun(bool(success), steps, ctrl.advances, ctrl.tracker.index, np.asarray(positions),
                   np.asarray(subgoals).reshape(-1, 2))
