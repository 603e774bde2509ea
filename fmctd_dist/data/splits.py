"""Train / val splits and per-episode seeding, shared by every family's data (navigate, ant, cube).

Episode ``ep`` of split ``s`` draws from ``SeedSequence([data.seed, SPLITS[s], ep])`` only, so
any episode can be regenerated alone and a smaller dataset is a prefix of a larger one.
"""

from __future__ import annotations

import numpy as np

from fmctd_dist.config import Config

SPLITS = {"train": 0, "val": 1}  # split id feeds the per-episode seed


def val_episodes(cfg: Config) -> int:
    """Validation episodes beside ``data.episodes`` training ones (OGBench: 10%)."""
    return max(1, round(cfg.data.episodes * cfg.data.val_fraction))


def episode_rng(cfg: Config, split: str, ep: int) -> np.random.Generator:
    """Episode ``ep`` of ``split`` draws only from its own stream: any episode can be regenerated alone."""
    return np.random.default_rng(np.random.SeedSequence([cfg.data.seed, SPLITS[split], ep]))
