"""End to end with a shipped checkpoint: Fast-MCTD solves PointMaze-medium task 1, seed 0, on CPU."""

import pytest
from conftest import torch_threads

from fmctd_dist.config import load_config
from fmctd_dist.denoiser.local import LocalDenoiser
from fmctd_dist.diffusion.checkpoint import load_checkpoint, normaliser_from_manifest
from fmctd_dist.envs import make_env
from fmctd_dist.evaluation.episode import run_episode
from fmctd_dist.planners import make_planner


@pytest.mark.slow
def test_fast_mctd_solves_medium_task1_seed0():
    cfg = load_config(["method=fast-mctd", "env=pointmaze-medium"])
    model, manifest = load_checkpoint(cfg.checkpoint_dir(), cfg)
    with torch_threads(2):
        denoiser = LocalDenoiser(model, cfg.diffusion, "cpu", cfg.ray.micro_batch)
        planner = make_planner(cfg, denoiser, normaliser_from_manifest(manifest))
        row = run_episode(cfg, make_env(cfg.env.name), planner, task=1, seed=0)
    assert row["success"], row["plan_status"]
    assert row["env_steps"] <= 500 and row["plans"] == 1
    assert row["denoise_share"] > 0.9  # the search is almost all denoiser
