"""Plan-level success on validation start/goal pairs of a maze (not its five evaluation tasks), per config.

For choosing a planner setting without looking at the evaluation tasks (e.g. ``method.wall_guidance``): each
config plans once from each of N random pairs of free cells (seeded; the tasks' own pairs are left out, both
ways round; BFS distance at least half the tasks' shortest) and the plan counts as a success when it is valid
(no step over ``method.warp_threshold``, no step through a wall) and comes within ``method.goal_radius`` of the
goal (the warp test stops at the first waypoint within the radius, as the value's does). No robot runs: this
scores what the search hands the controller.

    python jobs/probes/validation_plans.py env=antmaze-large method=fast-mctd pairs=20 \
        'settings=[method.wall_guidance=0, method.wall_guidance=1 method.wall_margin=1]'   # words of a setting: spaces

On the visual maze (``env=visual-pointmaze-medium``) the planner plans between the encoded chase-camera
frames at the start and the goal, as an episode does, and the plan's world path is its own (x, y) with
``visual.plan_xy`` or the position estimator's reading of its latents otherwise; the start of that path is
the planner's own reading of the start frame (what the value tests), the goal the true one.

On AntMaze, ``clearances=[0,1.5]`` also walks each plan with the ant (its low-level policy, ``env.max_steps``
steps, the controller's copy of the plan kept ``env.wall_clearance`` off the walls) and adds the share of
ants that reached the goal per clearance: the plan is made once and walked once per clearance, so the
columns differ by the controller alone.
"""

from __future__ import annotations

import time

import numpy as np

from fmctd_dist.cli import run
from fmctd_dist.config import Config, is_ant, load_config
from fmctd_dist.denoiser.local import LocalDenoiser
from fmctd_dist.diffusion.checkpoint import normaliser_from_manifest, read_manifest
from fmctd_dist.errors import ConfigError
from fmctd_dist.families import guide_map, hooks_for
from fmctd_dist.family import warp_threshold
from fmctd_dist.families.maze.antmaze import AntMaze
from fmctd_dist.families.maze.geometry import MazeGeometry, maze_geometry
from fmctd_dist.families.maze.make import make_env
from fmctd_dist.families.maze.robots import Controller, controller_factory
from fmctd_dist.planners.base import plan_seed
from fmctd_dist.planners.factory import make_planner
from fmctd_dist.registry import family

VISUAL = "visual-pointmaze"


class MazeEnds:
    """A maze planner's ends are the cells' (x, y), and its plan is its world path."""

    def __init__(self, cfg: Config):
        manifest = read_manifest(cfg.checkpoint_dir())
        denoiser = LocalDenoiser.from_checkpoint(cfg.checkpoint_dir(), cfg, guide_map=guide_map(cfg.env.name))
        self.planner = make_planner(cfg, denoiser, normaliser_from_manifest(manifest),
                                    hooks_for(cfg.env.name).plan_rules(cfg))

    def frame(self, xy: np.ndarray) -> np.ndarray:
        return xy

    def world(self, frames: np.ndarray) -> np.ndarray:
        return np.asarray(frames)


class VisualEnds:
    """A visual planner's ends are the encoded frames the chase camera sees there, as in an episode."""

    def __init__(self, cfg: Config):
        from visual_plan_quality import visual_planner  # this folder's probe: the planner and parts an episode uses

        self.planner, self.parts, _, _ = visual_planner(cfg)

    def frame(self, xy: np.ndarray) -> np.ndarray:
        image = self.parts.env.frames.render(np.asarray(xy, np.float64)[None])
        return self.parts.frames.of_latents(self.parts.vae.encode(image)[0])

    def world(self, frames: np.ndarray) -> np.ndarray:
        return self.parts.frames(frames)


def validation_pairs(geo: MazeGeometry, n: int, seed: int = 0) -> list[tuple[tuple[int, int], tuple[int, int]]]:
    """n (start cell, goal cell) pairs: free cells, not an evaluation task either way round, and at least half
    as far apart (BFS) as the closest task."""
    tasks = {(t.init_ij, t.goal_ij) for t in geo.tasks} | {(t.goal_ij, t.init_ij) for t in geo.tasks}
    near = min(int(geo.bfs(t.goal_ij)[t.init_ij]) for t in geo.tasks) // 2
    cells = geo.free_cells()
    rng = np.random.default_rng(seed)
    out: list[tuple[tuple[int, int], tuple[int, int]]] = []
    while len(out) < n:
        a, b = (cells[i] for i in rng.choice(len(cells), 2, replace=False))
        if (a, b) not in tasks and geo.bfs(b)[a] >= near:
            out.append((a, b))
    return out


