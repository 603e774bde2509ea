"""Reach rate: can a controller walk the ant from a held-out state to the point it reached 10 steps later?

This is the low-level half of AntMaze planning in isolation. For N val rows (seeded), the
ant's full MuJoCo state is restored from the row's 29-D observation (qpos + qvel; replaying
the row's own torques reproduces the data to ~1e-6), the subgoal is the same episode's
x, y ``offset`` steps later (the controller's subgoal interval), and the controller gets
``max_steps`` env steps. Reached = within ``radius`` (the controller's advance radius)
after some step. Also reported: steps to reach, falls, the start distance (~1 m: about
half the tries start within the radius, so ``reach_rate_0.5``, the OGBench success radius,
is the sharper number) and the fraction already inside at the start.

The reference controller is the ant expert steered at the subgoal: direction =
unit(subgoal - x, y), the same input it made the data with (where the direction pointed at
the BFS oracle's next cell). Rows are only taken where the ant is upright at t and stays so
up to t + offset (a fallen ant's subgoal says nothing). Deterministic given the seed.

The restored state keeps the row's velocity, and at the data's 1.25 m/s the ant coasts a
good part of the ~1 m: zero torques "reach" most radius-1.0 subgoals (measured 80% on
antmaze-medium val), so :func:`zero_controller` is reported beside the others as the floor.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from fmctd_dist.families.maze.ant_policy_rows import PolicyRows
from fmctd_dist.device import torch_threads
from fmctd_dist.families.maze.antmaze import ACT_DIM, AntMaze, healthy, upright

if TYPE_CHECKING:
    from fmctd_dist.families.maze.expert.expert import AntExpert

Controller = Callable[[np.ndarray, np.ndarray], np.ndarray]  # (obs [29], subgoal [2]) -> torques [8]
OGBENCH_RADIUS = 0.5
ROW_STREAM = 7  # SeedSequence([reach.seed, ROW_STREAM]) picks the rows


def reach_rows(rows: PolicyRows, n: int, offset: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Up to n (row, row + offset) index pairs, drawn without replacement; the ant is upright over the whole span."""
    up = healthy(rows.obs) & upright(rows.obs)
    idx = np.arange(len(rows.obs), dtype=np.int64)
    # the span stays in one run of upright rows (runs never cross episodes): end of run of i >= i + offset
    ok = up & (rows.end >= idx + offset) & (idx + offset < len(idx))
    if not ok.any():
        raise ValueError(f"no val row has {offset} upright steps after it; lower reach.offset or use more val data")
    cands = idx[ok]
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, ROW_STREAM])))
    pick = np.sort(rng.choice(cands, size=min(n, cands.size), replace=False))
    return pick, pick + offset


def zero_controller(obs: np.ndarray, subgoal: np.ndarray) -> np.ndarray:
    """No torques: how far the restored velocity alone carries the ant (the floor any controller must beat)."""
    return np.zeros(ACT_DIM)


def expert_controller(expert: AntExpert) -> Controller:
    """The ant expert as a subgoal follower: direction = unit(subgoal - x, y)."""
    from fmctd_dist.families.maze.expert.direction_env import expert_input

    return lambda obs, subgoal: expert.act(expert_input(obs, np.asarray(subgoal) - np.asarray(obs)[:2]))


def reach_rate(env: AntMaze, controller: Controller, rows: PolicyRows, pairs: tuple[np.ndarray, np.ndarray],
               max_steps: int, radius: float) -> dict[str, Any]:
    """Try every (row, subgoal row) pair for ``max_steps`` env steps; aggregate metrics (see module doc)."""
    starts, targets = pairs
    first = {radius: [], OGBENCH_RADIUS: []}  # first step within each radius, or None
    fell, d0, dmin = [], [], []
    with torch_threads(1):
        for i, j in zip(starts, targets):
            ob = env.restore(rows.obs[i].astype(np.float64))
            goal = rows.obs[j, :2].astype(np.float64)
            d0.append(float(np.linalg.norm(ob[:2] - goal)))
            hit: dict[float, int | None] = {r: None for r in first}
            down, best = False, d0[-1]
            for s in range(1, max_steps + 1):
                ob, _ = env.step(controller(ob, goal))
                d = float(np.linalg.norm(ob[:2] - goal))
                best = min(best, d)
                for r in hit:
                    if hit[r] is None and d < r:
                        hit[r] = s
                if not (healthy(ob) and upright(ob)):
                    down = True
                    break
            for r in first:
                first[r].append(hit[r])
            fell.append(down)
            dmin.append(best)
    n = len(starts)
    reached = [s for s in first[radius] if s is not None]
    d0a = np.asarray(d0)
    return {
        "tries": n,
        "reach_rate": len(reached) / max(n, 1),
        "mean_steps_to_reach": float(np.mean(reached)) if reached else None,
        "fall_rate": float(np.mean(fell)) if n else 0.0,
        "reach_rate_0.5": sum(s is not None for s in first[OGBENCH_RADIUS]) / max(n, 1),
        "mean_subgoal_dist": float(d0a.mean()) if n else None,
        "start_within_radius": float((d0a < radius).mean()) if n else None,
        "mean_min_dist": float(np.mean(dmin)) if n else None,
        "radius": radius,
        "max_steps": max_steps,
    }


def evaluate_reach(env_name: str, controllers: dict[str, Controller], rows: PolicyRows, n: int, offset: int,
                   max_steps: int, radius: float, seed: int) -> dict[str, dict[str, Any]]:
    """The same seeded tries for each named controller, on one AntMaze env."""
    pairs = reach_rows(rows, n, offset, seed)
    env = AntMaze(env_name)
    env.reset(1, seed=0)  # builds MuJoCo's state once; every try then restores its own
    try:
        out = {}
        for name, ctrl in controllers.items():
            out[name] = {**reach_rate(env, ctrl, rows, pairs, max_steps, radius), "offset": offset, "seed": seed}
        return out
    finally:
        env.close()


def format_reach(name: str, r: dict[str, Any]) -> str:
    """One line of a reach result (job output)."""
    steps = "-" if r["mean_steps_to_reach"] is None else f"{r['mean_steps_to_reach']:.1f}"
    return (f"  {name:7s} reach {r['reach_rate']:.1%} (within {r['radius']} in {r['max_steps']} steps), "
            f"mean steps {steps}, falls {r['fall_rate']:.1%}, reach@0.5 {r['reach_rate_0.5']:.1%}; "
            f"{r['tries']} val rows, start dist {r['mean_subgoal_dist']:.2f}, "
            f"{r['start_within_radius']:.0%} start within {r['radius']}")
