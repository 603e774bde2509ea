"""Robot-arm cubes (issue 19, first slice): the OGBench cube env wrapper, the play datasets, windows, bad inputs."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from fmctd_dist.config import load_config
from fmctd_dist.families.cube.data import (generate_episode, global_numpy_seed, load_cube_dataset,
                                          make_cube_dataset)
from fmctd_dist.families.cube.env import (SUCCESS_RADIUS, CubeEpisodes, cube_columns, cube_xyz, cubes_at_goal,
                                  make_cube_env, to_obs_units)
from fmctd_dist.errors import ConfigError, DatasetError

TINY = ["data.episodes=2", "data.episode_steps=121", "env.horizon=100", "env.max_steps=200",
        "data.train_window=100"]


def tiny_cfg(root, env="cube-single", *extra):
    return load_config([f"env={env}", *TINY, f"data.root={root}", *extra], method="mctd")


@pytest.fixture(scope="module")
def tiny_cube(tmp_path_factory):
    """A 2 (+1 val) episode x 121 step cube-single play dataset, generated once."""
    cfg = tiny_cfg(tmp_path_factory.mktemp("cube"))
    path, manifest = make_cube_dataset(cfg, progress=False)
    return cfg, path, manifest


@pytest.fixture(scope="module")
def episodes():
    envs = {name: CubeEpisodes(name) for name in ("cube-single", "cube-double", "cube-triple")}
    yield envs
    for e in envs.values():
        e.close()


# ---- env wrapper ----

def test_obs_layout(episodes):
    env = episodes["cube-double"]
    r = env.reset(3, seed=0)
    assert r.obs.shape == (19 + 9 * 2,) and r.goal.shape == (6,) and r.goal_obs.shape == r.obs.shape
    u = env._env
    cubes = np.stack([to_obs_units(u._data.joint(f"object_joint_{i}").qpos[:3]) for i in range(2)])
    np.testing.assert_allclose(cube_xyz(r.obs, 2).reshape(2, 3), cubes, atol=1e-6)
    assert list(cube_columns(2)) == [19, 20, 21, 28, 29, 30]
    np.testing.assert_allclose(r.obs[12:15], to_obs_units(u._data.site_xpos[u._pinch_site_id]), atol=1e-6)
    np.testing.assert_allclose(cube_xyz(r.obs, 2)[[2, 5]], 0.2, atol=1e-6)  # on the table: z = 0.02 m -> 0.2
    with pytest.raises(ValueError, match="37 numbers"):
        cube_xyz(r.obs[:28], 2)


# OGBench's task 1 of each env in obs units (docs/reference.md §13), unpermuted: start, goal rows per cube.
TASK1 = {
    "cube-single": ([[0, 1, 0.2]], [[0, -1, 0.2]]),
    "cube-double": ([[0, 0, 0.2], [0, -1, 0.2]], [[0, 0, 0.2], [0, 1, 0.2]]),
    "cube-triple": ([[-0.75, -1, 0.2], [-0.75, 1, 0.2], [0.75, -1, 0.2]],
                    [[-0.75, -1, 0.2], [-0.75, 1, 0.2], [0.75, 1, 0.2]]),
}


@pytest.mark.parametrize("name", ["cube-single", "cube-double", "cube-triple"])
def test_tasks_start_and_goal(episodes, name):
    """Each of the 5 tasks: slot i starts at some task cube (+-0.01 m xy jitter) and its goal is that cube's goal."""
    env = episodes[name]
    np.testing.assert_allclose(env.task_start_goal(1)[0], TASK1[name][0], atol=1e-9)
    np.testing.assert_allclose(env.task_start_goal(1)[1], TASK1[name][1], atol=1e-9)
    for task in (1, 2, 3, 4, 5):
        init, goal = env.task_start_goal(task)
        r = env.reset(task, seed=task)
        start = env.state(r.obs).reshape(-1, 3)
        for s, g in zip(start, r.goal.reshape(-1, 3)):
            j = [k for k in range(len(init)) if np.abs(init[k, :2] - s[:2]).max() <= 0.1 + 1e-6
                 and abs(init[k, 2] - s[2]) < 1e-6 and np.allclose(goal[k], g)]
            assert j, f"{name} task {task}: slot start {s} / goal {g} matches no task cube"
        assert sorted(map(tuple, r.goal.reshape(-1, 3).round(6))) == sorted(map(tuple, goal.round(6)))
        assert not cubes_at_goal(env.state(r.obs), r.goal)  # every task moves at least one cube
        np.testing.assert_allclose(env.state(r.goal_obs), r.goal, atol=0.05)  # OGBench's settled goal obs
    with pytest.raises(ConfigError, match="task=6"):
        env.reset(6, seed=0)


