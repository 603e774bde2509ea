"""Maze geometry, BFS and the evaluation tasks on all three OGBench PointMaze maps."""

import numpy as np
import pytest

from fmctd_dist.families.maze.make import make_env

from fmctd_dist.families.maze.geometry import maze_geometry
from fmctd_dist.seeding import check_seed
from fmctd_dist.errors import ConfigError

# docs/reference.md §9: (init_xy, goal_xy, BFS cell distance) per task
TASKS = {
    "pointmaze-medium": [((0, 0), (20, 20), 10), ((0, 20), (20, 0), 10), ((8, 16), (4, 12), 6),
                         ((16, 20), (0, 20), 10), ((20, 4), (0, 0), 8)],
    "pointmaze-large": [((0, 0), (36, 24), 15), ((12, 16), (0, 24), 19), ((12, 24), (36, 0), 12),
                        ((28, 8), (12, 16), 14), ((0, 0), (12, 16), 15)],
    "pointmaze-giant": [((0, 0), (52, 36), 30), ((52, 0), (0, 36), 26), ((52, 28), (0, 0), 30),
                        ((8, 28), (44, 16), 26), ((32, 16), (28, 8), 17)],
}
SHAPES = {"pointmaze-medium": ((8, 8), 26), "pointmaze-large": ((9, 12), 46), "pointmaze-giant": ((12, 16), 86)}


@pytest.mark.parametrize("name", sorted(TASKS))
def test_tasks_and_bfs(name):
    geo = maze_geometry(name)
    for task, (init_xy, goal_xy, dist) in zip(geo.tasks, TASKS[name]):
        np.testing.assert_array_equal(task.init_xy, init_xy)
        np.testing.assert_array_equal(task.goal_xy, goal_xy)
        assert geo.bfs(task.goal_ij)[task.init_ij] == dist


@pytest.mark.parametrize("name", sorted(TASKS))
def test_cell_xy_geometry(name):
    geo = maze_geometry(name)
    shape, n_free = SHAPES[name]
    assert geo.shape == shape and len(geo.free_cells()) == n_free
    for ij in geo.free_cells():
        xy = geo.cell_to_xy(ij)
        assert geo.xy_to_cell(xy) == ij
        # anywhere inside the 4x4 cell maps back to it
        assert geo.xy_to_cell(xy + np.array([1.99, -1.99])) == ij
        assert geo.in_free_cell(xy)
    walls = list(zip(*np.nonzero(geo.walls)))
    assert not geo.in_free_cell(np.stack([geo.cell_to_xy(w) for w in walls])).any()


def test_next_cell_descends_bfs():
    geo = maze_geometry("pointmaze-medium")
    goal = geo.tasks[0].goal_ij
    for ij in geo.free_cells():
        if ij != goal:
            assert geo.bfs(goal)[geo.next_cell(ij, goal)] == geo.bfs(goal)[ij] - 1


def test_env_reset_protocols():
    env = make_env("pointmaze-medium")
    r = env.reset(1, seed=3)
    np.testing.assert_array_equal(r.obs, [0, 0])
    np.testing.assert_array_equal(r.goal, [20, 20])
    noisy = make_env("pointmaze-medium", protocol="ogbench")
    a, b = noisy.reset(1, seed=3), noisy.reset(1, seed=3)
    np.testing.assert_array_equal(a.obs, b.obs)
    assert 0 < np.abs(a.obs).max() <= 1.0 and np.abs(a.goal - [20, 20]).max() <= 1.0


def test_bad_task_and_seed():
    env = make_env("pointmaze-medium")
    with pytest.raises(ConfigError, match="task"):
        env.reset(7, 0)
    with pytest.raises(ConfigError, match="seed"):
        env.reset(1, -1)
    with pytest.raises(ConfigError, match="seed"):
        check_seed(1.5)
    with pytest.raises(ConfigError, match="env.name"):
        make_env("pointmaze-huge")


def test_steps_cross_wall_matches_the_cells_and_the_value_uses_it():
    from fmctd_dist.config import load_config
    from fmctd_dist.families.maze.hooks import plan_rules
    from fmctd_dist.search.actions import scale_actions

    geo = maze_geometry("pointmaze-medium")
    free = np.argwhere(geo.walls == 0)
    # two free cells side by side in a row, and a free cell with a wall cell between it and another free one
    a = next((i, j) for i, j in free if geo.walls[i, j + 1] == 0)
    b = next((i, j) for i, j in free if j + 2 < geo.walls.shape[1] and geo.walls[i, j + 1] == 1
             and geo.walls[i, j + 2] == 0)
    xy = geo.cell_to_xy
    ok = np.stack([xy(a), xy((a[0], a[1] + 1))])
    through = np.stack([xy(b), xy((b[0], b[1] + 2))])
    assert not geo.steps_cross_wall(ok[None])[0, 0] and geo.steps_cross_wall(through[None])[0, 0]
    assert geo.steps_cross_wall(np.stack([ok, through])).shape == (2, 1)

    start, goal = through[0], through[1]
    plans = np.stack([start + (goal - start) * k / 8 for k in range(1, 10)])[None]  # small steps, straight through
    cfg = load_config(["env=pointmaze-medium", "method=fast-mctd"])
    paper = plan_rules(cfg).value.values(plans, start, goal, scale_actions([0.0]))
    walled = plan_rules(load_config(["env=pointmaze-medium", "method=fast-mctd", "method.wall_test=true"]))
    assert paper[0][0] > 0 and walled.value.values(plans, start, goal, scale_actions([0.0]))[0][0] == 0
