"""Visual maze episodes with ideal latent plans instead of a model: is the failure the planner's or the controller's?

    python jobs/probes/visual_ideal_plans.py env=visual-pointmaze-medium               # tasks 1-5, seed 0
    python jobs/probes/visual_ideal_plans.py env=visual-pointmaze-medium jump=1 tasks=[1]

The "plan" of each call is the BFS cell path from the task's start cell to its goal cell at the
point's speed (0.2 per step, as ``jobs/figures/plot_visual_frames.py`` draws it), rendered and encoded by
the VAE: on the latent manifold by construction. It is cut every ``jump`` steps and held ``jump``
steps per frame, as a sparse plan is, then run by the visual episode (chase-camera frames, VAE,
inverse dynamics toward the latents, ``families/visual/episode.py``) with nothing else changed.
Prints one line per episode and the success count.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from fmctd_dist.cli import run
from fmctd_dist.config import load_config
from fmctd_dist.planners.base import repeat_waypoints
from fmctd_dist.device import set_threads
from fmctd_dist.families.maze.geometry import maze_geometry
from fmctd_dist.families.visual.env import point_env_name, render_states
from fmctd_dist.families import hooks_for
from fmctd_dist.planners.base import PlanOutput


class IdealLatentPlanner:
    """plan(z, z_goal) -> the encoded BFS path of the current task (the episode sets ``task`` first)."""

    def __init__(self, cfg, encode):
        self.cfg, self.encode = cfg, encode
        self.geo = maze_geometry(point_env_name(cfg.env.name))
        self.task = 1

    def path(self) -> np.ndarray:
        task = self.geo.task(self.task)
        cells = [task.init_ij]
        while cells[-1] != task.goal_ij:
            cells.append(self.geo.next_cell(cells[-1], task.goal_ij))
        centres = np.array([self.geo.cell_to_xy(c) for c in cells])
        pts = [np.linspace(a, b, 20, endpoint=False) for a, b in zip(centres[:-1], centres[1:])]
        return np.concatenate(pts + [centres[-1:]])

    def plan(self, start, goal, seed) -> PlanOutput:
        xy = self.path()[1:]  # [F, 2] step 1 onwards
        h = self.cfg.jump
        sparse = np.concatenate([xy[h - 1::h], xy[-1:]])  # frames at steps h, 2h, ..., and the goal
        z = self.encode(render_states(self.cfg.env.name, sparse, shadowsize=self.cfg.visual.shadowsize))
        return PlanOutput(repeat_waypoints(z, h), "ideal", 0.0, 0.0)


def main(argv: list[str]) -> int:
    cfg = load_config(argv, env="visual-pointmaze-medium", method="fast-mctd")
    set_threads(cfg.eval.threads or 1)
    # the parts are checked against the shipped H=5 planner (its VAE); the episode then runs at cfg.jump
    episodes = hooks_for(cfg.env.name).episodes(dataclasses.replace(cfg, jump=5))
    episodes.cfg = cfg
    planner = IdealLatentPlanner(cfg, episodes.vae.encode)
    wins = 0
    for task in cfg.eval.tasks:
        for seed in cfg.eval.seeds[:1]:
            planner.task = task
            row = episodes.run(planner, task, seed)
            end = np.asarray(row["traj_xy"]).reshape(-1, 2)[-1]
            wins += row["success"]
            print(f"task {task} seed {seed}: {'success' if row['success'] else 'failure'} after {row['env_steps']} "
                  f"steps; ends at {end.round(2).tolist()}, goal {episodes.env.goal.round(2).tolist()}")
    print(f"ideal latent plans, jump={cfg.jump}: {wins}/{len(cfg.eval.tasks)} solved")
    return 0


if __name__ == "__main__":
    run(main)
