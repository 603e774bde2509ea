"""Which family hooks (spec, rows, noise floor, reach test) train and evaluate an env's learned policy.

The env's registry record names them (``registry.EnvSpec.policy``, "module:Class"); the training loop,
the policy checkpoints and the jobs ask here, so none of them branches on the family.
"""

from __future__ import annotations

import importlib
from typing import Any

from fmctd_dist.control.policy.spec import PolicySpec
from fmctd_dist.errors import ConfigError
from fmctd_dist.registry import env_spec, env_specs


def _load(ref: str) -> Any:
    module, cls = ref.split(":")
    return getattr(importlib.import_module(module), cls)()


def hooks_for_env(env_name: str) -> Any:
    """The hooks object of ``env_name``'s policy; an env without a learned policy is one ConfigError."""
    ref = env_spec(env_name).policy
    if not ref:
        with_policy = ", ".join(n for n, s in env_specs().items() if s.policy)
        raise ConfigError(f"env={env_name} has no low-level policy (e.g. a point is driven by the PD controller); "
                          f"use env={with_policy}")
    return _load(ref)


def spec_for_env(env_name: str) -> PolicySpec:
    """The spec of ``env_name``'s policy (input layout and features); none: one ConfigError."""
    return hooks_for_env(env_name).spec


def policy_kinds() -> dict[str, PolicySpec]:
    """Every registered policy spec by the ``kind`` its checkpoints record."""
    refs = dict.fromkeys(s.policy for s in env_specs().values() if s.policy)
    return {spec.kind: spec for spec in (_load(r).spec for r in refs)}
