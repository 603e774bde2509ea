"""Ant direction expert: env contract, SAC determinism, checkpoints, exact resume, clear errors. No Ray."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest
import torch

from fmctd_dist.families.maze.expert.config import load_expert_config
from fmctd_dist.families.maze.expert.direction_env import ACT_DIM, ANT_OBS_DIM, OBS_DIM, AntDirectionEnv, expert_input
from fmctd_dist.artifacts import MODEL_FILE
from fmctd_dist.families.maze.expert.expert import load_expert
from fmctd_dist.families.maze.expert.sac import SAC, ReplayBuffer
from fmctd_dist.families.maze.expert.train import train_expert
from fmctd_dist.config import REPO_ROOT
from fmctd_dist.resume import load_train_state
from fmctd_dist.errors import CheckpointError, ConfigError
from conftest import torch_threads, with_words

pytestmark = pytest.mark.usefixtures("one_torch_thread")

TINY = ["sac.hidden=[32,32]", "sac.batch_size=32", "sac.buffer_size=2000", "expert.start_steps=100",
        "expert.ckpt_every=100", "expert.log_every=50", "eval.every=0", "eval.episodes=2", "eval.segment_steps=10"]


def tiny(max_steps: int, *extra: str):
    return load_expert_config(with_words([*TINY, f"expert.max_steps={max_steps}"], *extra))


@pytest.fixture(scope="module")
def tiny_expert(tmp_path_factory):
    """A 200-step run (100 random steps, then 100 updates), trained once for the module."""
    out = tmp_path_factory.mktemp("ant-expert")
    with torch_threads(1):  # train_expert sets 1 thread (expert.threads); give the old count back after
        summary = train_expert(tiny(200), out, progress=False)
    return out, summary


def test_env_shapes_reward_and_direction_schedule():
    env = AntDirectionEnv(tiny(1, "env.resample_every=5", "env.episode_steps=12").env, seed=0)
    obs = env.reset()
    assert obs.shape == (OBS_DIM,) and obs.dtype == np.float32 and OBS_DIM == 29
    assert np.isclose(np.linalg.norm(obs[-2:]), 1.0)
    dirs, done = [obs[-2:].copy()], False
    for t in range(12):
        obs, r, terminated, truncated, info = env.step(np.zeros(ACT_DIM))
        assert np.isfinite(r) and not terminated and set(info) >= {"speed", "direction", "xy", "healthy"}
        dirs.append(obs[-2:].copy())
        done = truncated
    assert done  # time limit at env.episode_steps
    assert all(np.array_equal(dirs[i], dirs[0]) for i in range(5)) and not np.array_equal(dirs[5], dirs[0])
    again = AntDirectionEnv(env.cfg, seed=0)
    assert np.array_equal(again.reset(), env.reset(seed=0, direction=dirs[0].astype(np.float64)))


def test_expert_input_is_the_maze_ant_observation_without_xy():
    import ogbench

    maze = ogbench.make_env_and_datasets("antmaze-medium-navigate-v0", env_only=True)
    ob, _ = maze.reset(seed=0)
    assert ob.shape == (ANT_OBS_DIM,)
    env = AntDirectionEnv(tiny(1).env, seed=0)
    env.reset()
    u = maze.unwrapped
    env._u.set_state(u.data.qpos.copy(), u.data.qvel.copy())  # same body state in the open arena
    x = expert_input(ob, np.array([0.0, 2.0]))
    assert x.shape == (OBS_DIM,)
    np.testing.assert_allclose(x[:-2], env._u._get_obs())
    np.testing.assert_allclose(x[-2:], [0.0, 1.0])
    with pytest.raises(ValueError, match="29-D OGBench ant"):
        expert_input(ob[2:], np.array([1.0, 0.0]))


def _batch(seed: int) -> dict[str, torch.Tensor]:
    rng = np.random.default_rng(seed)
    buf = ReplayBuffer(64, OBS_DIM, ACT_DIM)
    for _ in range(64):
        buf.add(rng.normal(size=OBS_DIM), rng.uniform(-1, 1, ACT_DIM), rng.normal(), rng.normal(size=OBS_DIM),
                rng.random() < 0.1)
    return buf.sample(rng, 32)


def test_sac_update_changes_parameters_and_is_deterministic():
    cfg = tiny(1).sac
    a, b, c = SAC(OBS_DIM, ACT_DIM, cfg, seed=3), SAC(OBS_DIM, ACT_DIM, cfg, seed=3), SAC(OBS_DIM, ACT_DIM, cfg, seed=4)
    before = {k: v.clone() for k, v in a.actor.state_dict().items()}
    critic_before = {k: v.clone() for k, v in a.critic.state_dict().items()}
    target_before = {k: v.clone() for k, v in a.critic_target.state_dict().items()}
    alpha_before = a.alpha
    for i in range(3):
        a.update(_batch(i))
        b.update(_batch(i))
        c.update(_batch(i))
    assert all(not torch.equal(before[k], v) for k, v in a.actor.state_dict().items())
    assert all(not torch.equal(critic_before[k], v) for k, v in a.critic.state_dict().items())
    assert all(not torch.equal(target_before[k], v) for k, v in a.critic_target.state_dict().items())
    assert a.alpha != alpha_before and a.updates == 3
    for m1, m2 in ((a.actor, b.actor), (a.critic, b.critic), (a.critic_target, b.critic_target)):
        assert all(torch.equal(x, y) for x, y in zip(m1.state_dict().values(), m2.state_dict().values()))
    assert not torch.equal(a.actor.net[0].weight, c.actor.net[0].weight)
    obs = np.zeros(OBS_DIM, np.float32)
    act = a.act(obs)
    assert act.shape == (ACT_DIM,) and np.all(np.abs(act) <= 1)
    assert np.array_equal(a.act(obs, deterministic=True), b.act(obs, deterministic=True))


def test_tiny_run_writes_a_checkpoint_that_loads_with_weights_only(tiny_expert):
    out, summary = tiny_expert
    assert summary["step"] == 200 and summary["resumed_from"] is None
    state = torch.load(out / MODEL_FILE, map_location="cpu", weights_only=True)
    assert state["net.0.weight"].shape == (32, OBS_DIM)
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["env_steps"] == 200 and manifest["updates"] == 100 and manifest["obs_dim"] == OBS_DIM
    assert {"git_sha", "config", "metrics", "model_sha256"} <= set(manifest)
    assert manifest["metrics"]["eval"]["step"] == 200 and 0 <= manifest["metrics"]["eval"]["success"] <= 1
    train_state = load_train_state(out)  # weights_only=True inside
    assert train_state["buffer"]["size"] == 200 and train_state["step"] == 200
    expert = load_expert(out)
    a = expert.act(np.zeros((3, OBS_DIM)))
    assert a.shape == (3, ACT_DIM) and np.all(np.abs(a) <= 1)


def test_rerun_resumes_exactly_where_it_stopped(tmp_path, tiny_expert):
    straight, _ = tiny_expert
    killed = tmp_path / "killed"
    train_expert(tiny(150), killed, progress=False)  # "killed" after its step-150 checkpoint
    first = load_train_state(killed)
    assert first["step"] == 150 and first["agent"]["updates"] == 50
    s = train_expert(tiny(200), killed, progress=False)
    assert s["step"] == 200 and s["resumed_from"] == 150
    a, b = load_train_state(straight), load_train_state(killed)
    assert b["agent"]["updates"] == 100
    assert all(float(st["step"]) == 100 for st in b["agent"]["critic_opt"]["state"].values())
    for part in ("actor", "critic", "critic_target"):
        assert all(torch.equal(a["agent"][part][k], v) for k, v in b["agent"][part].items())
    assert torch.equal(a["agent"]["log_alpha"], b["agent"]["log_alpha"])
    assert a["env"]["mj_state"] == b["env"]["mj_state"]
    again = train_expert(tiny(200), killed, progress=False)  # finished: nothing to do
    assert again["step"] == 200 and again["resumed_from"] == 200


def test_partial_buffer_save_resumes_on_the_newest_transitions(tmp_path):
    out = tmp_path / "partial"
    train_expert(tiny(150, "expert.buffer_save=120"), out, progress=False)
    st = load_train_state(out)["buffer"]
    assert st["size"] == 120 and st["seen"] == 150 and st["ptr"] == 120
    s = train_expert(tiny(200, "expert.buffer_save=120"), out, progress=False)
    assert s["step"] == 200 and s["resumed_from"] == 150


def test_clear_errors_for_missing_wrong_or_mismatched_checkpoints(tmp_path, tiny_expert):
    out, _ = tiny_expert
    with pytest.raises(CheckpointError, match="does not exist.*jobs/train_expert.py"):
        load_expert(tmp_path / "nowhere")
    with pytest.raises(CheckpointError, match="obs_dim=29 but the caller asks for obs_dim=31"):
        load_expert(out, obs_dim=31)
    with pytest.raises(CheckpointError, match=r"takes obs_dim=29.*without x, y"):
        load_expert(out).act(np.zeros(31))
    other = tmp_path / "diffusion"
    other.mkdir()
    (other / MODEL_FILE).write_bytes(b"")
    (other / "manifest.json").write_text(json.dumps({"model_kind": "df"}))
    with pytest.raises(CheckpointError, match="'df' checkpoint.*not an ant direction expert"):
        load_expert(other)
    corrupt = tmp_path / "corrupt"
    shutil.copytree(out, corrupt)
    with open(corrupt / MODEL_FILE, "ab") as f:
        f.write(b"x")
    with pytest.raises(CheckpointError, match="sha256.*corrupt"):
        load_expert(corrupt)
    resumed = tmp_path / "resume"
    shutil.copytree(out, resumed)
    with pytest.raises(CheckpointError, match=r"sac.hidden=\[32, 32\].*sac.hidden=\[64, 64\]"):
        train_expert(tiny(300, "sac.hidden=[64,64]"), resumed, progress=False)
    os.remove(resumed / "train_state.pt")
    with pytest.raises(CheckpointError, match="without train_state.pt"):
        train_expert(tiny(300), resumed, progress=False)
    with pytest.raises(ConfigError, match="did you mean 'expert.max_steps'"):
        load_expert_config(["expert.max_step=10"])
    with pytest.raises(ConfigError, match="expert.start_steps=10 is below sac.batch_size=256"):
        load_expert_config(["expert.start_steps=10"])


def test_job_script_smoke(tmp_path):
    """jobs/train_expert.py as a subprocess: trains, then a bad key is one `error:` line with exit code 2."""
    out = tmp_path / "job"
    cmd = [sys.executable, str(REPO_ROOT / "jobs" / "train_expert.py"), *TINY,
           "expert.max_steps=120", f"expert.out={out}"]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert r.returncode == 0, r.stderr
    assert "120 env steps" in r.stdout and (out / MODEL_FILE).exists()
    r = subprocess.run(cmd[:2] + ["sac.hiden=[8]"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and r.stderr.strip().startswith("error:") and "did you mean 'sac.hidden'" in r.stderr
