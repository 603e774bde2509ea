"""What one family's goal-conditioned policy is: its checkpoint kind, input layout and input function.

The network, checkpoints and training loop are shared by every family (ant, cube); a family
brings only this spec (``ant.py``, ``cube.py``) plus its data rows and reach test. A spec is
plain data, so the shared modules never branch on the family.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fmctd_dist.errors import ConfigError
from fmctd_dist.records import EnvSpec
from fmctd_dist.registry import env_spec, env_specs

# (obs [..., obs_dim], subgoal [..., goal_dim], max_subgoal_dist) -> network input [..., in_dim]
InputFn = Callable[[np.ndarray, np.ndarray, float], np.ndarray]


@dataclass(frozen=True)
class PolicySpec:
    kind: str  # manifest "kind" of its checkpoints, e.g. ant-goal-bc
    family: str  # env family it drives (fmctd_dist.registry): antmaze | cube
    name: str  # what it is, in words
    obs_dim: int  # numbers act() takes as obs
    goal_dim: int  # numbers of a subgoal
    act_dim: int  # numbers of an action
    in_dim: int  # network input width
    input_layout: str  # act()'s arguments, in words (for errors and manifests)
    make_input: InputFn  # (obs, subgoal, max_subgoal_dist) -> [..., in_dim] float32
    any_env_of_family: bool  # True: a policy trained on one env of the family drives all of them (cubes)


def require_policy(env_name: str) -> EnvSpec:
    """``env_name``'s registry spec when its robot has a learned policy, else one ConfigError."""
    spec = env_spec(env_name)
    if not spec.policy:
        with_policy = ", ".join(n for n, s in env_specs().items() if s.policy)
        raise ConfigError(f"env={env_name} has no low-level policy (e.g. a point is driven by the PD controller); "
                          f"use env={with_policy}")
    return spec
