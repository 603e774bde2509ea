"""AntMaze (issue 9): env contract, expert-driven navigate data (determinism, 29-D rows, the
expert recorded and checked), clear errors, and evaluation refused up front. No Ray."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from fmctd_dist.config import REPO_ROOT, load_config
from fmctd_dist.families import hooks_for
from fmctd_dist.families.maze.data import dataset_dir, load_dataset, make_dataset
from fmctd_dist.errors import CheckpointError, ConfigError, DatasetError

pytestmark = pytest.mark.usefixtures("one_torch_thread")

EXPERT = REPO_ROOT / "checkpoints" / "ant-expert"
TINY_ANT = ["env=antmaze-medium", "data.episodes=2", "data.episode_steps=30", "env.horizon=10",
            "data.train_window=10"]


def ant_cfg(root, *extra: str):
    return load_config([*TINY_ANT, f"data.root={root}", *extra], method="mctd")


@pytest.fixture(scope="module")
def ant_dataset(tmp_path_factory):
    """2 train + 1 val episodes of 30 steps on antmaze-medium, made once by the shipped expert."""
    cfg = ant_cfg(tmp_path_factory.mktemp("antdata"))
    path, manifest = make_dataset(cfg, progress=False)
    return cfg, path, manifest


# ---- env ----

def test_make_env_gives_an_ant_with_29d_obs_and_8d_actions():
    from fmctd_dist.families.maze.make import make_env
    from fmctd_dist.families.maze.antmaze import AntMaze

    env = make_env("antmaze-medium")
    assert isinstance(env, AntMaze) and env.geometry.name == "antmaze-medium"
    r = env.reset(1, seed=0)
    assert r.obs.shape == (29,) and r.goal.shape == (2,)
    assert np.array_equal(r.obs[:2], [0.0, 0.0]) and np.array_equal(r.goal, [20.0, 20.0])  # task 1 cell centres
    assert np.array_equal(env.reset(1, seed=0).obs, r.obs)  # joint noise comes from the seed only
    assert not np.array_equal(env.reset(1, seed=1).obs, r.obs)
    obs, success = env.step(np.zeros(8))
    assert obs.shape == (29,) and success is False and env.healthy() and env.upright()
    with pytest.raises(ValueError, match=r"takes \(8,\)"):
        env.step(np.zeros(2))
    noisy = make_env("antmaze-medium", "ogbench").reset(1, seed=0)
    assert 0 < np.abs(noisy.obs[:2]).max() <= 1.0 and 0 < np.abs(noisy.goal - 20.0).max() <= 1.0
    env.close()


def test_success_is_within_half_a_metre_after_the_step():
    from fmctd_dist.families.maze.make import make_env

    env = make_env("antmaze-medium")
    env.reset(2, seed=0)
    for offset, want in ((0.3, True), (0.7, False)):
        env.set_goal(env.position() + np.array([offset, 0.0]))
        _, success = env.step(np.zeros(8))
        assert success is want
        assert success == (np.linalg.norm(env.position() - env.goal) <= 0.5)
    env.close()


def test_fall_detectors_on_hand_made_states():
    from fmctd_dist.families.maze.antmaze import healthy, upright

    obs = np.zeros((3, 29))
    obs[:, 2] = [0.55, 0.1, 0.3]  # torso height
    obs[:, 3:7] = [[1, 0, 0, 0], [1, 0, 0, 0], [0, 1, 0, 0]]  # upright, upright, on its back
    assert healthy(obs).tolist() == [True, False, True]
    assert upright(obs).tolist() == [True, True, False]


# ---- dataset ----

def test_same_config_same_bytes_other_seed_other_bytes(ant_dataset, tmp_path):
    cfg, path, manifest = ant_dataset
    path2, manifest2 = make_dataset(ant_cfg(tmp_path, "data.workers=2"), progress=False)  # one process per episode
    for split in ("train", "val"):
        assert (path / f"{split}.npz").read_bytes() == (path2 / f"{split}.npz").read_bytes()
    strip = lambda m: {k: v for k, v in m.items() if k not in ("generation", "_generation_s")}  # noqa: E731
    assert strip(manifest) == strip(manifest2)
    assert manifest["generation"]["workers"] == 1 and manifest2["generation"]["workers"] == 2
    _, manifest3 = make_dataset(ant_cfg(tmp_path, "data.seed=1"), progress=False)
    assert manifest3["sha256"]["train"] != manifest["sha256"]["train"]


def test_rows_keep_the_29d_state_and_loading_gives_xy(ant_dataset):
    cfg, path, manifest = ant_dataset
    with np.load(path / "train.npz") as z:
        rows = {k: z[k] for k in z.files}
    assert sorted(rows) == ["actions", "goals", "observations", "terminals"]
    assert rows["observations"].shape == (2, 30, 29) and rows["actions"].shape == (2, 30, 8)
    assert rows["goals"].shape == (2, 30, 2) and rows["terminals"][:, -1].all() and not rows["terminals"][:, :-1].any()
    assert np.abs(rows["actions"]).max() <= 1.0
    ds = load_dataset(cfg)
    assert ds.train.shape == (2, 30, 2) and ds.val.shape == (1, 30, 2)
    assert np.array_equal(ds.train, rows["observations"][..., :2])
    assert np.allclose(ds.normaliser.mean, rows["observations"][..., :2].reshape(-1, 2).mean(0), atol=1e-4)
    expert = json.loads((EXPERT / "manifest.json").read_text())
    assert manifest["expert"]["model_sha256"] == expert["model_sha256"] and manifest["noise"] == 0.2
    stats = manifest["stats"]["train"]
    assert stats["env_steps"] == 60 and 0 <= stats["upside_down_fraction"] <= 1
    assert {"goals_per_1000_steps", "unhealthy_fraction", "episodes_fallen", "mean_speed_m_per_s"} <= set(stats)
    assert manifest["generation"]["env_steps_per_s"] > 0


def test_windows_for_training_on_xy(ant_dataset):
    from fmctd_dist.data.windows import train_data

    cfg, _, _ = ant_dataset
    batch = train_data(cfg, load_dataset(cfg)).sample(np.random.default_rng(0), 4)
    assert batch.shape == (4, cfg.n_tokens, cfg.token_dim)


def test_data_from_another_expert_is_refused(ant_dataset, tmp_path):
    cfg, path, _ = ant_dataset
    other = tmp_path / "other-expert"
    shutil.copytree(EXPERT, other)
    m = json.loads((other / "manifest.json").read_text())
    m["model_sha256"], m["digest"] = "0" * 64, "0" * 16
    (other / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(DatasetError, match="made by ant expert 'a65a.*data.expert="):
        load_dataset(load_config([*TINY_ANT, f"data.root={cfg.data.root}", f"data.expert={other}"], method="mctd"))


# ---- clear errors ----

def test_a_planner_checkpoint_as_expert_is_one_clear_error(tmp_path):
    cfg = ant_cfg(tmp_path, f"data.expert={REPO_ROOT / 'checkpoints' / 'pointmaze-medium-h5'}")
    with pytest.raises(CheckpointError, match="not an ant direction expert"):
        make_dataset(cfg, progress=False)
    assert not dataset_dir(cfg).exists()  # checked before anything is written


def test_missing_expert_dir_is_one_clear_error(tmp_path):
    cfg = ant_cfg(tmp_path, f"data.expert={tmp_path / 'nope'}")
    with pytest.raises(CheckpointError, match="does not exist.*train_expert.py"):
        make_dataset(cfg, progress=False)
    with pytest.raises(ConfigError, match="data.expert is empty"):
        ant_cfg(tmp_path, "data.expert=''")


def test_wrong_observation_size_to_the_expert():
    from fmctd_dist.families.maze.expert.direction_env import expert_input
    from fmctd_dist.families.maze.expert.expert import load_expert

    expert = load_expert(EXPERT)
    ob = np.zeros(29)
    assert expert.act(expert_input(ob, np.array([1.0, 0.0]))).shape == (8,)
    with pytest.raises(CheckpointError, match="obs_dim=29"):
        expert.act(np.concatenate([ob, [1.0, 0.0]]))  # the maze obs + direction, x, y not dropped
    with pytest.raises(ValueError, match="29-D OGBench ant observation"):
        expert_input(ob[2:], np.array([1.0, 0.0]))  # x, y already dropped


def test_unknown_env_names_suggest_the_closest():
    from fmctd_dist.families.maze.make import make_env

    with pytest.raises(ConfigError, match="did you mean 'antmaze-medium'"):
        load_config(["env=antmaze-medim"])
    with pytest.raises(ConfigError, match="did you mean 'antmaze-giant'"):
        make_env("antmaze-gaint")
    with pytest.raises(ConfigError, match="did you mean 'pointmaze-giant'"):
        load_config(["env=pointmaze-gaint"])


def test_ant_env_configs_follow_the_paper():
    for maze, (steps, horizon, episodes, ep_steps) in {"medium": (1000, 500, 1000, 1001),
                                                       "large": (1000, 500, 1000, 1001),
                                                       "giant": (1500, 1000, 500, 2001)}.items():
        cfg = load_config([f"env=antmaze-{maze}"])
        assert (cfg.env.max_steps, cfg.env.horizon, cfg.data.episodes, cfg.data.episode_steps) == \
            (steps, horizon, episodes, ep_steps)
        assert cfg.data.noise == 0.2 and cfg.data.expert == "checkpoints/ant-expert"


def test_antmaze_evaluation_without_a_policy_fails_before_anything_starts(tmp_path):
    from fmctd_dist.evaluation.grid import prepare

    missing = tmp_path / "no-policy"
    cfg = load_config(["env=antmaze-medium", "runner=local", "tasks=[1]", "seeds=[0]", f"env.policy={missing}"])
    with pytest.raises(CheckpointError, match=r"env.policy=.*no-policy \(the ant's low-level policy"):
        prepare(cfg, hooks_for)
    # a planner checkpoint is not a policy: one clear error naming what it is
    cfg = load_config(["env=antmaze-medium", "env.policy=checkpoints/pointmaze-medium-h5"])
    with pytest.raises(CheckpointError, match="not a goal-conditioned ant policy"):
        prepare(cfg, hooks_for)
    out = subprocess.run([sys.executable, str(REPO_ROOT / "jobs" / "eval.py"), "env=antmaze-medium",
                          f"env.policy={missing}"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    assert out.stderr.strip().startswith("error: env.policy=")
    assert "Traceback" not in out.stderr
