"""AntMaze low-level policy (issue 9): hindsight subgoals, training + exact resume, checkpoints and their
clear errors, the reach evaluation's state restore, and the plan controller on a fake ant. No Ray."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest
import torch

from fmctd_dist.families.maze.ant_policy import ANT_SPEC, NAME, policy_input
from fmctd_dist.families.maze.ant_policy_hooks import AntHooks
from fmctd_dist.families.maze.ant_policy_rows import make_rows, run_ends
from fmctd_dist.artifacts import MODEL_FILE
from fmctd_dist.control.policy.checkpoint import load_policy
from fmctd_dist.control.policy.config import load_policy_args
from fmctd_dist.control.policy.hindsight import sample_offsets, sample_pairs
from fmctd_dist.control.policy.train import train_policy
from fmctd_dist.config import REPO_ROOT
from fmctd_dist.families.maze.ant_controller import AntPlanController, run_plan
from fmctd_dist.resume import load_train_state
from fmctd_dist.errors import CheckpointError, ConfigError
from conftest import torch_threads, with_words

pytestmark = pytest.mark.usefixtures("one_torch_thread")

TINY_ANT = ["env=antmaze-medium", "data.episodes=2", "data.episode_steps=60", "env.horizon=10",
            "data.train_window=10"]
TINY_POLICY = ["policy.hidden=[32,32]", "policy.batch_size=64", "policy.lr=1e-3", "policy.val_every=10",
               "policy.ckpt_every=10", "policy.log_every=5", "policy.val_rows=256", "reach.rows=4",
               "reach.max_steps=5"]


def tiny(root, max_steps: int, *extra: str):
    return load_policy_args(with_words([*TINY_ANT, f"data.root={root}", *TINY_POLICY, f"policy.max_steps={max_steps}"],
                                       *extra))


@pytest.fixture(scope="module")
def data_root(tmp_path_factory):
    """2 train + 1 val antmaze-medium episodes of 60 steps, made by the shipped expert."""
    from fmctd_dist.families.maze.data import make_dataset

    root = tmp_path_factory.mktemp("antdata")
    cfg, _ = tiny(root, 1)
    make_dataset(cfg, progress=False)
    return root


@pytest.fixture(scope="module")
def trained(data_root, tmp_path_factory):
    """A 30-step policy run, trained once for the module."""
    out = tmp_path_factory.mktemp("policy")
    with torch_threads(1):  # train_policy sets policy.threads=1; give the old count back after
        summary = train_policy(*tiny(data_root, 30), AntHooks(), out, progress=False)
    return out, summary


# ---- hindsight subgoals ----

def _upright_obs(e: int, s: int) -> np.ndarray:
    obs = np.zeros((e, s, 29), np.float32)
    obs[..., 0] = np.arange(s)  # x = time: a subgoal's x tells which row it came from
    obs[..., 1] = np.arange(e)[:, None]  # y = episode
    obs[..., 2], obs[..., 3] = 0.55, 1.0  # torso height, quaternion w: healthy and upright
    return obs


def test_offsets_are_two_geometric_draws_with_mean_ten():
    k = sample_offsets(np.random.default_rng(0), 200_000, 0.2, 2)
    assert k.min() == 2 and abs(k.mean() - 10.0) < 0.05 and abs(np.median(k) - 8) <= 1
    assert np.array_equal(sample_offsets(np.random.default_rng(1), 10, 0.2, 1) >= 1, np.ones(10, bool))


def test_run_ends_split_episodes_and_falls():
    ok = np.array([[1, 1, 1, 0, 0, 1, 1], [1, 1, 1, 1, 1, 1, 1]], bool)
    end = run_ends(ok)
    assert end[:3].tolist() == [2, 2, 2] and end[5:7].tolist() == [6, 6]
    assert end[7:].tolist() == [13] * 7  # a run never crosses into the next episode


def test_subgoals_stay_inside_the_episode_and_off_fallen_rows():
    e, s = 3, 200
    obs = _upright_obs(e, s)
    obs[1, 80:120, 2] = 0.1  # episode 1 falls for 40 steps (unhealthy height)
    rows = make_rows(obs, np.zeros((e, s, 8), np.float32), np.zeros((e, s, 2), np.float32), drop_fallen=True)
    assert rows.stats == {"rows": 600, "fallen_rows": 40, "episodes_with_falls": 1, "trained_rows": 600 - 40 - 4}
    i, j = sample_pairs(rows.valid, rows.end, np.random.default_rng(0), 100_000, 0.2, 2)
    ep_i, ep_j, t_i, t_j = i // s, j // s, i % s, j % s
    assert np.array_equal(ep_i, ep_j) and np.all(j > i) and np.all(j <= rows.end[i])
    assert np.array_equal(rows.xy[j, 0], t_j) and np.array_equal(rows.xy[j, 1], ep_j)
    fallen = (ep_i == 1) & (t_i >= 80) & (t_i < 120)
    assert not fallen.any() and not ((ep_j == 1) & (t_j >= 80) & (t_j < 120)).any()
    assert not np.any(t_i == s - 1)  # an episode's last row has no future
    interior = t_i < 40  # far from any run end: the offset is the uncut draw
    assert abs((j - i)[interior].mean() - 10.0) < 0.15
    kept = make_rows(obs, np.zeros((e, s, 8), np.float32), np.zeros((e, s, 2), np.float32), drop_fallen=False)
    assert kept.stats["trained_rows"] == 600 - 3


def test_input_is_translation_invariant_and_far_subgoals_are_clipped():
    rng = np.random.default_rng(0)
    obs, sub = rng.normal(size=(5, 29)), rng.normal(size=(5, 2))
    shift = np.array([12.0, -4.0])
    moved = obs.copy()
    moved[:, :2] += shift
    np.testing.assert_allclose(policy_input(moved, sub + shift, 4.0), policy_input(obs, sub, 4.0), atol=1e-5)
    x = policy_input(np.zeros(29), np.array([30.0, 40.0]), 4.0)
    assert x.shape == (29,) and np.allclose(x[-2:], [2.4, 3.2])
    assert np.allclose(policy_input(np.zeros(29), np.array([30.0, 40.0]), 0.0)[-2:], [30.0, 40.0])


# ---- training, resume, checkpoints ----

def test_tiny_run_lowers_the_loss_and_ships_a_checkpoint(trained):
    out, s = trained
    assert s["step"] == 30 and s["resumed_from"] is None and s["name"] == NAME
    state = load_train_state(out)
    losses = [loss for _, loss in state["history"]["train"]]
    assert len(losses) == 6 and losses[-1] < 0.8 * losses[0]
    vals = [v for _, v in state["history"]["val"]]
    assert vals[-1] < vals[0]
    m = json.loads((out / "manifest.json").read_text())
    assert m["kind"] == "ant-goal-bc" and m["name"] == NAME and m["env"] == "antmaze-medium" and m["steps"] == 30
    assert {"git_sha", "config", "dataset", "metrics", "model_sha256", "wall_time_s"} <= set(m)
    assert m["dataset"]["expert"]["model_sha256"] == json.loads(
        (REPO_ROOT / "checkpoints" / "ant-expert" / "manifest.json").read_text())["model_sha256"]
    assert len(m["dataset"]["sha256"]["train"]) == 64 and m["dataset"]["rows"]["train"]["rows"] == 120
    assert 0 < m["metrics"]["val_mse_expert"] < 0.1  # the data's noise floor (noise 0.2^2 = 0.04, clipped)
    reach = m["metrics"]["reach"]
    assert set(reach) == {"policy", "expert", "zero"} and all(r["tries"] == 4 for r in reach.values())
    assert all(0 <= r["reach_rate"] <= 1 and 0 <= r["fall_rate"] <= 1 for r in reach.values())


def test_checkpoint_round_trip_loads_with_weights_only_and_acts_identically(trained):
    out, _ = trained
    state = torch.load(out / MODEL_FILE, map_location="cpu", weights_only=True)
    assert state["net.0.weight"].shape == (32, 29) and "in_mean" in state
    a, b = load_policy(out, ANT_SPEC, env_name="antmaze-medium"), load_policy(out, ANT_SPEC)
    rng = np.random.default_rng(0)
    obs, sub = rng.normal(size=(7, 29)), rng.normal(size=(7, 2))
    act = a.act(obs, sub)
    assert act.shape == (7, 8) and np.all(np.abs(act) < 1)
    assert np.array_equal(act, b.act(obs, sub))
    np.testing.assert_allclose(a.act(obs[3], sub[3]), act[3], atol=1e-6)  # one row: another matmul path
    x = torch.from_numpy(policy_input(obs, sub, 4.0))
    net = type(a.net)([32, 32], 29, 8)
    net.load_state_dict(state)
    assert np.array_equal(net.eval()(x).detach().numpy().astype(np.float64), act)


def test_rerun_resumes_bit_exactly(data_root, trained, tmp_path):
    straight, _ = trained
    killed = tmp_path / "killed"
    train_policy(*tiny(data_root, 20, "reach.rows=0"), AntHooks(), killed, progress=False)  # "killed" after step 20
    s = train_policy(*tiny(data_root, 30), AntHooks(), killed, progress=False)
    assert s["step"] == 30 and s["resumed_from"] == 20
    a, b = load_train_state(straight), load_train_state(killed)
    assert all(torch.equal(v, b["net"][k]) for k, v in a["net"].items())
    assert a["history"] == b["history"] and a["rng"] == b["rng"]
    assert all(torch.equal(a["opt"]["state"][k]["exp_avg"], b["opt"]["state"][k]["exp_avg"]) for k in a["opt"]["state"])
    assert (straight / MODEL_FILE).read_bytes() == (killed / MODEL_FILE).read_bytes()
    again = train_policy(*tiny(data_root, 30), AntHooks(), killed, progress=False)  # finished: nothing to do
    assert again["step"] == 30 and again["resumed_from"] == 30 and again["reach"] is not None


def test_clear_errors_for_missing_wrong_or_mismatched_policies(data_root, trained, tmp_path):
    out, _ = trained
    with pytest.raises(CheckpointError, match="does not exist.*jobs/train_policy.py env=antmaze-medium"):
        load_policy(tmp_path / "nowhere", ANT_SPEC, env_name="antmaze-medium")
    with pytest.raises(CheckpointError, match="kind 'df' \\(a Diffusion Forcing planner\\), not a goal-conditioned"):
        load_policy(REPO_ROOT / "checkpoints" / "pointmaze-medium-h5", ANT_SPEC, env_name="antmaze-medium")
    with pytest.raises(CheckpointError, match="kind 'ant-direction-sac' \\(the ant expert"):
        load_policy(REPO_ROOT / "checkpoints" / "ant-expert", ANT_SPEC)
    with pytest.raises(CheckpointError, match="trained on antmaze-medium data but the env is antmaze-large.*"
                                              "env=antmaze-large"):
        load_policy(out, ANT_SPEC, env_name="antmaze-large")
    with pytest.raises(CheckpointError, match="takes obs_dim=29 but the caller feeds obs_dim=27"):
        load_policy(out, ANT_SPEC, obs_dim=27)
    policy = load_policy(out, ANT_SPEC)
    with pytest.raises(ValueError, match=r"full OGBench ant observation.*x and y first"):
        policy.act(np.zeros(27), np.zeros(2))  # x, y already dropped
    with pytest.raises(ValueError, match=r"subgoal \(3,\)"):
        policy.act(np.zeros(29), np.zeros(3))
    corrupt = tmp_path / "corrupt"
    shutil.copytree(out, corrupt)
    with open(corrupt / MODEL_FILE, "ab") as f:
        f.write(b"x")
    with pytest.raises(CheckpointError, match="sha256.*corrupt"):
        load_policy(corrupt, ANT_SPEC)
    resumed = tmp_path / "resume"
    shutil.copytree(out, resumed)
    with pytest.raises(CheckpointError, match=r"policy.hidden=\[32, 32\].*policy.hidden=\[64, 64\]"):
        train_policy(*tiny(data_root, 40, "policy.hidden=[64,64]"), AntHooks(), resumed, progress=False)
    os.remove(resumed / "train_state.pt")
    with pytest.raises(CheckpointError, match="without train_state.pt"):
        train_policy(*tiny(data_root, 40), AntHooks(), resumed, progress=False)
    with pytest.raises(CheckpointError, match="kind 'ant-direction-sac'"):  # never trains into another checkpoint
        train_policy(*tiny(data_root, 40), AntHooks(), REPO_ROOT / "checkpoints" / "ant-expert", progress=False)
    with pytest.raises(ConfigError, match="did you mean 'policy.max_steps'"):
        load_policy_args(["policy.max_step=10"])
    with pytest.raises(ConfigError, match="policy.geom_p=0.0 must be > 0 and <= 1"):
        load_policy_args(["policy.geom_p=0"])
    with pytest.raises(ConfigError, match="has no low-level policy"):
        load_policy_args(["env=pointmaze-medium"])


# ---- reach evaluation ----

def test_restored_rows_replay_the_dataset(data_root):
    """Reach tries restore a row's MuJoCo state from its 29-D obs: replaying its torques reproduces the data."""
    from fmctd_dist.families.maze.data import dataset_dir
    from fmctd_dist.families.maze.antmaze import AntMaze

    cfg, _ = tiny(data_root, 1)
    with np.load(dataset_dir(cfg) / "val.npz") as z:
        obs, act = z["observations"][0], z["actions"][0]
    env = AntMaze("antmaze-medium")
    env.reset(3, seed=5)
    for t in (0, 25):
        assert np.array_equal(env.restore(obs[t].astype(np.float64)), obs[t].astype(np.float64))
        for s in range(10):
            ob, _ = env.step(act[t + s].astype(np.float64))
        np.testing.assert_allclose(ob, obs[t + 10], atol=1e-4)
    with pytest.raises(ValueError, match=r"restore takes a \(29,\)"):
        env.restore(obs[0, 2:])
    env.close()