def test_success_rule():
    goal = np.array([0.0, 1.0, 0.2, 1.0, -1.0, 0.2])
    assert cubes_at_goal(goal, goal)
    assert cubes_at_goal(goal + np.array([SUCCESS_RADIUS - 0.01, 0, 0, 0, 0, 0]), goal)
    assert not cubes_at_goal(goal + np.array([0, 0, 0, SUCCESS_RADIUS + 0.01, 0, 0]), goal)  # one cube off: no


def test_seeded_determinism(episodes):
    env = episodes["cube-single"]
    acts = np.random.default_rng(0).uniform(-1, 1, size=(15, 5))

    def run(seed):
        r = env.reset(2, seed=seed)
        return np.concatenate([r.obs, r.goal_obs] + [env.step(a)[0] for a in acts])

    a, b, c = run(7), run(7), run(8)
    assert np.array_equal(a, b)  # arm start, jitter, yaw, settling actions: all from the seed
    assert not np.array_equal(a, c)
    with pytest.raises(ConfigError, match="seed"):
        env.reset(1, seed=-1)


def test_oracle_solves_single_task1(episodes):
    """OGBench's CubePlanOracle (noise off) picks the task-1 cube and places it: OGBench success."""
    from ogbench.manipspace.oracles.plan.cube_plan import CubePlanOracle

    env = episodes["cube-single"]
    r = env.reset(1, seed=0)
    u = env._env
    info = u.compute_ob_info()
    info.update({"privileged/target_block": 0, "privileged/target_block_yaw": np.zeros(1),
                 "privileged/target_block_pos": u._data.mocap_pos[u._cube_target_mocap_ids[0]].copy()})
    with global_numpy_seed(0):
        oracle = CubePlanOracle(env=u, segment_dt=0.4, noise=0.0, noise_smoothing=0.5)
        oracle.reset(r.obs, info)
    ob, success = r.obs, False
    for _ in range(200):
        ob, success = env.step(np.clip(oracle.select_action(ob, u.compute_ob_info()), -1, 1))
        if oracle.done:
            break
    assert success and cubes_at_goal(env.state(ob), r.goal)


def test_make_cube_env_refuses_maze_names():
    with pytest.raises(ConfigError, match="built for"):
        make_cube_env("pointmaze-medium")


# ---- datasets ----

def test_dataset_layout_and_manifest(tiny_cube):
    cfg, path, m = tiny_cube
    assert path.name == "cube-single-play-seed0-2x121"
    assert m["episodes"] == {"train": 2, "val": 1} and m["state_dim"] == 3 and m["obs_dim"] == 28
    assert m["ogbench_episodes"]["train"] == 1000 and m["fraction_of_ogbench"] == 0.002
    assert m["oracle"]["p_stack_per_episode"] == [0.0, 0.0] and m["oracle"]["segment_dt"] == 0.4
    with np.load(path / "train.npz") as z:
        assert z["observations"].shape == (2, 121, 28) and z["actions"].shape == (2, 121, 5)
        assert z["qpos"].shape[:2] == (2, 121) and z["terminals"][:, -1].all() and not z["terminals"][:, :-1].any()
        assert np.abs(z["actions"]).max() <= 1.0 and set(np.unique(z["target_block"])) == {0}
    assert not list(path.parent.glob("*.parts"))  # episode parts are removed once the dataset is written


