"""An MLP on VAE latents with its own input and output standardisation: the estimator and the inverse dynamics.

    position estimator: z [B, D]                         -> (x, y) [B, 2] in world units
    inverse dynamics:   (z_{t-1}, z_t, z_{t+1}) [B, 3 D] -> a_t [B, 2], the action taken at t

Both read latents whose scale the VAE chose (and the estimator predicts positions of 0..~30
world units), so the network standardises its input and output with buffers set from the
training data: they travel in ``model.pt`` and a loaded head needs nothing else.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn


class LatentMLP(nn.Module):
    """[B, in_dim] -> [B, out_dim]: standardise, Linear -> ReLU per hidden width, Linear, un-standardise."""

    def __init__(self, in_dim: int, out_dim: int, hidden: list[int]):
        super().__init__()
        self.in_dim, self.out_dim = in_dim, out_dim
        for name, n in (("in_mean", in_dim), ("in_std", in_dim), ("out_mean", out_dim), ("out_std", out_dim)):
            self.register_buffer(name, torch.zeros(n) if name.endswith("mean") else torch.ones(n))
        layers: list[nn.Module] = []
        width = in_dim
        for h in hidden:
            layers += [nn.Linear(width, h), nn.ReLU()]
            width = h
        layers.append(nn.Linear(width, out_dim))
        self.net = nn.Sequential(*layers)

    def set_normaliser(self, x: np.ndarray, y: np.ndarray) -> None:
        """Standardise with the mean / std of training inputs x [N, in] and targets y [N, out] (std floored)."""
        with torch.no_grad():
            for name, a in (("in", x), ("out", y)):
                a = np.asarray(a, dtype=np.float64)
                getattr(self, f"{name}_mean").copy_(torch.as_tensor(a.mean(0), dtype=torch.float32))
                getattr(self, f"{name}_std").copy_(torch.as_tensor(np.maximum(a.std(0), 1e-4), dtype=torch.float32))

    def normalised(self, x: torch.Tensor) -> torch.Tensor:
        """The output in standardised units (what training's MSE compares)."""
        return self.net((x - self.in_mean) / self.in_std)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.normalised(x) * self.out_std + self.out_mean


def build_mlp(in_dim: int, out_dim: int, hidden: list[int], seed: int) -> LatentMLP:
    """Seeded init without touching the caller's global torch RNG."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        return LatentMLP(in_dim, out_dim, list(hidden))


def triples(z: np.ndarray) -> np.ndarray:
    """Per-episode latents [E, S, D] -> inverse-dynamics inputs [E, S - 2, 3 D]: (z_{t-1}, z_t, z_{t+1}), t = 1..S-2."""
    return np.concatenate([z[:, :-2], z[:, 1:-1], z[:, 2:]], axis=-1)
