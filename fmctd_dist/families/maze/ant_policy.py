"""The AntMaze goal-conditioned policy's spec: what the ant's low-level policy sees and does.

    action [8] = tanh(MLP(ant state without x, y [27]  ++  clip_norm(subgoal - x, y) [2]))

The planner gives x, y waypoints; the ant needs torques. The input drops the absolute x, y
and sees the subgoal only relative to the torso: walking 1 m north-east takes the same
torques anywhere in the maze, so the policy is translation invariant by construction and
every row of the dataset teaches every place (the walls are the planner's business). The
relative subgoal's norm is clipped at ``max_subgoal_dist`` so a far subgoal (a slow ant, a
plan that jumps) reads as "that way, far" instead of an input never seen in training.

Trained by MSE onto the dataset's noisy expert torques (their mean is the expert's), with
subgoals relabelled in hindsight (:mod:`fmctd_dist.families.maze.ant_policy_rows`); the network,
checkpoints and loop are shared with the cube (``network.py``, ``checkpoint.py``, ``train.py``).
A policy drives the maze it was trained on only.
"""

from __future__ import annotations

import numpy as np

from fmctd_dist.control.policy.spec import PolicySpec
from fmctd_dist.families.maze.antmaze import ACT_DIM, OBS_DIM

NAME = "goal-conditioned BC with hindsight subgoals"
KIND = "ant-goal-bc"
IN_DIM = OBS_DIM - 2 + 2  # proprioception (27) + relative subgoal (2)
INPUT_LAYOUT = (f"act(obs [..., {OBS_DIM}], subgoal [..., 2]): obs is the full OGBench ant observation (qpos 15 + "
                "qvel 14, x and y first; the policy subtracts x, y from the subgoal itself), subgoal is a world x, y")


def clip_norm(rel: np.ndarray, max_dist: float) -> np.ndarray:
    """[..., D] vectors with their norm clipped at ``max_dist`` (0 = no clip), float32."""
    rel = np.asarray(rel, dtype=np.float32)
    if max_dist > 0:
        norm = np.linalg.norm(rel, axis=-1, keepdims=True)
        rel = rel * np.minimum(1.0, max_dist / np.maximum(norm, 1e-6)).astype(np.float32)
    return rel


def policy_input(obs: np.ndarray, subgoal: np.ndarray, max_dist: float) -> np.ndarray:
    """obs [..., 29] + subgoal [..., 2] (world x, y) -> [..., 29] float32 network input."""
    obs = np.asarray(obs, dtype=np.float32)
    rel = clip_norm(np.asarray(subgoal, dtype=np.float32) - obs[..., :2], max_dist)
    return np.concatenate([obs[..., 2:], rel], axis=-1)


ANT_SPEC = PolicySpec(kind=KIND, family="antmaze", name=NAME, obs_dim=OBS_DIM, goal_dim=2, act_dim=ACT_DIM,
                      in_dim=IN_DIM, input_layout=INPUT_LAYOUT, make_input=policy_input, any_env_of_family=False)