def test_dataset_determinism_and_resume(tiny_cube, tmp_path, monkeypatch):
    """Same seed -> same sha256; a run interrupted after one episode resumes to the same bytes."""
    import fmctd_dist.families.cube.data as cd

    _, _, m = tiny_cube
    cfg = tiny_cfg(tmp_path)
    real, calls = cd.generate_episode, []

    def dies_on_second(*a, **k):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*a, **k)

    monkeypatch.setattr(cd, "generate_episode", dies_on_second)
    with pytest.raises(KeyboardInterrupt):
        make_cube_dataset(cfg, progress=False)
    monkeypatch.setattr(cd, "generate_episode", real)
    assert len(list(cd.parts_dir(cfg).glob("train-*.npz"))) == 1
    (cd.parts_dir(cfg) / "val-00000.npz").write_bytes(b"not a zip")  # an unreadable part is made again
    _, m2 = make_cube_dataset(cfg, progress=False)
    assert m2["sha256"] == m["sha256"] and m2["stats"]["train"]["episodes_generated_in_last_run"] == 1
    assert m2["stats"]["val"]["episodes_generated_in_last_run"] == 1
    other = tiny_cfg(tmp_path / "seed1", "cube-single", "data.seed=1")
    assert make_cube_dataset(other, progress=False)[1]["sha256"]["train"] != m["sha256"]["train"]


def test_episode_is_a_function_of_its_seeds():
    env = make_cube_env("cube-double", mode="data_collection")
    a, _ = generate_episode(env, 40, 0.1, (1, 2))
    generate_episode(env, 40, 0.1, (3, 4))
    b, _ = generate_episode(env, 40, 0.1, (1, 2))
    assert all(np.array_equal(a[k], b[k]) for k in a)
    state = np.random.get_state()[1].copy()
    generate_episode(env, 5, 0.1, (5, 6))
    assert np.array_equal(np.random.get_state()[1], state)  # the caller's global RNG is left alone


@pytest.mark.parametrize("jump, tokens", [(1, 11), (5, 3)])
def test_windows_over_cube_xyz(tiny_cube, jump, tokens):
    from fmctd_dist.data.windows import train_data

    cfg, path, _ = tiny_cube
    ds = load_cube_dataset(cfg)
    assert ds.train.shape == (2, 121, 3) and ds.val.shape == (1, 121, 3) and ds.train.dtype == np.float32
    cfg = tiny_cfg(path.parent, "cube-single", f"jump={jump}")
    data = train_data(cfg, ds)
    x = data.sample(np.random.default_rng(0), 4)
    assert x.shape == (4, tokens, 3 * cfg.model.frame_stack) == (4, data.n_tokens, 30)
    np.testing.assert_allclose(ds.normaliser.unnormalise(x[:, 0, :3]).reshape(4, 3)[:, 2].min(), 0.2, atol=0.3)


# ---- bad inputs ----

def test_unknown_cube_env_suggests():
    with pytest.raises(ConfigError, match="did you mean 'cube-single'"):
        load_config(["env=cube-singel"], method="mctd")
    from fmctd_dist.registry import env_spec

    with pytest.raises(ConfigError, match="did you mean 'cube-triple'"):
        env_spec("cube-tripel")


def test_dataset_of_another_env(tiny_cube, tmp_path):
    _, path, _ = tiny_cube
    with pytest.raises(DatasetError, match="cube dataset .env=cube-single.* env.name=cube-double"):
        load_cube_dataset(tiny_cfg(tmp_path, "cube-double"), path)


def test_cube_data_for_a_maze_model(tiny_cube, tmp_path):
    """A cube dataset given to a maze config, and a maze dataset given to a cube config: one DatasetError each."""
    import json

    from fmctd_dist.families.cube.data import load_cube_manifest
    from fmctd_dist.families.maze.data import load_dataset

    cfg, path, m = tiny_cube
    with pytest.raises(DatasetError, match="env='cube-single'.*env.name=pointmaze-medium"):
        load_dataset(load_config(["env=pointmaze-medium"], method="mctd"), path)
    (tmp_path / "manifest.json").write_text(json.dumps({**m, "env": "pointmaze-medium"}))
    with pytest.raises(DatasetError, match="is a pointmaze dataset"):
        load_cube_manifest(tmp_path, cfg)


def test_maze_code_refuses_cube_envs(tiny_cube):
    """The maze code guards its own entries: a cube env name stops there with one error naming the cube jobs."""
    from fmctd_dist.families.maze.data import load_dataset, make_dataset
    from fmctd_dist.families.maze.make import make_env
    from fmctd_dist.families.maze.geometry import maze_geometry

    cfg, _, _ = tiny_cube
    for call in (lambda: make_env("cube-single"), lambda: maze_geometry("cube-double"),
                 lambda: load_dataset(cfg), lambda: make_dataset(cfg)):
        with pytest.raises(ConfigError, match="is a cube env.*for pointmaze / antmaze envs only.*eval.py env=cube"):
            call()


