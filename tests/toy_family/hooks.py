"""The toy family's hooks: guidance scales + the generic reach value; episodes that follow the plan's waypoints."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fmctd_dist.config import Config
from fmctd_dist.evaluation.plan_tally import PlanTally
from fmctd_dist.planners.base import Planner
from fmctd_dist.search.actions import Actions, scale_actions
from fmctd_dist.search.value_rule import MazeValue, PlanValue

from toy_family.env import Plane


@dataclass(frozen=True)
class ToyRules:
    scales: tuple[float, ...]
    value: PlanValue

    def tree(self, start: np.ndarray, goal: np.ndarray) -> tuple[Actions, PlanValue]:
        return scale_actions(self.scales), self.value

    def fixed(self, start: np.ndarray, goal: np.ndarray) -> tuple[Actions, PlanValue]:
        return scale_actions(self.scales[-1:]), self.value


def plan_rules(cfg: Config) -> ToyRules:
    m = cfg.method
    value = MazeValue(float(m.warp_threshold), float(m.goal_radius))
    return ToyRules(tuple(float(s) for s in m.guidance_scales), value)


def check_episodes(cfg: Config) -> str:
    return ""  # no low-level policy: the point moves toward each waypoint


class ToyEpisodes:
    policy_digest = ""

    def __init__(self, cfg: Config):
        self.cfg = cfg

    def run(self, planner: Planner, task: int, seed: int) -> dict[str, Any]:
        env, tally = Plane(), PlanTally.episode(self.cfg, task, seed, 0.0)
        pos, goal = env.reset(task)
        tally.plan(planner, pos, goal)  # one plan (0.0: no episode time limit), followed to its end
        traj, success, steps = [pos], False, 0
        for waypoint in tally.first:
            pos, success = env.step(waypoint - pos)
            traj.append(pos)
            steps += 1
            if success or steps >= self.cfg.env.max_steps:
                break
        return {**tally.row(success, steps), "plan_xy": np.asarray(tally.first, np.float32).reshape(-1).tolist(),
                "traj_xy": np.asarray(traj, np.float32).reshape(-1).tolist()}


def episodes(cfg: Config) -> ToyEpisodes:
    return ToyEpisodes(cfg)


def plot_episode(row: dict[str, Any], path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(3, 3))
    ax.plot(*np.asarray(row["plan_xy"]).reshape(-1, 2).T, label="plan")
    ax.plot(*np.asarray(row["traj_xy"]).reshape(-1, 2).T, label="trajectory")
    ax.set(xlim=(0, 8), ylim=(0, 8), aspect="equal")
    ax.legend()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path
