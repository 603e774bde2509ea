"""The robot's copy of a plan kept off the walls (env.wall_clearance): where points go, and off means the paper's."""

from __future__ import annotations

import numpy as np
import pytest

from fmctd_dist.config import load_config
from fmctd_dist.errors import ConfigError
from fmctd_dist.families.maze.clearance import keep_clear
from fmctd_dist.families.maze.geometry import MAZE_UNIT, MazeGeometry
from fmctd_dist.families.maze.pd import PDController
from fmctd_dist.families.maze.robots import controller_factory

# a 3 x 5 maze: walls around, a corridor of three free cells (1, 1) (1, 2) (1, 3) along x
GEO = MazeGeometry("toy", np.array([[1, 1, 1, 1, 1], [1, 0, 0, 0, 1], [1, 1, 1, 1, 1]]), ())


def wall_distance(xy: np.ndarray) -> np.ndarray:
    """Distance from points in the corridor to its two long walls (its ends are far from the test points)."""
    centre_y = MazeGeometry.cell_to_xy((1, 2))[1]
    return 0.5 * MAZE_UNIT - np.abs(xy[:, 1] - centre_y)


def test_points_near_a_wall_move_out_along_its_normal_and_clear_ones_stay():
    centre = MazeGeometry.cell_to_xy((1, 2))
    plan = centre + np.array([[0.0, 0.0], [0.3, 1.2], [-0.4, -1.9], [0.0, 0.4]])
    out = keep_clear(plan, GEO, 1.5)
    assert np.array_equal(out[[0, 3]], plan[[0, 3]])  # 2.0 and 1.6 from the walls: left alone
    assert np.allclose(out[:, 0], plan[:, 0])  # pushed straight off the long walls, never along them
    assert wall_distance(out[1:3]).min() == pytest.approx(1.5, abs=1e-4)


def test_a_point_inside_a_wall_comes_back_into_the_corridor():
    inside = MazeGeometry.cell_to_xy((0, 2)) + np.array([0.2, 1.0])  # 1 unit into the wall below the corridor
    out = keep_clear(inside[None], GEO, 1.0)
    assert GEO.in_free_cell(out).all() and wall_distance(out)[0] == pytest.approx(1.0, abs=1e-4)


def test_the_corridor_centre_is_as_far_as_a_point_can_go():
    centre = MazeGeometry.cell_to_xy((1, 2))
    out = keep_clear(centre + np.array([[0.0, 1.9]]), GEO, 2.0)
    assert out[0, 1] == pytest.approx(centre[1], abs=1e-4)  # between two walls 4 apart: the middle


def test_off_is_the_plan_itself_and_mazes_only():
    plan = np.random.default_rng(0).normal(size=(7, 2))
    assert np.array_equal(keep_clear(plan, GEO, 0.0), plan)
    assert controller_factory(load_config(["env=pointmaze-medium"])) is PDController  # the paper's controller
    with pytest.raises(ConfigError, match="env.wall_clearance=1.5 needs a point or ant maze"):
        load_config(["env=cube-single", "method=fast-mctd-replan", "env.wall_clearance=1.5"])
    with pytest.raises(ConfigError, match="env.wall_clearance"):
        load_config(["env=pointmaze-medium", "env.wall_clearance=3"])  # past a corridor's centre line


def test_the_controller_follows_the_cleared_copy():
    cfg = load_config(["env=pointmaze-medium", "env.wall_clearance=1.5"])
    geo_plan = np.array([[-1.9, -0.5], [-1.9, 0.0], [-1.9, 0.5]])  # hugging the wall left of medium's cell (1, 1)
    ctrl = controller_factory(cfg)(geo_plan)
    assert isinstance(ctrl, PDController) and not np.array_equal(ctrl.plan, geo_plan)
