"""Wall-aware guidance (method.wall_guidance): the penalty, its gradient, and that off means the paper's bits."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from fmctd_dist.config import REPO_ROOT, load_config
from fmctd_dist.diffusion.sampler import goal_reward
from fmctd_dist.errors import ConfigError
from fmctd_dist.families.maze import hooks
from fmctd_dist.families.maze.geometry import MAZE_UNIT, MazeGeometry
from fmctd_dist.families.maze.wall_guide import WallGuide

# a 3 x 4 maze: walls around, two free cells (1, 1) and (1, 2) side by side
WALLS = np.array([[1, 1, 1, 1], [1, 0, 0, 1], [1, 1, 1, 1]])
MEAN, STD = [4.0, 0.0], [2.0, 2.0]
MARGIN = 0.5


def guide(weight: float = 1.0) -> WallGuide:
    return WallGuide(WALLS, MEAN, STD, weight, MARGIN)


def norm(xy) -> torch.Tensor:
    return (torch.as_tensor(np.asarray(xy, np.float64), dtype=torch.float32) - torch.tensor(MEAN)) / torch.tensor(STD)


def test_sdf_signs_and_penalty_only_near_or_inside_walls():
    g = guide()
    free, wall = MazeGeometry.cell_to_xy((1, 1)), MazeGeometry.cell_to_xy((0, 1))
    sdf = g.sdf(torch.tensor(np.stack([free, wall]), dtype=torch.float32))
    assert sdf[0].item() == pytest.approx(0.5 * MAZE_UNIT, abs=1e-5)  # the free cell's centre: 2 from each wall
    assert sdf[1].item() == pytest.approx(-0.5 * MAZE_UNIT, abs=1e-5)  # the wall cell's centre: 2 into the wall
    assert g.penalty(norm([[free]])).item() == 0.0
    deep = g.penalty(norm([[wall]])).item()
    assert deep == pytest.approx((MARGIN + 0.5 * MAZE_UNIT) / MAZE_UNIT, abs=1e-5)
    assert guide(3.0).penalty(norm([[wall]])).item() == pytest.approx(3 * deep, rel=1e-6)


def test_the_gradient_points_out_of_the_wall():
    g = guide()
    # inside the wall above the free cell (1, 1): descending the penalty moves the point toward it
    p = norm([[MazeGeometry.cell_to_xy((0, 1)) + [0.3, 0.5]]]).requires_grad_(True)
    g.penalty(p).sum().backward()
    step = -p.grad[0, 0] * torch.tensor(STD)  # world-space descent direction
    assert step[1] > 0 and abs(step[0]) < 1e-6  # cell (0, 1) lies below (1, 1) in y: out through its face
    assert torch.isfinite(p.grad).all()


def test_goal_reward_with_the_wall_map_is_the_papers_minus_the_penalty():
    g = guide(2.0)
    torch.manual_seed(0)
    x0 = torch.randn(3, 5, 4)  # 2 frames of (x, y) per token
    start, goal = torch.randn(3, 2), torch.randn(3, 2)
    plain = goal_reward(x0, start, goal)
    walled = goal_reward(x0, start, goal, guide_map=g)
    frames = x0.reshape(3, 10, 2)[:, 2:]  # the plan frames (token 0 is the context)
    assert torch.equal(walled, plain - g.penalty(frames))


def test_off_by_default_and_mazes_only():
    cfg = load_config(["env=pointmaze-medium", "method=fast-mctd"])
    manifest = json.loads((REPO_ROOT / "checkpoints/pointmaze-medium-h5/manifest.json").read_text())
    assert hooks.guide_map(cfg, manifest) is None  # the paper's guidance, bit for bit
    on = hooks.guide_map(load_config(["env=pointmaze-medium", "method=fast-mctd", "method.wall_guidance=4"]), manifest)
    assert isinstance(on, WallGuide) and on.weight == 4.0 and on.margin == 0.5
    with pytest.raises(ConfigError, match="method.wall_guidance=2.0 needs a point or ant maze"):
        load_config(["env=cube-single", "method=fast-mctd-replan", "method.wall_guidance=2"])


# ------------------------------------------------------------------ the wall loss (train.wall_weight)

def test_wall_depth_reads_the_guides_distance_off_a_grid_and_points_out_of_walls():
    from fmctd_dist.families.maze.wall_loss import WallDepth

    depth, exact = WallDepth(WALLS, MEAN, STD), WallGuide(WALLS, MEAN, STD, 1.0, 0.0)
    pts = norm(np.random.default_rng(0).uniform([-6, -6], [14, 10], (2000, 2)))  # the map, and 2 units around it
    want = torch.relu(-exact.sdf(pts * torch.tensor(STD) + torch.tensor(MEAN))) / MAZE_UNIT
    assert torch.allclose(depth(pts), want, atol=0.02)  # bilinear between grid points 0.1 apart
    free = norm([MazeGeometry.cell_to_xy((1, 1)) + [0.3, -1.9], MazeGeometry.cell_to_xy((1, 2))])
    assert depth(free).abs().max().item() == 0.0  # free space, even 0.1 from a wall: no data frame pays
    p = norm([MazeGeometry.cell_to_xy((0, 1)) + [0.3, 0.5]]).requires_grad_(True)
    depth(p).sum().backward()
    assert -p.grad[0, 1] > 0 and abs(p.grad[0, 0].item()) < 1e-4  # out through the face, as the guide's gradient


def test_maze_data_serve_the_wall_depth_of_their_own_maze():
    from fmctd_dist.families.maze.data import NavigateDataset

    cfg = load_config(["env=pointmaze-medium", "train.wall_weight=1"])
    data = NavigateDataset.__new__(NavigateDataset)
    data.manifest = {"obs_mean": [10.0, 10.0], "obs_std": [5.0, 5.0]}
    depth, provenance = data.wall_depth(cfg)
    assert provenance["maze"] == "pointmaze-medium" and depth.depth.max() > 0


def test_the_wall_depth_probe_reads_a_checkpoints_predictions_on_its_own_maze(tiny_checkpoint):
    from conftest import load_job

    job = load_job("wall_depth")
    rows = job.wall_depths(tiny_checkpoint[1])
    assert [k for k, *_ in rows] == list(job.TIMESTEPS)
    assert all(0 <= share <= 1 and depth >= 0 and mse > 0 for _, share, depth, mse in rows)
    assert rows[-1][3] > rows[0][3]  # from pure noise the prediction is further from the data
