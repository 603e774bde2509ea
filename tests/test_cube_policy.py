"""The cube low-level policy (issue 19): the one-cube view and input, hindsight rows, training, checkpoints and
their clear errors, the closed-loop reach test and the jobs. No Ray."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from fmctd_dist.config import REPO_ROOT
from fmctd_dist.control.policy.checkpoint import load_policy, read_policy_manifest
from fmctd_dist.control.policy.config import load_policy_args
from fmctd_dist.families.cube.policy import CUBE_SPEC, IN_DIM, VIEW_DIM, cube_view, policy_input
from fmctd_dist.families.cube.policy_hooks import CubeHooks
from fmctd_dist.families.maze.ant_policy import ANT_SPEC
from fmctd_dist.families.cube.policy_rows import load_cube_policy_data, make_rows
from fmctd_dist.control.policy.hindsight import label_run_ends, sample_pairs
from fmctd_dist.control.policy.train import train_policy
from fmctd_dist.families.maze.subgoal import SubgoalTracker
from fmctd_dist.resume import load_train_state
from fmctd_dist.errors import CheckpointError, ConfigError
from conftest import torch_threads, with_words

pytestmark = pytest.mark.usefixtures("one_torch_thread")

TINY_CUBE = ["env=cube-single", "data.episodes=2", "data.episode_steps=201", "env.horizon=100",
             "data.train_window=100"]
TINY_POLICY = ["policy.hidden=[32,32]", "policy.batch_size=64", "policy.lr=1e-3", "policy.val_every=10",
               "policy.ckpt_every=10", "policy.log_every=5", "policy.val_rows=256", "reach.rows=2",
               "reach.max_steps=20"]


def tiny(root, max_steps: int, *extra: str):
    return load_policy_args(with_words([*TINY_CUBE, f"data.root={root}", *TINY_POLICY, f"policy.max_steps={max_steps}"],
                                       *extra))


@pytest.fixture(scope="module")
def data_root(tmp_path_factory):
    """2 train + 1 val cube-single play episodes of 201 steps (each holds a completed pick-and-place)."""
    from fmctd_dist.families.cube.data import make_cube_dataset

    root = tmp_path_factory.mktemp("cubedata")
    make_cube_dataset(tiny(root, 1)[0], progress=False)
    return root


@pytest.fixture(scope="module")
def trained(data_root, tmp_path_factory):
    out = tmp_path_factory.mktemp("cubepolicy")
    with torch_threads(1):
        summary = train_policy(*tiny(data_root, 30), CubeHooks(), out, progress=False)
    return out, summary


# ---- the view and the input ----

def test_view_picks_the_target_cube_and_the_input_is_relative():
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(4, 19 + 9 * 3))  # cube-triple observations
    view = cube_view(obs, 2)
    assert view.shape == (4, VIEW_DIM)
    assert np.array_equal(view[:, :19], obs[:, :19]) and np.array_equal(view[:, 19:], obs[:, 37:46])
    per_row = cube_view(obs, np.array([0, 1, 2, 1]))
    assert np.array_equal(per_row[3, 19:], obs[3, 28:37]) and np.array_equal(per_row[0, 19:], obs[0, 19:28])
    sub = rng.normal(size=(4, 3))
    x = policy_input(view, sub, 0.0)
    assert x.shape == (4, IN_DIM) and x.dtype == np.float32
    np.testing.assert_allclose(x[:, -3:], sub - view[:, 19:22], atol=1e-5)  # subgoal relative to the cube
    np.testing.assert_allclose(x[:, -6:-3], view[:, 19:22] - view[:, 12:15], atol=1e-5)  # cube rel. effector
    far = policy_input(np.zeros(VIEW_DIM), np.array([30.0, 40.0, 0.0]), 4.0)
    assert np.allclose(far[-3:], [2.4, 3.2, 0.0])  # a far subgoal is clipped to "that way, far"


def test_runs_end_at_each_new_target_and_subgoals_stay_inside():
    labels = np.array([[0, 0, 0, 1, 1], [0, 0, 1, 1, 1]])
    assert label_run_ends(labels).tolist() == [2, 2, 2, 4, 4, 6, 6, 9, 9, 9]
    e, s = 2, 50
    obs = np.zeros((e, s, 28), np.float32)
    obs[..., 19] = np.arange(s)  # cube x = time
    tpos = np.zeros((e, s, 3), np.float32)
    tpos[:, 20:, 0] = 1.0  # a new target at step 20 in both episodes
    arrays = {"observations": obs, "actions": np.zeros((e, s, 5), np.float32),
              "qpos": np.zeros((e, s, 2), np.float32), "qvel": np.zeros((e, s, 2), np.float32),
              "target_block": np.zeros((e, s), np.int8), "target_pos": tpos}
    rows = make_rows(arrays, 1)
    assert rows.stats == {"rows": 100, "trained_rows": 96, "pick_and_place_runs": 4}
    i, j = sample_pairs(rows.valid, rows.end, np.random.default_rng(0), 20_000, 0.2, 2)
    same_run = (i // s == j // s) & ((i % s < 20) == (j % s < 20))
    assert np.all(j > i) and np.all(same_run)
    np.testing.assert_allclose(rows.inputs(i, j, 0.0)[:, -3:][:, 0], (j - i).astype(np.float32))


def test_subgoal_tracker_follows_a_cube_path_in_3d():
    path = np.zeros((31, 3))
    path[:, 2] = np.linspace(0.2, 3.2, 31)  # lift 3 obs units over 30 steps
    tr = SubgoalTracker(path, 10, 1.0, dim=3)
    assert tr.update(np.array([0.0, 0.0, 0.2]))[2] == pytest.approx(1.2)
    assert tr.update(np.array([0.0, 0.0, 1.0]))[2] == pytest.approx(2.2)  # within 1.0: moved on by 10


# ---- training and checkpoints ----

def test_short_training_lowers_the_loss_and_writes_a_cube_checkpoint(trained):
    out, s = trained
    assert s["step"] == 30 and s["val_mse_expert"] is None
    losses = [loss for _, loss in load_train_state(out)["history"]["train"]]
    assert losses[-1] < losses[0]
    m = json.loads((out / "manifest.json").read_text())
    assert m["kind"] == "cube-goal-bc" and m["env"] == "cube-single" and m["obs_dim"] == VIEW_DIM
    assert m["in_dim"] == IN_DIM and m["act_dim"] == 5 and m["dataset"]["oracle"]["class"].endswith("CubePlanOracle")
    assert set(m["metrics"]["reach"]) == {"policy", "oracle", "zero"}
    assert all(r["tries"] == 2 and 0 <= r["reach_rate"] <= 1 for r in m["metrics"]["reach"].values())
    policy = load_policy(out, CUBE_SPEC, env_name="cube-single")
    act = policy.act(np.zeros((3, VIEW_DIM)), np.ones((3, 3)))
    assert act.shape == (3, 5) and np.all(np.abs(act) < 1)


def test_time_budget_stops_at_a_checkpoint_and_a_rerun_continues(data_root, tmp_path):
    out = tmp_path / "budget"
    s = train_policy(*tiny(data_root, 40, "policy.time_budget_s=1e-9", "reach.rows=0"), CubeHooks(), out,
                     progress=False)
    assert s["step"] == 10 and "time_budget_s" in s["stopped"]
    s = train_policy(*tiny(data_root, 20, "reach.rows=0"), CubeHooks(), out, progress=False)
    assert s["step"] == 20 and s["resumed_from"] == 10 and s["stopped"] is None


def test_one_clear_error_for_a_policy_of_another_family(trained, tmp_path):
    out, _ = trained
    ant = REPO_ROOT / "checkpoints" / "antmaze-medium-policy"
    with pytest.raises(CheckpointError) as e:  # a maze policy given to a cube env
        load_policy(ant, CUBE_SPEC, env_name="cube-single")
    msg = str(e.value)
    assert msg.startswith("cube policy:") and "kind 'ant-goal-bc' (the ant policy)" in msg
    assert "jobs/train_policy.py env=cube-single" in msg and "\n" not in msg
    with pytest.raises(CheckpointError, match="ant policy: .*kind 'cube-goal-bc' \\(the cube policy\\)"):
        load_policy(out, ANT_SPEC, env_name="antmaze-medium")
    with pytest.raises(CheckpointError, match="cube policy: .*kind 'df' \\(a Diffusion Forcing planner\\)"):
        load_policy(REPO_ROOT / "checkpoints" / "pointmaze-medium-h5", CUBE_SPEC, env_name="cube-double")
    with pytest.raises(CheckpointError, match="cube policy: .*does not exist.*env=cube-single"):
        load_policy(tmp_path / "nowhere", CUBE_SPEC, env_name="cube-single")
    for env in ("cube-double", "cube-triple"):  # the single-cube policy drives every cube env (authors' choice)
        assert read_policy_manifest(out, CUBE_SPEC, env)["env"] == "cube-single"
    with pytest.raises(ConfigError, match="has no low-level policy"):
        load_policy(out, CUBE_SPEC, env_name="pointmaze-medium")


def test_a_missing_dataset_is_one_dataset_error(tmp_path):
    from fmctd_dist.errors import DatasetError

    cfg, _ = tiny(tmp_path, 1)
    with pytest.raises(DatasetError, match="no dataset at .*jobs/make_dataset.py env=cube-single"):
        load_cube_policy_data(cfg)


# ---- reach and jobs ----

def test_reach_restores_val_states_and_is_deterministic(data_root):
    from fmctd_dist.families.cube.reach import evaluate_reach, zero_controller

    cfg, _ = tiny(data_root, 1)
    _, val, _ = load_cube_policy_data(cfg)

    a = evaluate_reach("cube-single", {"zero": zero_controller, "oracle": None}, val, 2, 10, 1.0, 0.4, 15, 0,
                       progress=False)
    b = evaluate_reach("cube-single", {"oracle": None, "zero": zero_controller}, val, 2, 10, 1.0, 0.4, 15, 0,
                       progress=False)
    assert a == b and a["zero"]["tries"] == 2  # each try restores its own state: order does not matter
    assert a["zero"]["mean_start_dist"] > 0.4  # tries start with the cube away from where the data took it


def test_job_scripts_smoke(data_root, trained, tmp_path):
    """train_policy.py trains a cube policy; eval_policy.py reports policy / oracle / zero; an ant policy is refused."""
    out = tmp_path / "job"
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    words = [*TINY_CUBE, f"data.root={data_root}", *TINY_POLICY, "policy.max_steps=10", f"policy.out={out}"]
    r = subprocess.run([sys.executable, str(REPO_ROOT / "jobs" / "train_policy.py"), *words],
                       capture_output=True, text=True, timeout=300, env=env)
    assert r.returncode == 0, r.stderr
    assert "10 steps" in r.stdout and "policy  reach" in r.stdout and "oracle  reach" in r.stdout
    r = subprocess.run([sys.executable, str(REPO_ROOT / "jobs" / "eval_policy.py"), *with_words(words, "reach.rows=1")],
                       capture_output=True, text=True, timeout=300, env=env)
    assert r.returncode == 0, r.stderr
    assert all(f"{n:7s} reach" in r.stdout for n in ("policy", "oracle", "zero")), r.stdout
    r = subprocess.run([sys.executable, str(REPO_ROOT / "jobs" / "eval_policy.py"), *words[:-1],
                        f"policy.out={REPO_ROOT / 'checkpoints' / 'antmaze-medium-policy'}"],
                       capture_output=True, text=True, timeout=300, env=env)
    assert r.returncode == 2 and r.stderr.strip().startswith("error: cube policy") and "Traceback" not in r.stderr