def test_make_dataset_job_smoke(tmp_path):
    """jobs/make_dataset.py env=cube-single as a subprocess, tiny: it writes the play dataset and says so."""
    import subprocess
    import sys

    from fmctd_dist.config import REPO_ROOT

    words = ["env=cube-single", "data.episodes=1", "data.episode_steps=61", "env.horizon=50", "env.max_steps=50",
             "data.train_window=50", f"data.root={tmp_path}"]
    out = subprocess.run([sys.executable, "jobs/make_dataset.py", *words], cwd=REPO_ROOT, capture_output=True,
                         text=True, timeout=300, env={**__import__("os").environ, "OMP_NUM_THREADS": "1"})
    assert out.returncode == 0, out.stderr[-2000:]
    assert "generated" in out.stdout and "0% of OGBench's 1000 episodes" in out.stdout
    assert (tmp_path / "cube-single-play-seed0-1x61" / "manifest.json").is_file()
    bad = subprocess.run([sys.executable, "jobs/eval.py", "env=cube-single", f"checkpoint={tmp_path / 'none'}"],
                         cwd=REPO_ROOT, capture_output=True, text=True, timeout=300)  # no model: one error, the fix
    assert bad.returncode != 0 and "python jobs/train" in bad.stderr + bad.stdout


# ---- Diffusion Forcing models on cube xyz (frames of 3 numbers per cube) ----

@pytest.mark.parametrize("param", ["x0", "v_offset"])
def test_train_and_load_a_cube_model(tiny_cube, tmp_path, param):
    """jobs/train.py's path for a cube env: the family's data, 3-D frames, a checkpoint that loads for cube-single
    and is refused, by name, for a maze env."""
    import torch

    from fmctd_dist.families import load_dataset, make_dataset
    from fmctd_dist.data.windows import train_data
    from fmctd_dist.diffusion.checkpoint import load_checkpoint
    from fmctd_dist.diffusion.train import train
    from fmctd_dist.errors import CheckpointError

    _, path, _ = tiny_cube
    small = ["model.width=32", "model.layers=1", "model.heads=2", "model.ff=64", f"model.param={param}",
             "train.max_steps=2", "train.batch_size=4", "train.val_batches=1", "train.warmup=1", "jump=5"]
    cfg = tiny_cfg(path.parent, "cube-single", *small)
    assert (cfg.frame_dim, cfg.token_dim, cfg.n_tokens) == (3, 30, 3)
    assert make_dataset(cfg, progress=False)[0] == path  # the registry finds (and verifies) the cube data
    train(cfg, train_data(cfg, load_dataset(cfg)), tmp_path / "ckpt", progress=False)
    model, manifest = load_checkpoint(tmp_path / "ckpt", cfg)
    assert manifest["token_dim"] == 30 and model.frame_dim == 3
    x = torch.randn(2, 3, 30)
    assert model(x, torch.zeros(2, 3, dtype=torch.long)).shape == (2, 3, 30)
    from conftest import load_job

    # the quality-table row runs end to end on a cube model
    row = load_job("plan_quality").cube_plan_quality(tmp_path / "ckpt", cfg, n=4)
    assert row["warp"] == 2.0 and row["data"]["no_warp"] == 1.0 and 0.0 <= row["model"]["no_warp"] <= 1.0
    maze = load_config(["env=pointmaze-medium", "jump=5", *small[:5]], method="mctd")
    with pytest.raises(CheckpointError, match="env.name='cube-single'.*env.name='pointmaze-medium'"):
        load_checkpoint(tmp_path / "ckpt", maze)


def test_v_offset_keeps_each_cube_coordinate_apart():
    """v_offset's token offset is a mean per frame coordinate: with 3-D frames it must not mix x with y or z."""
    import torch

    from fmctd_dist.diffusion.model import token_offset

    frames = torch.arange(2 * 3, dtype=torch.float32).reshape(1, 1, 2, 3)  # one token, 2 frames of (x, y, z)
    off = token_offset(frames.reshape(1, 1, 6), frame_dim=3).reshape(2, 3)
    assert torch.equal(off, torch.tensor([[1.5, 2.5, 3.5]] * 2))


