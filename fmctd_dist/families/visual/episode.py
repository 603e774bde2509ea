"""One visual maze episode: see the chase camera's frame, plan in latents, act with the inverse dynamics.

At every step the env renders the 64x64 chase-camera frame and the VAE encodes it (mu); the
planner plans from that latent to the goal frame's latent (OGBench's ``render_goal``: the frame at
the goal), and :class:`~fmctd_dist.families.visual.latent_path.LatentPathController` acts toward the
planned path, replanning every ``method.replan_every`` env steps (0 = open loop). The robot's
true position is used only for success (OGBench's: within 1.0 of the goal) and the row's
trajectory. ``plan_xy`` is the first plan's positions (the figure's plan). ``frames`` maps latents to
the planner's frames (``visual/frames_xy.py``: the latent, or with ``visual.plan_xy`` the latent and
its estimated (x, y)) and planner frames to world (x, y); the controller follows the plan's latents.

Same row columns as the maze's episode (:func:`fmctd_dist.families.maze.episode.run_episode`), so
grids, tables and reports read either.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from fmctd_dist.config import Config
from fmctd_dist.families.visual.latent_path import InverseDynamics, LatentPathController
from fmctd_dist.families.maze.episode import maze_row
from fmctd_dist.evaluation.plan_tally import PlanTally
from fmctd_dist.planners.base import Planner
from fmctd_dist.families.visual.frames_xy import PlanFrames

Encoder = Callable[[np.ndarray], np.ndarray]  # uint8 [N, 64, 64, 3] -> mu [N, D]


def run_visual_episode(cfg: Config, env: Any, encode: Encoder, invdyn: InverseDynamics, frames: PlanFrames,
                       planner: Planner, task: int, seed: int, time_limit_s: float | None = None) -> dict[str, Any]:
    """Run one episode of ``env`` (a :class:`~fmctd_dist.families.visual.env.VisualPointMaze`); its row."""
    tally = PlanTally.episode(cfg, task, seed, time_limit_s)
    reset = env.reset(task, seed)
    pos = reset.obs[:2]
    z = encode(env.image()[None])[0]
    z_goal = encode(env.goal_image()[None])[0]
    z_prev = z
    traj = [pos]
    steps, success = 0, False
    while steps < cfg.env.max_steps and not success:
        out = tally.plan(planner, frames.of_latents(z), frames.of_latents(z_goal))
        if out is None:
            break
        ctrl = LatentPathController(frames.latents(out.waypoints), cfg.jump, invdyn, z)
        for _ in range(min(cfg.method.replan_every or cfg.env.max_steps, cfg.env.max_steps - steps)):
            pos, success = env.step(ctrl.act(z_prev, z))
            z_prev, z = z, encode(env.image()[None])[0]
            traj.append(pos)
            steps += 1
            if success:
                break
    plan_xy = frames(np.asarray(tally.first)) if tally.first is not None else np.zeros((0, 2))
    return {**maze_row(tally, success, steps, plan_xy, traj),
            "goal_xy_estimate_error": float(np.linalg.norm(frames.estimator(z_goal) - env.goal))}
