"""The oracle reaches every evaluation goal within the paper's budgets; the PD controller follows it."""

import numpy as np
import pytest

from fmctd_dist.families.maze.pd import PDController
from fmctd_dist.planners.base import repeat_waypoints
from fmctd_dist.families.maze.oracle import NoisyOracle
from fmctd_dist.families.maze.make import make_env

BUDGET = {"pointmaze-medium": 500, "pointmaze-large": 500, "pointmaze-giant": 1000}


def run_oracle(env, oracle, task, seed, budget):
    r = env.reset(task, seed)
    rng = np.random.default_rng(seed)
    pos, path = r.obs, [r.obs]
    for t in range(budget):
        pos, success = env.step(oracle.act(pos, r.goal, rng))
        path.append(pos)
        if success:
            return t + 1, np.array(path)
    return None, np.array(path)


@pytest.mark.parametrize("name", sorted(BUDGET))
def test_oracle_reaches_every_goal_within_budget(name):
    env = make_env(name)
    oracle = NoisyOracle(env.geometry, noise=0.5)
    steps = [run_oracle(env, oracle, task, 0, BUDGET[name])[0] for task in range(1, 6)]
    assert all(s is not None for s in steps), f"{name}: oracle steps to goal {steps}"


def test_pd_controller_follows_oracle_path():
    env = make_env("pointmaze-large")
    oracle = NoisyOracle(env.geometry, noise=0.5)
    steps, path = run_oracle(env, oracle, 2, 0, 500)
    assert steps is not None
    r = env.reset(2, 0)
    ctrl, pos = PDController(path[1:]), r.obs
    for t in range(500):
        pos, success = env.step(ctrl.act(pos))
        if success:
            break
    assert success and t + 1 <= steps + 5


def test_pd_controller_formula():
    """a = clip(kp (p_t - pos) + kd (v_plan - vel)); v_plan = p_t - p_{t-1}; vel by finite difference."""
    ctrl = PDController(np.array([[0.1, 0.0], [0.3, 0.1]]), kp=2.0, kd=0.5)
    np.testing.assert_allclose(ctrl.act(np.zeros(2)), [2 * 0.1 + 0.5 * 0.1, 0.0])  # v_plan = p_0 - pos, vel = 0
    pos = np.array([0.05, 0.0])
    expect = 2 * (np.array([0.3, 0.1]) - pos) + 0.5 * (np.array([0.2, 0.1]) - np.array([0.05, 0.0]))
    np.testing.assert_allclose(ctrl.act(pos), expect)
    np.testing.assert_allclose(ctrl.act(np.array([0.3, 0.1])), 0.5 * -(np.array([0.25, 0.1])))  # plan over: hold
    assert np.abs(PDController(np.array([[9.0, -9.0]])).act(np.zeros(2))).max() == 1.0  # clipped


def test_repeat_waypoints():
    plan = np.arange(6.0).reshape(3, 2)
    dense = repeat_waypoints(plan, 5)
    assert dense.shape == (15, 2) and (dense[:5] == plan[0]).all() and (dense[-1] == plan[-1]).all()
