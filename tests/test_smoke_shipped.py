"""End to end with shipped checkpoints: Fast-MCTD solves PointMaze-medium and AntMaze-medium task 1,
seed 0, on CPU; the shipped Diffusers' plans are warp-free (task 1: a strict xfail, issue 7)."""

import numpy as np
import pytest
from conftest import torch_threads

from fmctd_dist.config import load_config
from fmctd_dist.denoiser.local import LocalDenoiser
from fmctd_dist.diffusion.checkpoint import load_checkpoint, normaliser_from_manifest
from fmctd_dist.envs import make_env
from fmctd_dist.errors import CheckpointError
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


EDGE8 = ["method=diffuser", "env=pointmaze-medium", "checkpoint=checkpoints/pointmaze-medium-diffuser-edge8",
         "model.unet_edge_frames=8"]


def shipped_diffuser_plan_steps(args: list[str], task: int, seed: int = 0) -> tuple[np.ndarray, float]:
    """Step lengths (world units) of one Diffuser plan from a shipped checkpoint, start -> frame 1 first,
    and the method's warp threshold."""
    cfg = load_config(args)
    model, manifest = load_checkpoint(cfg.checkpoint_dir(), cfg)
    reset = make_env(cfg.env.name).reset(task, 0)
    with torch_threads(1):
        planner = make_planner(cfg, LocalDenoiser(model, cfg.diffusion, "cpu", 1), normaliser_from_manifest(manifest))
        out = planner.plan(reset.obs, reset.goal, seed=seed)
    assert out.waypoints.shape == (cfg.env.horizon, 2)
    steps = np.linalg.norm(np.diff(np.concatenate([reset.obs[None], out.waypoints]), axis=0), axis=1)
    return steps, cfg.method.warp_threshold


@pytest.mark.xfail(strict=True, reason="issue 7: the shipped Diffuser's first plan frame is 1.4-4.9 from the inpainted "
                   "start, the edge8 one's still 1.7-1.8 on task 1, a corner the data hardly visits (docs/results.md "
                   "section 3.1); strict: once a retrained checkpoint passes, this mark must go")
def test_shipped_diffuser_plan_on_medium_task1_is_warp_free():
    steps, warp = shipped_diffuser_plan_steps(["method=diffuser", "env=pointmaze-medium"], task=1)
    assert steps.max() <= warp, f"largest plan step {steps.max():.2f} at {steps.argmax()}"


def test_edge8_diffuser_plan_on_medium_task3_is_warp_free():
    """The edge frames fixed the first step where the start is well covered (the Janner net's is 1.6 here)."""
    for seed in (0, 1, 2):
        steps, warp = shipped_diffuser_plan_steps(EDGE8, task=3, seed=seed)
        assert steps.max() <= warp, f"seed {seed}: largest plan step {steps.max():.2f} at {steps.argmax()}"


def test_edge8_checkpoint_without_its_flag_is_one_clear_error():
    cfg = load_config(EDGE8[:-1])
    with pytest.raises(CheckpointError, match="unet_edge_frames"):
        load_checkpoint(cfg.checkpoint_dir(), cfg)
