"""Wall-aware guidance (``method.wall_guidance``; not the paper's): a guidance term that pushes plan frames
out of the maze's wall cells.

Why: our smooth models' shortest reaching plans often cut through a wall, and the authors' value, which
tests warps only, keeps them (docs/results.md, AntMaze). The value stays the authors'; this only changes
what the guided denoiser proposes. The denoiser asks the family for a guide map
(:func:`fmctd_dist.families.maze.hooks.guide_map`); this one leaves distances where they are (identity)
and brings a ``penalty``, which :func:`fmctd_dist.diffusion.sampler.goal_reward` subtracts.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from torch import nn

from fmctd_dist.families.maze.geometry import MAZE_UNIT, cell_centres, maze_geometry


def square_distance(p: torch.Tensor, centres: torch.Tensor) -> torch.Tensor:
    """[..., 2] points, [K, 2] cell centres -> [..., K]: Euclidean distance to each axis-aligned cell
    square of side ``MAZE_UNIT`` (0 inside). The 1e-12 keeps the gradient finite at 0."""
    gap = torch.relu((p[..., None, :] - centres).abs() - 0.5 * MAZE_UNIT)
    return torch.sqrt((gap * gap).sum(-1) + 1e-12)


class WallGuide(nn.Module):
    """Identity guide map on normalised (x, y) frames with a wall penalty.

    ``penalty(frames)`` [B, F, 2] -> [B]: ``weight`` x mean over frames of max(0, margin - sdf) / MAZE_UNIT,
    where sdf is the signed distance to the walls (positive in free space, negative inside a wall), so a
    frame deep in a wall is pulled toward the nearest free cell and a frame in free space beyond the margin
    feels nothing.
    """

    def __init__(self, walls: np.ndarray, mean: list[float], std: list[float], weight: float, margin: float):
        super().__init__()
        wall_cells, free_cells = cell_centres(walls)
        self.register_buffer("wall_cells", torch.as_tensor(wall_cells, dtype=torch.float32))
        self.register_buffer("free_cells", torch.as_tensor(free_cells, dtype=torch.float32))
        self.register_buffer("mean", torch.as_tensor(mean, dtype=torch.float32))
        self.register_buffer("std", torch.as_tensor(std, dtype=torch.float32))
        self.in_dim = len(mean)
        self.weight, self.margin = float(weight), float(margin)

    def forward(self, frames: torch.Tensor) -> torch.Tensor:
        return frames

    def sdf(self, xy: torch.Tensor) -> torch.Tensor:
        """[..., 2] world points -> [...] signed distance to the walls (> 0 in free space)."""
        return (square_distance(xy, self.wall_cells).amin(-1) - square_distance(xy, self.free_cells).amin(-1))

    def penalty(self, frames: torch.Tensor) -> torch.Tensor:
        xy = frames * self.std + self.mean
        return self.weight * (torch.relu(self.margin - self.sdf(xy)) / MAZE_UNIT).mean(dim=-1)


def wall_guide(env_name: str, manifest: dict[str, Any], weight: float, margin: float) -> WallGuide:
    """The wall guide of a maze planner checkpoint: its maze's cells, its normaliser."""
    norm = manifest["normaliser"]
    return WallGuide(maze_geometry(env_name).walls, norm["mean"], norm["std"], weight, margin)