def test_reach_is_deterministic_and_the_expert_beats_zero_torques(data_root):
    from fmctd_dist.families.maze.expert.expert import load_expert
    from fmctd_dist.families.maze.ant_policy_rows import load_policy_data
    from fmctd_dist.families.maze.ant_reach import evaluate_reach, expert_controller, zero_controller

    cfg, _ = tiny(data_root, 1)
    _, val, _ = load_policy_data(cfg, drop_fallen=True)
    ctrls = {"expert": expert_controller(load_expert(REPO_ROOT / "checkpoints" / "ant-expert")),
             "zero": zero_controller}
    a = evaluate_reach(cfg.env.name, ctrls, val, 6, 20, 25, 1.0, seed=0)
    assert a == evaluate_reach(cfg.env.name, ctrls, val, 6, 20, 25, 1.0, seed=0)
    assert a["expert"]["tries"] == 6 and a["expert"]["mean_subgoal_dist"] == a["zero"]["mean_subgoal_dist"]
    assert a["expert"]["mean_min_dist"] < a["zero"]["mean_min_dist"]


# ---- controller on a fake ant ----

class FakeAnt:
    """No MuJoCo: the torso moves straight towards the point in action[:2], at most ``speed`` per step
    (None: all the way). Success = within 0.5 of ``goal``, as AntMaze."""

    def __init__(self, start, goal, speed: float | None = None):
        self.pos, self.goal, self.speed = np.asarray(start, float), np.asarray(goal, float), speed

    def observation(self) -> np.ndarray:
        return np.concatenate([self.pos, np.zeros(27)])

    def step(self, action):
        d = np.asarray(action[:2]) - self.pos
        n = np.linalg.norm(d)
        if self.speed is not None and n > self.speed:
            d = d * self.speed / n
        self.pos = self.pos + d
        return self.observation(), bool(np.linalg.norm(self.pos - self.goal) <= 0.5)


