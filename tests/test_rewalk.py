"""jobs/probes/rewalk.py: an open-loop ant episode walked again gives the row's outcome; bad input is refused."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import load_job

from fmctd_dist.config import load_config
from fmctd_dist.errors import ConfigError
from fmctd_dist.evaluation.identity import config_hash, identity_columns
from fmctd_dist.evaluation.results import ResultStore
from fmctd_dist.families.maze.episode import run_episode
from fmctd_dist.families.maze.geometry import maze_geometry
from fmctd_dist.families.maze.make import make_env


def _rows(tmp_path, plans: int = 1):
    """Two AntMaze-medium task-1 rows made by the evaluation's episode with the ideal plan, 150 steps each."""
    ideal = load_job("ant_ideal_plans")
    cfg = load_config(["env=antmaze-medium", "env.max_steps=150", "env.horizon=150", "data.train_window=150",
                       "env.wall_clearance=1"], env="antmaze-medium")
    env, store = make_env(cfg.env.name), ResultStore(tmp_path, "run")
    planner = ideal.IdealPlanner(maze_geometry(cfg.env.name), ideal.DATA_SPEED, 1.0)
    for seed in (0, 1):
        row = {**run_episode(cfg, env, planner, 1, seed), "method": "fast-mctd", "env": cfg.env.name,
               "task": 1, "seed": seed, **identity_columns(cfg)}
        store.write({**row, "plans": plans})
    return tmp_path / "run" / "fast-mctd" / "antmaze-medium", cfg


def test_the_walk_is_the_episode_and_other_clearances_walk_the_same_plans(tmp_path, capsys):
    job = load_job("rewalk")
    directory, cfg = _rows(tmp_path)
    rows = job.read_rows(directory)
    assert [r["seed"] for r in rows] == [0, 1]
    assert config_hash(job.row_config(rows[0])) == config_hash(cfg) == rows[0]["config_hash"]  # the row's own config
    assert job.row_config(rows[0]).env.max_steps == 150 and job.row_config(rows[0], 0).env.wall_clearance == 0
    assert job.main([str(directory), "clearances=[1,0]"]) == 0
    out = capsys.readouterr().out
    assert "recorded at clearance 1.0" in out
    assert "clearance 1.0: " in out and ", 2 agree with the rows" in out.split("clearance 0.0")[0]
    reached, steps, traj, up = job.walk(make_env(cfg.env.name), _controller(cfg, rows[0]), rows[0], 150)
    assert steps == rows[0]["env_steps"] and reached == rows[0]["success"]
    assert np.allclose(traj.reshape(-1), rows[0]["traj_xy"], atol=1e-5) and up


def _controller(cfg, row):
    from fmctd_dist.families.maze.robots import controller_factory

    return controller_factory(cfg)(np.asarray(row["plan_xy"]).reshape(-1, 2))


def test_replanned_rows_and_a_missing_directory_are_refused(tmp_path):
    job = load_job("rewalk")
    with pytest.raises(ConfigError, match="no result rows"):
        job.main([str(tmp_path / "nothing")])
    directory, _ = _rows(tmp_path, plans=3)
    with pytest.raises(ConfigError, match="replanned"):
        job.main([str(directory)])


def test_bad_clearances_and_flags_are_refused_before_any_walk(tmp_path):
    job = load_job("rewalk")
    directory, _ = _rows(tmp_path)
    with pytest.raises(ConfigError, match="env.wall_clearance=3.0 must be"):
        job.main([str(directory), "clearances=[0,3]"])
    with pytest.raises(ConfigError, match="give numbers"):
        job.main([str(directory), "clearances=[a]"])
    with pytest.raises(ConfigError, match="unknown flag --all"):
        job.main([str(directory), "--all"])


def test_a_row_without_a_recorded_config_cannot_be_rebuilt():
    from fmctd_dist.errors import ResultsError
    from fmctd_dist.evaluation.identity import recorded_config

    with pytest.raises(ResultsError, match="records no config"):
        recorded_config({"method": "fast-mctd", "env": "antmaze-large", "task": 1, "seed": 0})
