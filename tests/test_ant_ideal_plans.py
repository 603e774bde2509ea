"""jobs/probes/ant_ideal_plans.py: the ideal plan follows the BFS cells, rounds corners inside them, keeps its pace."""

from __future__ import annotations

import numpy as np
from conftest import load_job

from fmctd_dist.families.maze.geometry import MazeGeometry, Task

# a 4 x 5 maze: a U of free cells around the wall cell (1, 2)
WALLS = np.array([[1, 1, 1, 1, 1], [1, 0, 1, 0, 1], [1, 0, 0, 0, 1], [1, 1, 1, 1, 1]])
XY = MazeGeometry.cell_to_xy


def test_the_ideal_plan_goes_round_the_wall_at_the_given_pace():
    job = load_job("ant_ideal_plans")
    geo = MazeGeometry("toy", WALLS, (Task(1, (1, 1), (1, 3), XY((1, 1)), XY((1, 3))),) * 5)
    start, goal = XY((1, 1)) + [0.3, -0.2], XY((1, 3))
    path = job.cell_path(geo, start, goal)
    assert np.allclose(path[0], start) and np.allclose(path[-1], goal)
    assert [geo.xy_to_cell(p) for p in path[1:-1]] == [(2, 1), (2, 2), (2, 3), (1, 3)]
    plan = job.IdealPlanner(geo, 0.25, 1.0).plan(start, goal, seed=0).waypoints
    steps = np.linalg.norm(np.diff(plan, axis=0), axis=1)
    assert steps.max() <= 0.25 + 1e-6 and np.median(steps) > 0.24  # the pace, with the last step shorter
    assert geo.path_in_free(plan) and np.allclose(plan[-1], goal, atol=1e-6)
    sharp = job.resample(path, 0.25)
    assert len(plan) < len(sharp)  # rounded corners cut the path inside the free cells
