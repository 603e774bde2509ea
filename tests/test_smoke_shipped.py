"""End to end with shipped checkpoints: Fast-MCTD solves PointMaze-medium and AntMaze-medium task 1,
seed 0, on CPU; the shipped Diffuser's plan for that task is warp-free."""

import numpy as np
import pytest
from conftest import torch_threads

from fmctd_dist.config import load_config
from fmctd_dist.denoiser.local import LocalDenoiser
from fmctd_dist.diffusion.checkpoint import load_checkpoint, normaliser_from_manifest
from fmctd_dist.envs import make_env
from fmctd_dist.evaluation.episode import run_episode
from fmctd_dist.planners import make_planner


def shipped_fast_mctd_episode(env: str, task: int = 1, seed: int = 0) -> dict:
    """One Fast-MCTD episode in process with the shipped checkpoint (and, for the ant, the shipped policy)."""
    cfg = load_config(["method=fast-mctd", f"env={env}"])
    model, manifest = load_checkpoint(cfg.checkpoint_dir(), cfg)
    with torch_threads(2):
        denoiser = LocalDenoiser(model, cfg.diffusion, "cpu", cfg.ray.micro_batch)
        planner = make_planner(cfg, denoiser, normaliser_from_manifest(manifest))
        return run_episode(cfg, make_env(cfg.env.name), planner, task=task, seed=seed)


@pytest.mark.slow
def test_fast_mctd_solves_medium_task1_seed0():
    row = shipped_fast_mctd_episode("pointmaze-medium")
    assert row["success"], row["plan_status"]
    assert row["env_steps"] <= 500 and row["plans"] == 1
    assert row["denoise_share"] > 0.9  # the search is almost all denoiser


@pytest.mark.slow
def test_fast_mctd_with_the_shipped_ant_policy_solves_antmaze_medium_task1_seed0():
    row = shipped_fast_mctd_episode("antmaze-medium")
    assert row["success"], row["plan_status"]  # within OGBench's 0.5 of the goal, walked by the policy
    assert row["env_steps"] <= 500 and row["plans"] == 1


DIFFUSER_MEDIUM = load_config(["method=diffuser", "env=pointmaze-medium"]).checkpoint_dir()


@pytest.mark.xfail(strict=True, reason="issue 7: at 9000 of the paper's 20000 steps (width 32-64-128) the shipped "
                   "Diffuser's first plan frame is still 1.4-4.9 from the inpainted start (docs/results.md section 3); "
                   "strict: once a retrained checkpoint passes, this mark must go")
def test_shipped_diffuser_plan_on_medium_task1_is_warp_free():
    cfg = load_config(["method=diffuser", "env=pointmaze-medium"])
    model, manifest = load_checkpoint(cfg.checkpoint_dir(), cfg)
    env = make_env(cfg.env.name)
    reset = env.reset(1, 0)
    with torch_threads(1):
        planner = make_planner(cfg, LocalDenoiser(model, cfg.diffusion, "cpu", 1), normaliser_from_manifest(manifest))
        out = planner.plan(reset.obs, reset.goal, seed=0)
    path = np.concatenate([reset.obs[None], out.waypoints])
    steps = np.linalg.norm(np.diff(path, axis=0), axis=1)
    assert out.waypoints.shape == (cfg.env.horizon, 2)
    assert steps.max() <= cfg.method.warp_threshold, f"largest plan step {steps.max():.2f} at {steps.argmax()}"
