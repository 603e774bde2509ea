"""Seed checks shared by every env family (maze, ant, cube): one place, one error."""

from __future__ import annotations

import numpy as np

from fmctd_dist.errors import ConfigError


def check_seed(seed: object, field: str = "seed") -> int:
    """Gymnasium-style seed check: a non-negative int, else one ConfigError naming the field."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ConfigError(f"{field}={seed!r} must be a non-negative integer (e.g. {field}=0)")
    return int(seed)