def plan_success(waypoints: np.ndarray, start: np.ndarray, goal: np.ndarray, jump: int, warp: float,
                 radius: float, geo: MazeGeometry) -> tuple[bool, bool]:
    """(valid, reaches) of one plan, as the value reads it plus the wall test: its coarse path from the start
    up to the first waypoint within ``radius`` of the goal (all of it if none) has no step over ``warp``, and
    that path, with the step on to the goal the planner appends, crosses no wall."""
    coarse = np.asarray(waypoints)[::jump, :2]
    if len(coarse) == 0:
        return False, False
    near = np.linalg.norm(coarse - goal, axis=-1) < radius
    head = coarse[: int(near.argmax()) + 1] if near.any() else coarse
    path = np.concatenate([start[None], head])
    no_warp = np.linalg.norm(np.diff(path, axis=0), axis=-1).max() <= warp
    walk = np.concatenate([path, goal[None]]) if near.any() else path
    return bool(no_warp and geo.path_in_free(walk)), bool(near.any())


def walk(env: AntMaze, ctrl: Controller, start: np.ndarray, goal: np.ndarray, seed: int, steps: int) -> bool:
    """The ant from ``start`` (reset noise from ``seed``) follows ``ctrl`` for up to ``steps``: reached ``goal``?"""
    obs = env.reset_to(start, goal, seed)
    for _ in range(steps):
        obs, success = env.step(ctrl.act(obs))
        if success:
            return True
    return False


def main(argv: list[str]) -> int:
    opts = {"env": "antmaze-large", "method": "fast-mctd", "pairs": "20", "seed": "0", "settings": "[]",
            "clearances": "[]"}
    for a in argv:
        key, sep, value = a.partition("=")
        if not sep or key not in opts:
            raise ConfigError(f"validation_plans: unknown argument {a!r}; expected any of {', '.join(opts)}")
        opts[key] = value
    settings = [s.strip() for s in opts["settings"].strip("[]").split(",") if s.strip()] or [""]
    clearances = [float(c) for c in opts["clearances"].strip("[]").split(",") if c.strip()]
    if clearances and not is_ant(opts["env"]):
        raise ConfigError(f"validation_plans: clearances={opts['clearances']} walks the plans with the ant; "
                          f"env={opts['env']} is not an AntMaze. Drop clearances")
    visual = family(opts["env"]) == VISUAL
    if visual:
        from fmctd_dist.families.visual.env import point_env_name
    geo = maze_geometry(point_env_name(opts["env"]) if visual else opts["env"])
    pairs = validation_pairs(geo, int(opts["pairs"]), int(opts["seed"]))
    print(f"{opts['env']} {opts['method']}: {len(pairs)} validation pairs (seed {opts['seed']})", flush=True)
    walked = "".join(f" ant reached, clearance {c:g} |" for c in clearances)
    print(f"| setting | valid and reaching | valid | reaching | plan s (mean) |{walked}\n"
          f"|---|---|---|---|---|{'---|' * len(clearances)}")
    env = make_env(opts["env"]) if clearances else None
    walkers = [controller_factory(load_config([f"env={opts['env']}", f"env.wall_clearance={c}"])) for c in clearances]
    for setting in settings:
        cfg = load_config([f"env={opts['env']}", f"method={opts['method']}", "eval.threads=1"] + setting.split())
        ends = VisualEnds(cfg) if visual else MazeEnds(cfg)
        tally, reached, seconds = [], np.zeros(len(clearances)), 0.0
        for k, (a, b) in enumerate(pairs):
            start, goal = geo.cell_to_xy(a), geo.cell_to_xy(b)
            first, last = ends.frame(start), ends.frame(goal)
            t0 = time.perf_counter()
            out = ends.planner.plan(first, last, plan_seed(cfg.seed, 1000 + k))
            seconds += time.perf_counter() - t0
            tally.append(plan_success(ends.world(out.waypoints), ends.world(first), goal, cfg.jump,
                                      warp_threshold(cfg), cfg.method.goal_radius, geo))
            for i, make in enumerate(walkers):
                reached[i] += walk(env, make(out.waypoints), start, goal, k, cfg.env.max_steps)
        v, r = np.array(tally).T
        cells = "".join(f" {n / len(pairs):.0%} |" for n in reached)
        print(f"| {setting or 'default'} | {np.mean(v & r):.0%} ({int((v & r).sum())}/{len(pairs)}) | {v.mean():.0%} | "
              f"{r.mean():.0%} | {seconds / len(pairs):.1f} |{cells}", flush=True)
    return 0


if __name__ == "__main__":
    run(main)
