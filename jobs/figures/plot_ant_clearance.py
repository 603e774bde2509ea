"""Figure: one AntMaze plan walked twice, as it is and kept off the walls (``env.wall_clearance``).

    python jobs/figures/plot_ant_clearance.py env=antmaze-large method.wall_guidance=1 tasks=[4] seeds=[2]

Plans once with the configured method (task and seed: the first of ``eval.tasks`` / ``eval.seeds``), in this
process, then walks the same plan with the ant at clearance 0 (the plan as is) and at the config's clearance
(the AntMaze default, 2). Left: the plan and the ant's path at 0, with the spot where the ant turned over;
right: the controller's copy of the plan and the ant's path. Written to ``docs/figures/ant_clearance_<env>.png``.
"""

from __future__ import annotations

import dataclasses

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from fmctd_dist.cli import run  # noqa: E402
from fmctd_dist.config import REPO_ROOT, load_config  # noqa: E402
from fmctd_dist.denoiser.local import LocalDenoiser  # noqa: E402
from fmctd_dist.device import set_threads  # noqa: E402
from fmctd_dist.diffusion.checkpoint import normaliser_from_manifest, read_manifest  # noqa: E402
from fmctd_dist.evaluation.plots import save_figure  # noqa: E402
from fmctd_dist.families import guide_map, plan_rules  # noqa: E402
from fmctd_dist.families.maze.antmaze import upright  # noqa: E402
from fmctd_dist.families.maze.clearance import keep_clear  # noqa: E402
from fmctd_dist.families.maze.geometry import maze_geometry  # noqa: E402
from fmctd_dist.families.maze.make import make_env  # noqa: E402
from fmctd_dist.families.maze.plots import draw_maze  # noqa: E402
from fmctd_dist.families.maze.robots import controller_factory  # noqa: E402
from fmctd_dist.planners import make_planner  # noqa: E402
from fmctd_dist.planners.base import plan_seed  # noqa: E402
from fmctd_dist.registry import require_family  # noqa: E402


def walk(env, make, plan: np.ndarray, task: int, seed: int, steps: int) -> tuple[np.ndarray, bool, int | None]:
    """The ant's path [T, 2], success, and the step it turned over (None if it stayed up)."""
    obs = env.reset(task, seed).obs
    ctrl, path, fell = make(plan), [obs[:2]], None
    for t in range(steps):
        obs, success = env.step(ctrl.act(obs))
        path.append(obs[:2])
        fell = t if fell is None and not upright(obs) else fell
        if success:
            return np.asarray(path), True, fell
    return np.asarray(path), False, fell


def main(argv: list[str]) -> int:
    cfg = load_config(argv, env="antmaze-large", method="fast-mctd")
    require_family(cfg.env.name, ("antmaze",), "jobs/figures/plot_ant_clearance.py")
    set_threads(cfg.eval.threads or 1)
    task, seed = int(cfg.eval.tasks[0]), int(cfg.eval.seeds[0])
    manifest = read_manifest(cfg.checkpoint_dir(), cfg)
    denoiser = LocalDenoiser.from_checkpoint(cfg.checkpoint_dir(), cfg, guide_map=guide_map(cfg.env.name))
    planner = make_planner(cfg, denoiser, normaliser_from_manifest(manifest), plan_rules(cfg))
    env, geo = make_env(cfg.env.name), maze_geometry(cfg.env.name)
    start, goal = env.reset(task, seed).obs[:2], geo.task(task).goal_xy
    plan = np.asarray(planner.plan(start, goal, plan_seed(cfg.seed, task, seed, 0)).waypoints)[:, :2]
    as_is = dataclasses.replace(cfg, env=dataclasses.replace(cfg.env, wall_clearance=0.0))
    clear = cfg.env.wall_clearance
    fig, axes = plt.subplots(1, 2, figsize=(10, 5 * geo.walls.shape[0] / geo.walls.shape[1]))
    for ax, c, c_cfg in zip(axes, (0.0, clear), (as_is, cfg)):
        path, success, fell = walk(env, controller_factory(c_cfg), plan, task, seed, cfg.env.max_steps)
        draw_maze(ax, geo)
        ax.plot(plan[:, 0], plan[:, 1], "--", color="tab:blue", lw=1.0, label="plan", zorder=3)
        if c:
            walked = keep_clear(plan, geo, c)
            ax.plot(walked[:, 0], walked[:, 1], ":", color="tab:purple", lw=1.5, label=f"copy {c:g} off the walls",
                    zorder=3)
        ax.plot(path[:, 0], path[:, 1], "-", color="tab:orange", lw=2.5, alpha=0.6, label="ant", zorder=2)
        if fell is not None:
            ax.plot(*path[fell + 1], "X", color="black", ms=10, label="turned over", zorder=4)
        ax.plot(*start, "o", color="tab:green", ms=8, label="start")
        ax.plot(*goal, "*", color="tab:red", ms=14, label="goal")
        ax.set_title(f"clearance {c:g}: {'success' if success else 'failure'} after {len(path) - 1} steps", fontsize=9)
        ax.legend(loc="best", fontsize=7, framealpha=0.8)
    fig.suptitle(f"{cfg.method.name} {cfg.env.name} task {task} seed {seed}: one plan, walked twice", fontsize=10)
    out = save_figure(fig, REPO_ROOT / "docs" / "figures" / f"ant_clearance_{cfg.env.name}.png")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    run(main)
