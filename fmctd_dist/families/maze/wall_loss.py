"""The wall loss (``train.wall_weight``; not the paper's): how deep a predicted frame sits inside the maze's walls.

Why: the guided plans of our AntMaze and large PointMaze models reach the goal through walls, and the authors'
value keeps such plans (docs/results.md, the lines below the paper). The navigate data never enters a wall, so the
token loss only meets walls through the conditional mean: at high noise the model's x0 prediction is a blur of the
routes around a wall, which lies inside it, and guidance pushed along that prediction goes straight through. This
term penalises each predicted frame by its depth inside a wall, which is zero on every data frame.

The signed distance is read by bilinear interpolation from a grid computed once with the wall guide's exact one
(``maze/wall_guide.py``): the exact distance to a hundred cells per frame would cost more than the model's own step.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from fmctd_dist.families.maze.geometry import MAZE_UNIT, cell_centres, maze_geometry
from fmctd_dist.families.maze.wall_guide import square_distance

GRID_STEP = 0.1  # world units between the signed-distance grid's points (the maze unit is 4)
GRID_PAD = 2.0  # maze units the grid reaches past the map's (walled) border, so a frame pushed out still has a slope


class WallDepth(nn.Module):
    """Normalised (x, y) frames [..., 2] -> [...] depth inside the walls in maze units (0 in free space).

    Beyond ``GRID_PAD`` maze units outside the map the grid's border value is used (the map is walled all round)."""

    def __init__(self, walls: np.ndarray, mean: list[float], std: list[float], grid_step: float = GRID_STEP):
        super().__init__()
        wall_cells, free_cells = (torch.as_tensor(c, dtype=torch.float32) for c in cell_centres(walls))
        centres = torch.cat((wall_cells, free_cells))
        lo, hi = centres.amin(0) - (0.5 + GRID_PAD) * MAZE_UNIT, centres.amax(0) + (0.5 + GRID_PAD) * MAZE_UNIT
        nx, ny = (int(round(float(s))) + 1 for s in (hi - lo) / grid_step)
        xs, ys = torch.linspace(float(lo[0]), float(hi[0]), nx), torch.linspace(float(lo[1]), float(hi[1]), ny)
        grid = torch.stack(torch.meshgrid(xs, ys, indexing="xy"), dim=-1)  # [ny, nx, 2]
        sdf = square_distance(grid, wall_cells).amin(-1) - square_distance(grid, free_cells).amin(-1)
        self.register_buffer("depth", (torch.relu(-sdf) / MAZE_UNIT)[None, None])  # [1, 1, ny, nx]
        self.register_buffer("lo", lo)
        self.register_buffer("hi", hi)
        self.register_buffer("mean", torch.as_tensor(mean[:2], dtype=torch.float32))
        self.register_buffer("std", torch.as_tensor(std[:2], dtype=torch.float32))

    def forward(self, frames: torch.Tensor) -> torch.Tensor:
        xy = frames[..., :2].float() * self.std + self.mean
        uv = 2.0 * (xy - self.lo) / (self.hi - self.lo) - 1.0  # grid_sample's [-1, 1] box, x first
        shape = uv.shape[:-1]
        out = F.grid_sample(self.depth, uv.reshape(1, 1, -1, 2), mode="bilinear", padding_mode="border",
                            align_corners=True)
        return out.reshape(shape)


def wall_depth(env_name: str, mean: list[float], std: list[float]) -> WallDepth:
    """The wall depth of a maze's planner data: its maze's cells, its normaliser."""
    return WallDepth(maze_geometry(env_name).walls, mean, std)
