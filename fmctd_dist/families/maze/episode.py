"""One maze episode: plan from the current position, follow the plan with the robot's controller
(PD on waypoints for the point, subgoals + learned policy for the ant), replan every
``method.replan_every`` env steps (0 = open loop), stop at success or budget.

Returns a result row (docs/design.md §10); the episode seed only feeds the planner's seeds (and the
start/goal noise under ``env.protocol=ogbench``), so an episode is a pure function of
(config, checkpoint, task, seed).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fmctd_dist.config import Config
from fmctd_dist.families.maze.pointmaze import PointMaze
from fmctd_dist.families.maze.robots import ControllerFactory, controller_factory
from fmctd_dist.evaluation.plan_tally import PlanTally
from fmctd_dist.planners.base import Planner


def run_episode(cfg: Config, env: PointMaze, planner: Planner, task: int, seed: int,
                time_limit_s: float | None = None, make_controller: ControllerFactory | None = None) -> dict[str, Any]:
    """Run one episode and return its row (without the run-level provenance fields).

    ``make_controller`` (plan -> controller): pass one built once per env (the ant's loads a
    policy); default :func:`controller_factory` of ``cfg``.
    """
    make_controller = make_controller or controller_factory(cfg)
    tally = PlanTally.episode(cfg, task, seed, time_limit_s)
    reset = env.reset(task, seed)
    obs, goal = reset.obs, reset.goal
    pos = obs[:2]  # the planner's state: x, y (the ant's observation has 27 more features)
    traj = [pos]
    steps, success = 0, False
    while steps < cfg.env.max_steps and not success:
        out = tally.plan(planner, pos, goal)
        if out is None:
            break
        ctrl = make_controller(out.waypoints)
        for _ in range(min(cfg.method.replan_every or cfg.env.max_steps, cfg.env.max_steps - steps)):
            obs, success = env.step(ctrl.act(obs))
            pos = obs[:2]
            traj.append(pos)
            steps += 1
            if success:
                break
    return maze_row(tally, success, steps, tally.first, traj)


def maze_row(tally: PlanTally, success: bool, steps: int, plan_xy: Any, traj: list) -> dict[str, Any]:
    """The row of an episode moving a point in the maze plane (point, ant, visual point): the same columns,
    so grids, tables, plots and reports read any of them. ``plan_xy``: the first plan's (x, y) [N, 2]."""
    return {**tally.row(success, steps), "plan_xy": np.asarray(plan_xy, np.float32).reshape(-1).tolist(),
            "traj_xy": np.asarray(traj, np.float32).reshape(-1).tolist()}


STILL_STEPS = 200  # a robot whose last STILL_STEPS positions span less than STILL_RANGE stopped
STILL_RANGE = 1.0


def stood_still(traj_xy: Any) -> bool:
    """A row's executed x, y path [T, 2] (or flat) ends with the robot stopped: its last ``STILL_STEPS``
    positions span less than ``STILL_RANGE`` (a fallen ant never gets up; a robot can also push into a wall)."""
    traj = np.asarray(traj_xy, dtype=np.float64).reshape(-1, 2)
    return bool(len(traj) > STILL_STEPS and np.ptp(traj[-STILL_STEPS:], axis=0).max() < STILL_RANGE)
