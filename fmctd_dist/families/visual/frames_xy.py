"""The visual planner's frame: a VAE latent, or (``visual.plan_xy``) the latent with its estimated (x, y).

Latent space aliases the maze (docs/results.md 13.4): real frames far apart in the maze lie
closer in latent units than one real step often is, so a latent plan can cross between them in an
ordinary-looking step, and the estimator then reads a jump of ~8 world units. With
``visual.plan_xy=true`` every planner frame is [z, estimator(z)]: the diffusion loss then sees the
position beside the latent (a jump costs as much as on the point maze, whose planner plans x, y),
guidance and value read the plan's own (x, y), and the controller follows the plan's latents.
Without it, frames are latents and positions are the estimator's reading of them (the paper's setup).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

PositionFn = Callable[[np.ndarray], np.ndarray]  # latents [..., D] -> world (x, y) [..., 2]


class PlanFrames:
    """Latents <-> planner frames, and the world (x, y) of planner frames; numpy in and out."""

    def __init__(self, estimator: PositionFn, latent_dim: int, plan_xy: bool):
        self.estimator, self.latent_dim, self.plan_xy = estimator, int(latent_dim), bool(plan_xy)

    @property
    def dim(self) -> int:
        return self.latent_dim + (2 if self.plan_xy else 0)

    def of_latents(self, z: np.ndarray) -> np.ndarray:
        """Latents [..., D] -> planner frames [..., dim], float32."""
        z = np.asarray(z, np.float32)
        if not self.plan_xy:
            return z
        return np.concatenate([z, self.estimator(z).astype(np.float32)], axis=-1)

    def latents(self, frames: np.ndarray) -> np.ndarray:
        """Planner frames [..., dim] -> their latents [..., D] (what the inverse dynamics follows)."""
        return np.asarray(frames)[..., :self.latent_dim]

    def __call__(self, frames: np.ndarray) -> np.ndarray:
        """Planner frames [..., dim] -> world (x, y) [..., 2] float64: the plan's own, or the estimator's."""
        frames = np.asarray(frames)
        if self.plan_xy:
            return frames[..., self.latent_dim:self.latent_dim + 2].astype(np.float64)
        return self.estimator(frames)
