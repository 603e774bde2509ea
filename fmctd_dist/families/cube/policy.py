"""The cube goal-conditioned policy's spec: arm state + the target cube's state + its subgoal -> 5-D action.

    action [5] = tanh(MLP(arm [19] ++ cube [9] ++ cube xyz - effector xyz [3] ++ clip_norm(subgoal - cube xyz) [3]))

The planner plans cube positions; the arm needs effector moves. The policy sees one cube at a
time (the one the planner moves, docs/reference.md §13: the other cubes are held still), as a
28-number *view* of the observation: the arm's 19 numbers and that cube's 9 (xyz, quaternion,
yaw cos/sin). Its subgoal is where that cube should be ~10 steps later (obs units), given
relative to the cube, and the cube is also given relative to the effector, so what to do
does not depend on where on the table it happens.

One policy for every cube env (the authors reused their single-cube policy for double and
triple): the view has the same layout whatever the number of cubes, so a policy trained on
cube-single data drives cube-double and cube-triple. What it cannot see is the other cubes
(a collision, or a cube stacked on the target), which is the planner's business.
"""

from __future__ import annotations

import numpy as np

from fmctd_dist.families.maze.ant_policy import clip_norm
from fmctd_dist.control.policy.spec import PolicySpec
from fmctd_dist.families.cube.env import ACT_DIM, ARM_DIM, CUBE_OBS

NAME = "goal-conditioned BC with hindsight subgoals (one cube)"
KIND = "cube-goal-bc"
VIEW_DIM = ARM_DIM + CUBE_OBS  # 28: arm + one cube
EFFECTOR = slice(12, 15)  # effector xyz (obs units) inside the arm's 19 numbers
CUBE_XYZ = slice(ARM_DIM, ARM_DIM + 3)  # the cube's xyz inside a view
IN_DIM = VIEW_DIM + 3 + 3
INPUT_LAYOUT = (f"act(view [..., {VIEW_DIM}], subgoal [..., 3]): view is the arm's 19 observation numbers followed by "
                "the target cube's 9 (cube_view(obs, cube)), subgoal is that cube's xyz in obs units")


def cube_view(obs: np.ndarray, cube: int | np.ndarray) -> np.ndarray:
    """[..., 19+9N] observations + cube index (an int, or [...] per row) -> [..., 28] arm + that cube."""
    obs = np.asarray(obs)
    cube = np.asarray(cube, dtype=np.int64)
    cols = ARM_DIM + CUBE_OBS * cube[..., None] + np.arange(CUBE_OBS)  # [..., 9]
    if cube.ndim == 0:
        return np.concatenate([obs[..., :ARM_DIM], obs[..., cols]], axis=-1)
    return np.concatenate([obs[..., :ARM_DIM], np.take_along_axis(obs, cols, axis=-1)], axis=-1)


def policy_input(view: np.ndarray, subgoal: np.ndarray, max_dist: float) -> np.ndarray:
    """view [..., 28] + subgoal [..., 3] (cube xyz, obs units) -> [..., 34] float32 network input."""
    view = np.asarray(view, dtype=np.float32)
    xyz = view[..., CUBE_XYZ]
    rel = clip_norm(np.asarray(subgoal, dtype=np.float32) - xyz, max_dist)
    return np.concatenate([view, xyz - view[..., EFFECTOR], rel], axis=-1)


CUBE_SPEC = PolicySpec(kind=KIND, family="cube", name=NAME, obs_dim=VIEW_DIM, goal_dim=3, act_dim=ACT_DIM,
                       in_dim=IN_DIM, input_layout=INPUT_LAYOUT, make_input=policy_input, any_env_of_family=True)