def fake_policy(obs, subgoal):
    assert obs.shape == (29,) and subgoal.shape == (2,)
    return np.concatenate([subgoal, np.zeros(6)])


PLAN = np.stack([np.linspace(0.0, 10.0, 101), np.zeros(101)], axis=1)  # 0.1 m per plan point


def test_controller_advances_one_interval_each_time_the_subgoal_is_reached():
    env = FakeAnt(PLAN[0], PLAN[-1])  # reaches whatever subgoal it is given in one step
    run = run_plan(env, PLAN, fake_policy, max_steps=50)
    # step 1 goes to plan[10] (1.0 away: not < 1.0, no advance); each later step starts on the subgoal: +10
    assert run.advances == 9 and run.subgoal_index == 100 and np.array_equal(run.subgoals[-1], PLAN[-1])
    assert run.steps == 10 and run.success
    assert np.array_equal(run.subgoals, PLAN[10:101:10])
    np.testing.assert_allclose(run.positions[1:], PLAN[10:101:10], atol=1e-12)


def test_controller_holds_the_last_point_and_never_skips_an_interval():
    env = FakeAnt(PLAN[0], PLAN[-1], speed=0.25)
    run = run_plan(env, PLAN, fake_policy, max_steps=100)
    assert run.advances == 9 and run.subgoal_index == 100 and run.success and run.steps == 38  # 9.5 m / 0.25
    idx = np.rint(run.subgoals[:, 0] * 10).astype(int)
    assert idx[0] == 10 and np.all(idx % 10 == 0) and np.all(np.diff(idx) >= 0) and np.all(np.diff(idx) <= 10)
    env = FakeAnt(PLAN[0], np.array([50.0, 0.0]))  # the env's goal is elsewhere: the ant waits at the plan's end
    run = run_plan(env, PLAN, fake_policy, max_steps=60)
    assert not run.success and run.steps == 60 and np.array_equal(run.positions[-1], PLAN[-1])
    ctrl = AntPlanController(PLAN[:5], fake_policy)  # plan shorter than the interval: its last point at once
    assert np.array_equal(ctrl.subgoal, PLAN[4])


