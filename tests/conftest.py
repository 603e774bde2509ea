"""Shared fixtures. Pure tests never start Ray; Ray tests use the session-scoped cluster below."""

from __future__ import annotations

import os

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory):
    """A small medium-maze dataset (8 train + 1 val episodes of 301 steps), generated once."""
    from fmctd_dist.config import load_config
    from fmctd_dist.data.dataset import make_dataset

    root = tmp_path_factory.mktemp("data")
    cfg = load_config(TINY_DATA + [f"data.root={root}"], method="mctd")
    path, _ = make_dataset(cfg, progress=False)
    return cfg, path


TINY_DATA = ["env=pointmaze-medium", "data.episodes=8", "data.episode_steps=301",
             "env.horizon=100", "data.train_window=100"]
