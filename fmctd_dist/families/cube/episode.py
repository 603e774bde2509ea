"""One cube episode (docs/reference.md §13): plan cube paths, script the arm between segments, let the policy carry.

Per segment:
1. plan from the current cube xyz [3N] (obs units) to the goal;
2. the target cube = the unsolved cube whose planned path is longest (kept while it is carried);
3. on a new segment (the first plan, after a release, or when the target changes) the scripted
   pre-position: ~30 steps moving the open gripper above the target's first planned position (and, with
   ``env.preposition_yaw``, turning it to the target cube's yaw);
4. the low-level policy carries the target: its subgoal is the target's planned position 10
   steps ahead, advanced when the cube comes within 1.0 (:class:`control.subgoal.SubgoalTracker`);
5. when the target is within 0.2 of its goal the scripted release (10 steps lift while opening,
   20 steps away in +x) ends the segment; so does reaching the plan's end, or, for methods that
   replan, ``env.replan_every`` policy steps (``method.replan_every`` when that is 0).
Stops at OGBench's success (every cube within 0.04 m of its goal) or ``env.max_steps``. Like the
maze episode, a pure function of (config, checkpoints, task, seed).
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from fmctd_dist.config import Config
from fmctd_dist.families.cube.scripts import EFFECTOR, PrePosition, Release
from fmctd_dist.families.cube.policy import cube_view
from fmctd_dist.families.maze.subgoal import SubgoalTracker
from fmctd_dist.families.cube.env import CubeEpisodes
from fmctd_dist.families.cube.failures import on_cube, why_failed
from fmctd_dist.evaluation.plan_tally import PlanTally
from fmctd_dist.planners.base import Planner
from fmctd_dist.families.cube.value import CubeValue

CubePolicy = Callable[[np.ndarray, np.ndarray], np.ndarray]  # (view [28], subgoal [3]) -> action [5]

RELEASE_RADIUS = 0.2  # obs units: the target this close to its goal is released
SUBGOAL_AHEAD = 10  # env steps of plan between the cube and its subgoal
SUBGOAL_RADIUS = 1.0  # obs units: the subgoal advances when the cube is this close
CARRY_Z = 0.2 + 0.2  # obs units: the target above this (2 cm off the table), not on a cube, is being carried


def choose_target(plan: np.ndarray, state: np.ndarray, unsolved: list[int]) -> int:
    """The unsolved cube whose planned path (from ``state`` [N, 3] through ``plan`` [F, N, 3]) is longest."""
    path = np.concatenate([state[None], plan])  # [F+1, N, 3]
    length = np.linalg.norm(np.diff(path, axis=0), axis=-1).sum(0)  # [N]
    return int(max(unsolved, key=lambda i: (length[i], -i)))


def targets_left(rules: CubeValue, state: np.ndarray, goal: np.ndarray) -> list[int]:
    """Cubes to carry: unsolved by the value's rules and not already released within RELEASE_RADIUS of their goal
    (a cube let go there is left alone rather than picked up and released again); else every unsolved cube."""
    unsolved = rules.unsolved(state, goal) or list(range(len(goal) // 3))
    far = np.linalg.norm((state - goal).reshape(-1, 3), axis=1) >= RELEASE_RADIUS
    return [i for i in unsolved if far[i]] or unsolved


def replan_interval(cfg: Config) -> int:
    """Policy steps per plan for methods that replan (0 = follow each plan to its end)."""
    if cfg.method.replan_every <= 0:
        return 0
    return cfg.env.replan_every or cfg.method.replan_every


def run_cube_episode(cfg: Config, env: CubeEpisodes, planner: Planner, policy: CubePolicy, task: int, seed: int,
                     time_limit_s: float | None = None) -> dict[str, Any]:
    """Run one episode; return its row (without the run-level provenance fields)."""
    tally = PlanTally.episode(cfg, task, seed, time_limit_s)
    reset = env.reset(task, seed)
    obs, goal, n = reset.obs, reset.goal, env.n_cubes
    goal_c = goal.reshape(n, 3)
    rules = CubeValue()
    every = replan_interval(cfg)
    cubes, effector, targets = [env.state(obs)], [obs[EFFECTOR]], []
    steps, success = 0, False
    releases, chosen = 0, []
    last_target = -1

    def step(action: np.ndarray, target: int) -> None:
        nonlocal obs, success, steps
        obs, success = env.step(action)
        steps += 1
        cubes.append(env.state(obs))
        effector.append(obs[EFFECTOR])
        targets.append(target)

    def script(motion: PrePosition | Release) -> None:
        for k in range(motion.steps):
            if success or steps >= cfg.env.max_steps:
                return
            step(motion.act(obs, k), -1)

    while steps < cfg.env.max_steps and not success:
        state = env.state(obs)
        out = tally.plan(planner, state, goal)
        if out is None:
            break
        plan = np.asarray(out.waypoints, np.float64).reshape(-1, n, 3)  # [F, N, 3] one per env step
        cubes_now = state.reshape(n, 3)
        carrying = (last_target >= 0 and cubes_now[last_target, 2] > CARRY_Z
                    and not on_cube(cubes_now[None])[0, last_target])
        # a cube in the gripper stays the target: switching would open the gripper mid-air (the pre-position)
        target = last_target if carrying else choose_target(plan, cubes_now, targets_left(rules, state, goal))
        chosen.append(target)
        if target != last_target:
            script(PrePosition(plan[0, target], turn_to=target if cfg.env.preposition_yaw else None))
            last_target = target
        tracker = SubgoalTracker(plan[:, target], SUBGOAL_AHEAD, SUBGOAL_RADIUS, dim=3)
        k = 0
        while not success and steps < cfg.env.max_steps and (every == 0 or k < every):
            cube = env.state(obs).reshape(n, 3)[target]
            if k > 0 and np.linalg.norm(cube - goal_c[target]) < RELEASE_RADIUS:
                script(Release())
                releases += 1
                last_target = -1  # the next segment starts with a pre-position
                break
            subgoal = tracker.update(cube)
            if tracker.done and np.linalg.norm(cube - subgoal) < SUBGOAL_RADIUS and k >= SUBGOAL_AHEAD:
                break  # the plan is used up without a placement: plan the next segment
            step(np.asarray(policy(cube_view(obs, target), subgoal), np.float64), target)
            k += 1
    traj = np.asarray(cubes, np.float32)  # [T+1, 3N]
    row = tally.row(success, steps)
    return {
        **row,
        "n_cubes": n,
        "targets": ",".join(str(t) for t in chosen),  # the target cube of each plan
        "releases": releases,
        "why_failed": why_failed(traj.reshape(-1, n, 3), np.asarray(targets, np.int64), goal_c, row["success"],
                                 tally.timed_out),
        "goal_cubes": goal.astype(np.float32).tolist(),  # [3N]
        "plan_cubes": np.asarray(tally.first, np.float32).reshape(-1).tolist(),  # [F * 3N], the first plan
        "traj_cubes": traj.reshape(-1).tolist(),  # [(T+1) * 3N] cube xyz per step, obs units
        "traj_effector": np.asarray(effector, np.float32).reshape(-1).tolist(),  # [(T+1) * 3]
    }
