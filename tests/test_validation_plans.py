"""jobs/probes/validation_plans.py: validation pairs leave the evaluation tasks out; a plan's success as the value
reads it, plus the wall test."""

from __future__ import annotations

import numpy as np
from conftest import load_job

from fmctd_dist.families.maze.geometry import MazeGeometry, Task

# a 4 x 5 maze: a U of free cells around the wall cell (1, 2)
WALLS = np.array([[1, 1, 1, 1, 1], [1, 0, 1, 0, 1], [1, 0, 0, 0, 1], [1, 1, 1, 1, 1]])
XY = MazeGeometry.cell_to_xy


def geometry() -> MazeGeometry:
    task = Task(1, (1, 1), (1, 3), XY((1, 1)), XY((1, 3)))
    return MazeGeometry("toy", WALLS, (task,) * 5)


def test_pairs_avoid_the_tasks_and_short_hops():
    job = load_job("validation_plans")
    geo = geometry()
    pairs = job.validation_pairs(geo, 12, seed=1)
    assert len(pairs) == 12
    assert all({a, b} != {(1, 1), (1, 3)} and geo.bfs(b)[a] >= 2 for a, b in pairs)
    assert pairs == job.validation_pairs(geo, 12, seed=1)  # seeded


def test_a_plan_through_the_wall_reaches_but_is_not_valid():
    job = load_job("validation_plans")
    geo = geometry()
    start, goal = XY((1, 1)), XY((1, 3))
    straight = np.linspace(start, goal, 9)[1:]  # through the wall cell (1, 2), steps of 1
    assert job.plan_success(straight, start, goal, 1, 1.5, 2.0, geo) == (False, True)
    around = np.concatenate([np.linspace(start, XY((2, 1)), 5)[1:], np.linspace(XY((2, 1)), XY((2, 3)), 9)[1:],
                             np.linspace(XY((2, 3)), goal, 5)[1:]])
    assert job.plan_success(around, start, goal, 1, 1.5, 2.0, geo) == (True, True)
    # the planner's last step, from the reach frame on to the goal, may be longer than the warp threshold
    up = np.linspace(XY((2, 3)), goal, 9)[1:]  # steps of 0.5
    reached = np.concatenate([np.linspace(start, XY((2, 1)), 9)[1:], np.linspace(XY((2, 1)), XY((2, 3)), 17)[1:],
                              up[:5], goal[None]])  # the reach frame is 1.5 from the goal, then the goal itself
    assert job.plan_success(reached, start, goal, 1, 1.0, 2.0, geo) == (True, True)
    assert job.plan_success(np.repeat(around, 5, axis=0), start, goal, 5, 1.5, 2.0, geo) == (True, True)  # sparse
    assert job.plan_success(around[:6], start, goal, 1, 1.5, 2.0, geo) == (True, False)  # valid, short of the goal


def test_the_ant_walks_a_straight_plan_and_clearances_need_an_ant(capsys):
    import pytest

    from fmctd_dist.config import load_config
    from fmctd_dist.errors import ConfigError
    from fmctd_dist.families.maze.make import make_env
    from fmctd_dist.families.maze.robots import controller_factory

    job = load_job("validation_plans")
    with pytest.raises(ConfigError, match="clearances=.*not an AntMaze"):
        job.main(["env=pointmaze-medium", "clearances=[0,1.5]"])
    env = make_env("antmaze-medium")  # cells (1, 1) -> (1, 2) of medium: free, one cell apart
    start, goal = XY((1, 1)), XY((1, 2))
    plan = np.linspace(start, goal, 40)
    make = controller_factory(load_config(["env=antmaze-medium", "env.wall_clearance=1.5"]))
    assert job.walk(env, make(plan), start, goal, seed=0, steps=200)
    assert not job.walk(env, make(plan[:1]), start, goal, seed=0, steps=30)  # stays at the start: never reaches


def test_a_visual_planner_plans_between_the_frames_seen_at_the_pair(capsys):
    """On the visual maze the pairs are rendered and encoded as an episode's start and goal; the table's row
    reads the plan's world path (its own (x, y) at the visual default)."""
    from conftest import torch_threads

    job = load_job("validation_plans")
    with torch_threads(1):
        assert job.main(["env=visual-pointmaze-medium", "method=fast-mctd", "pairs=2",
                         "settings=[method.budget=10 method.parallel=5]"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("visual-pointmaze-medium fast-mctd: 2 validation pairs (seed 0)")
    row = [ln for ln in out.splitlines() if ln.startswith("| method.budget=10")]
    assert len(row) == 1 and row[0].split(" | ")[1].endswith("/2)")
