"""Failure diagnosis from result rows: wall-cutting plans and robots that stopped."""

import numpy as np

from conftest import load_job
from fmctd_dist.families.maze.geometry import maze_geometry
from fmctd_dist.families.maze.geometry import densify

failures = load_job("why_failed").failures  # jobs/probes/why_failed.py's maze measure


def row(plan, traj, success=False, status="early_stop"):
    return {"env": "pointmaze-medium", "task": 3, "seed": 0, "success": success, "plan_status": status,
            "env_steps": len(traj) - 1, "plan_xy": np.asarray(plan).ravel().tolist(),
            "traj_xy": np.asarray(traj).ravel().tolist()}


def test_a_plan_whose_straight_step_crosses_a_wall_is_caught_between_its_points():
    geo = maze_geometry("pointmaze-medium")
    start, beyond = np.array([8.0, 16.0]), np.array([0.0, 16.0])  # free cells on both sides of the wall at (4, 16)
    assert geo.in_free_cell(np.stack([start, beyond])).all() and not geo.in_free_cell(np.array([4.0, 16.0]))
    still = np.repeat(start[None], 300, axis=0)
    (f,) = failures([row([start, beyond], still), row([start, beyond], still, success=True)])
    assert 0 < f["plan_in_free"] < 1  # both plan points are free, the path between them is not
    assert f["stopped"] and f["status"] == "early_stop" and f["plan_len"] == 2


def test_a_moving_robot_is_not_stopped_and_replans_are_counted():
    traj = np.stack([np.linspace(0, 20, 300), np.zeros(300)], axis=1)
    (f,) = failures([row([[0, 0], [0, 1]], traj, status="plan,plan,plan")])
    assert not f["stopped"] and f["status"] == "3 plans" and f["plan_in_free"] == 1.0


def test_path_in_free_judges_whole_polylines_batched():
    """plan_quality's "valid" share rests on this: a step between two free points across a wall fails."""
    geo = maze_geometry("pointmaze-medium")
    start, beyond = np.array([8.0, 16.0]), np.array([0.0, 16.0])
    along = start + np.array([0.0, 0.5])
    paths = np.stack([np.stack([start, along, start]), np.stack([start, along, beyond])])  # [2, 3, 2]
    assert geo.in_free_cell(paths).all()  # every vertex is free ...
    assert geo.path_in_free(paths).tolist() == [True, False]  # ... the second path's last step is not
    assert densify(paths).shape == (2, 21, 2) and np.allclose(densify(paths)[:, ::10], paths)
