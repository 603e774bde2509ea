"""What one family's goal-conditioned policy is: its checkpoint kind, input layout and input function.

The network, checkpoints and training loop are shared by every family (ant, cube); a family
brings only this spec (``ant.py``, ``cube.py``) plus its data rows and reach test. A spec is
plain data, so the shared modules never branch on the family.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

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
