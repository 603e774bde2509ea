"""AntMaze episodes with ideal plans: how far the ant's controller gets when the plan is perfect.

    python jobs/probes/ant_ideal_plans.py env=antmaze-large
    python jobs/probes/ant_ideal_plans.py env=antmaze-giant 'seeds=[0,1]' probe.speed=0.5 probe.corner=0

The planner is replaced by the BFS cell path from the start to the goal (OGBench's oracle:
cell centres, the goal appended), its corners rounded by ``probe.corner`` world units (0 = sharp),
walked at ``probe.speed`` world units per env step (default: the mean step of the maze's data).
Everything else is the evaluation's maze episode (``families/maze/episode.py``: subgoal tracker,
the low-level policy of ``env.policy``, ``env.max_steps``). A failure here is the controller's,
not the diffusion model's: this is the ceiling any planner on our ant policy can reach, which
the AntMaze failure analysis needs to tell plan errors from walking errors. Prints one line per
episode (steps, closest approach, whether the ant stood still or fell) and a success count; writes nothing.
"""

from __future__ import annotations

import numpy as np

from fmctd_dist.cli import run
from fmctd_dist.config import load_config
from fmctd_dist.families.maze.episode import run_episode, stood_still
from fmctd_dist.families.maze.geometry import MazeGeometry, maze_geometry
from fmctd_dist.families.maze.make import make_env
from fmctd_dist.families.maze.robots import controller_factory
from fmctd_dist.planners.base import PlanOutput
from fmctd_dist.registry import require_family

DATA_SPEED = 0.14  # world units per env step: the mean step of our AntMaze plans (0.13-0.14), which follow the data


def cell_path(geo: MazeGeometry, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """[K, 2] start, the BFS cell centres to the goal's cell, the goal."""
    ij, goal_ij = geo.xy_to_cell(start), geo.xy_to_cell(goal)
    points = [np.asarray(start, np.float64)]
    while ij != goal_ij:
        nxt = geo.next_cell(ij, goal_ij)
        if nxt == ij:
            raise ValueError(f"no free path from cell {ij} to {goal_ij}")
        ij = nxt
        points.append(geo.cell_to_xy(ij))
    points.append(np.asarray(goal, np.float64))
    return np.asarray(points)


def round_corners(path: np.ndarray, corner: float) -> np.ndarray:
    """Replace each interior vertex by a quadratic Bezier from ``corner`` before it to ``corner`` after it."""
    if corner <= 0 or len(path) < 3:
        return path
    out = [path[0]]
    for a, b, c in zip(path[:-2], path[1:-1], path[2:]):
        u = (a - b) / max(np.linalg.norm(a - b), 1e-9)
        v = (c - b) / max(np.linalg.norm(c - b), 1e-9)
        p0 = b + u * min(corner, 0.5 * np.linalg.norm(a - b))
        p2 = b + v * min(corner, 0.5 * np.linalg.norm(c - b))
        s = np.linspace(0, 1, 9)[:, None]
        out.extend((1 - s) ** 2 * p0 + 2 * s * (1 - s) * b + s ** 2 * p2)
    out.append(path[-1])
    return np.asarray(out)


def resample(path: np.ndarray, speed: float) -> np.ndarray:
    """[K, 2] polyline -> [F, 2] points ``speed`` apart along it (the last point repeated to the end)."""
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    at = np.arange(0.0, s[-1] + speed, speed).clip(max=s[-1])
    return np.stack([np.interp(at, s, path[:, k]) for k in range(2)], axis=1)


class IdealPlanner:
    """The plan of the module docstring (no model, no search)."""

    def __init__(self, geo: MazeGeometry, speed: float, corner: float):
        self.geo, self.speed, self.corner = geo, speed, corner

    def plan(self, start: np.ndarray, goal: np.ndarray, seed: int) -> PlanOutput:
        path = round_corners(cell_path(self.geo, start[:2], goal[:2]), self.corner)
        return PlanOutput(resample(path, self.speed).astype(np.float32), "plan", 0.0, 0.0)


def main(argv: list[str]) -> int:
    speed, corner = DATA_SPEED, 1.0
    rest = []
    for a in argv:  # probe.* are this script's own words; the rest is the evaluation's config
        if a.startswith("probe.speed="):
            speed = float(a.split("=", 1)[1])
        elif a.startswith("probe.corner="):
            corner = float(a.split("=", 1)[1])
        else:
            rest.append(a)
    cfg = load_config(rest, env="antmaze-large", method="fast-mctd")
    require_family(cfg.env.name, ("antmaze",), "jobs/probes/ant_ideal_plans.py")
    geo, env = maze_geometry(cfg.env.name), make_env(cfg.env.name)
    planner, make_controller = IdealPlanner(geo, speed, corner), controller_factory(cfg)
    print(f"{cfg.env.name}: ideal plans at {speed} units/step, corners rounded by {corner}; "
          f"{cfg.env.max_steps} steps")
    wins = total = 0
    for task in cfg.eval.tasks:
        for seed in cfg.eval.seeds:
            row = run_episode(cfg, env, planner, task, seed, make_controller=make_controller)
            traj = np.asarray(row["traj_xy"]).reshape(-1, 2)
            goal = geo.task(task).goal_xy
            wins, total = wins + row["success"], total + 1
            print(f"  task {task} seed {seed}: {'success' if row['success'] else 'FAIL'} in {row['env_steps']} steps, "
                  f"plan {len(row['plan_xy']) // 2} steps, closest {np.linalg.norm(traj - goal, axis=1).min():.2f}"
                  f"{', stood still' if stood_still(traj) and not row['success'] else ''}", flush=True)
    print(f"{cfg.env.name}: {wins} of {total} episodes reached the goal ({100 * wins / max(total, 1):.0f}%)")
    return 0


if __name__ == "__main__":
    run(main)