def test_controller_drives_the_real_ant_with_the_trained_policy(trained):
    from fmctd_dist.families.maze.antmaze import AntMaze

    out, _ = trained
    env = AntMaze("antmaze-medium")
    env.reset(1, seed=0)
    run = run_plan(env, PLAN, load_policy(out, ANT_SPEC, env_name="antmaze-medium"), max_steps=5)
    assert run.steps == 5 and run.positions.shape == (6, 2) and run.subgoal_index in (10, 20)
    env.close()


# ---- jobs ----

def test_job_scripts_smoke(data_root, trained, tmp_path):
    """train_policy.py trains; eval_policy.py evaluates; a policy for another maze is one `error:` line."""
    out = tmp_path / "job"
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    words = [*TINY_ANT, f"data.root={data_root}", *TINY_POLICY, "policy.max_steps=10", f"policy.out={out}"]
    r = subprocess.run([sys.executable, str(REPO_ROOT / "jobs" / "train_policy.py"), *words],
                       capture_output=True, text=True, timeout=180, env=env)
    assert r.returncode == 0, r.stderr
    assert "10 steps" in r.stdout and "policy  reach" in r.stdout and "expert  reach" in r.stdout
    r = subprocess.run([sys.executable, str(REPO_ROOT / "jobs" / "eval_policy.py"), *words, "reach.expert=false",
                        "reach.zero=false"], capture_output=True, text=True, timeout=180, env=env)
    assert r.returncode == 0, r.stderr
    assert "policy  reach" in r.stdout and "expert" not in r.stdout
    r = subprocess.run([sys.executable, str(REPO_ROOT / "jobs" / "eval_policy.py"), "env=antmaze-large",
                        f"policy.out={out}"], capture_output=True, text=True, timeout=180, env=env)
    assert r.returncode == 2 and r.stderr.strip().startswith("error: ant policy")
    assert "trained on antmaze-medium data but the env is antmaze-large" in r.stderr and "Traceback" not in r.stderr
