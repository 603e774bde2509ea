"""Baselines without search: Diffusion Forcing planner, and replanning cadence of the episode loop."""

import numpy as np

from fmctd_dist.config import load_config
from fmctd_dist.denoiser.local import LocalDenoiser
from fmctd_dist.diffusion.checkpoint import load_checkpoint, normaliser_from_manifest
from fmctd_dist.families import plan_rules
from fmctd_dist.families.maze.make import make_env
from fmctd_dist.families.maze.episode import run_episode
from fmctd_dist.planners import PlanOutput, make_planner
from fmctd_dist.diffusion.schedule import PyramidSchedule
from fmctd_dist.planners.fixed import FixedSchedulePlanner


class CountingPlanner:
    """Plans 'stay where you are' and counts the calls."""

    def __init__(self):
        self.calls = []

    def plan(self, start, goal, seed):
        self.calls.append(np.array(start))
        return PlanOutput(np.repeat(np.asarray(start)[None], 500, 0), "plan", 0.01, 0.0)


def test_replanning_every_50_steps():
    cfg = load_config(["method=diffusion-forcing", "env.max_steps=200", "env.horizon=200", "data.train_window=200"])
    planner = CountingPlanner()
    row = run_episode(cfg, make_env(cfg.env.name), planner, task=1, seed=0)
    assert row["env_steps"] == 200 and row["plans"] == 4 and len(planner.calls) == 4
    open_loop = load_config(["method=mctd", "env.max_steps=200", "env.horizon=200", "data.train_window=200"])
    planner = CountingPlanner()
    run_episode(open_loop, make_env(cfg.env.name), planner, task=1, seed=0)
    assert len(planner.calls) == 1


def test_diffusion_forcing_planner(tiny_checkpoint, one_torch_thread):
    args, ckpt = tiny_checkpoint
    cfg = load_config(args + ["method=diffusion-forcing"])  # args hold jump=1
    model, manifest = load_checkpoint(ckpt, cfg)
    denoiser = LocalDenoiser(model, cfg.diffusion, "cpu", micro_batch=4)
    planner = make_planner(cfg, denoiser, normaliser_from_manifest(manifest), plan_rules(cfg))
    assert isinstance(planner, FixedSchedulePlanner)
    assert np.array_equal(planner.levels, PyramidSchedule(cfg.plan_tokens, cfg.diffusion.levels).full())
    a = planner.plan(np.zeros(2), np.array([20.0, 20.0]), seed=3)
    b = planner.plan(np.zeros(2), np.array([20.0, 20.0]), seed=3)
    c = planner.plan(np.zeros(2), np.array([20.0, 20.0]), seed=4)
    assert a.waypoints.shape == (100, 2) and np.array_equal(a.waypoints, b.waypoints)
    assert not np.array_equal(a.waypoints, c.waypoints)
    assert a.denoise_calls == 1 and 0 < a.denoise_time_s <= a.plan_time_s
