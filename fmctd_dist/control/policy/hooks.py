"""Which family hooks (rows, noise floor, reach test) train and evaluate an env's policy.

The training loop and the jobs ask this module, so neither branches on the family.
"""

from __future__ import annotations

import importlib
from typing import Any

from fmctd_dist.control.policy.specs import spec_for_env

HOOKS = {"antmaze": ("fmctd_dist.families.maze.ant_policy_hooks", "AntHooks"),
         "cube": ("fmctd_dist.families.cube.policy_hooks", "CubeHooks")}  # imported on first use


def hooks_for_env(env_name: str) -> Any:
    """The hooks object of ``env_name``'s family (a family without a learned policy is one ConfigError)."""
    module, cls = HOOKS[spec_for_env(env_name).family]
    return getattr(importlib.import_module(module), cls)()