def test_cube_plan_rules_on_hand_made_plans():
    """The quality table's rules: a warp, a cube left mid-air, a clean stack, two cubes moved at once."""
    from conftest import load_job

    quality = load_job("plan_quality")
    plan_row, supported = quality.plan_row, quality.supported

    start = np.array([[0.0, 0.0, 0.2, 2.0, 0.0, 0.2]])  # two cubes on the table
    lift = np.linspace(start[0], [0.0, 0.0, 1.5, 2.0, 0.0, 0.2], 9)[1:][None]  # cube 0 lifted, left mid-air
    stack = np.linspace(start[0], [2.0, 0.1, 0.6, 2.0, 0.0, 0.2], 9)[1:][None]  # cube 0 onto cube 1
    both = np.linspace(start[0], [1.5, 0.0, 0.2, 3.5, 0.0, 0.2], 9)[1:][None]  # both slide 1.5
    jump = stack.copy()
    jump[0, 4:] += [1.0, 1.0, 0.0, 0.0, 0.0, 0.0]  # cube 0 jumps by 1.41 at frame 4 (H=1 threshold 1.0)
    assert supported(stack[:, -1]).all() and not supported(lift[:, -1]).any() and supported(start).all()
    r = {name: plan_row(p, start, jump=1, frame_stack=4) for name, p in
         (("lift", lift), ("stack", stack), ("both", both), ("jump", jump))}
    assert r["stack"]["no_warp"] == 1 and r["stack"]["supported_end"] == 1 and r["stack"]["one_mover"] == 1
    assert r["lift"]["supported_end"] == 0 and r["lift"]["moved"] == 1
    assert r["both"]["one_mover"] == 0 and r["both"]["supported_end"] == 1
    assert r["jump"]["no_warp"] == 0 and r["jump"]["max_step"] > 1.0


def test_quality_curve_job_on_cube_snapshots(tiny_cube, tmp_path, capsys):
    """jobs/bench/quality_curve.py measures each snapshot once (cached by digest) and draws the curve."""
    from conftest import load_job

    from fmctd_dist.families import load_dataset
    from fmctd_dist.data.windows import train_data
    from fmctd_dist.diffusion.train import train

    _, path, _ = tiny_cube
    cfg = tiny_cfg(path.parent, "cube-single", "model.width=32", "model.layers=1", "model.heads=2", "model.ff=64",
                   "train.max_steps=4", "train.batch_size=4", "train.val_batches=1", "train.warmup=1", "jump=5",
                   "train.ckpt_every=2", "train.snapshot_every_s=1e-9")
    train(cfg, train_data(cfg, load_dataset(cfg)), tmp_path / "run", progress=False)
    job = load_job("quality_curve")
    rows = job.points(tmp_path / "run")
    assert [r["steps"] for _, r in rows] == [2, 4] and all(0 <= r["unguided_no_warp"] <= 1 for _, r in rows)
    assert all((tmp_path / "run" / "snapshots" / name / "quality.json").exists() for name, _ in rows)
    assert job.main([str(tmp_path / "run"), "--plot", str(tmp_path / "curve.png")]) == 0
    assert "| k" in capsys.readouterr().out and (tmp_path / "curve.png").stat().st_size > 1000


def test_bench_denoiser_cube_overrides_apply_to_every_checkpoint():
    """`bench_denoiser --cube data.episodes=300 A B` measures models trained on different data sizes on one
    validation split: the words override each checkpoint's own config; a bad word is one ConfigError."""
    from conftest import load_job

    from fmctd_dist.config import REPO_ROOT, config_from_dict

    bench = load_job("bench_denoiser")
    ckpt = REPO_ROOT / "checkpoints" / "cube-triple-h5"
    own = config_from_dict(json.loads((ckpt / "manifest.json").read_text())["config"])
    assert bench.checkpoint_config(ckpt, []) is None
    other = own.data.episodes + 100
    cfg = bench.checkpoint_config(ckpt, [f"data.episodes={other}"])
    assert cfg.data.episodes == other
    assert dataclasses.replace(cfg, data=own.data) == own  # nothing else changed
    with pytest.raises(ConfigError, match="data.episodes"):
        bench.checkpoint_config(ckpt, ["data.episodes=-1"])
    with pytest.raises(SystemExit, match="no checkpoint \\(manifest.json\\) at no-such-dir"):
        bench.main(["--cube", "data.episodes=300", "no-such-dir"])
