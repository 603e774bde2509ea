"""Which goal-conditioned policy spec serves an env family, and which one a checkpoint's ``kind`` names."""

from __future__ import annotations

from fmctd_dist.families.maze.ant_policy import ANT_SPEC
from fmctd_dist.families.cube.policy import CUBE_SPEC
from fmctd_dist.control.policy.spec import PolicySpec
from fmctd_dist.errors import ConfigError
from fmctd_dist.registry import family

SPECS: dict[str, PolicySpec] = {s.family: s for s in (ANT_SPEC, CUBE_SPEC)}  # env family -> spec
BY_KIND: dict[str, PolicySpec] = {s.kind: s for s in SPECS.values()}
POLICY_ENVS = "antmaze-medium, antmaze-large, antmaze-giant, cube-single, cube-double or cube-triple"


def spec_for_env(env_name: str) -> PolicySpec:
    """The spec of ``env_name``'s family; a family without a learned policy is one ConfigError."""
    fam = family(env_name)
    if fam not in SPECS:
        raise ConfigError(f"env={env_name} has no low-level policy (a point is driven by the PD controller); "
                          f"use env={POLICY_ENVS}")
    return SPECS[fam]
