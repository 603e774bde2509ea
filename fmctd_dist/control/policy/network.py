"""The goal-conditioned policy network: an MLP from (state, subgoal) features to a bounded action.

    action [act_dim] = tanh(MLP((x - in_mean) / in_std)),  x = spec.make_input(obs, subgoal)

Shared by every family; the widths of the first and last layer come from the family's
:class:`~fmctd_dist.control.policy.spec.PolicySpec`. Parameter and buffer names are those of
the first (ant-only) version, so shipped ant checkpoints load unchanged.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn


class GoalPolicyNet(nn.Module):
    """[B, in_dim] input -> [B, act_dim] in (-1, 1). Input standardised by buffers set from the training data."""

    def __init__(self, hidden: list[int], in_dim: int, act_dim: int):
        super().__init__()
        self.register_buffer("in_mean", torch.zeros(in_dim))
        self.register_buffer("in_std", torch.ones(in_dim))
        layers: list[nn.Module] = []
        width = in_dim
        for h in hidden:
            layers += [nn.Linear(width, h), nn.LayerNorm(h), nn.ReLU()]
            width = h
        layers.append(nn.Linear(width, act_dim))
        self.net = nn.Sequential(*layers)

    def set_normaliser(self, x: np.ndarray) -> None:
        """Standardise inputs with the mean / std of training inputs x [N, in_dim] (std floored at 1e-3)."""
        x = np.asarray(x, dtype=np.float64)
        with torch.no_grad():
            self.in_mean.copy_(torch.as_tensor(x.mean(0), dtype=torch.float32))
            self.in_std.copy_(torch.as_tensor(np.maximum(x.std(0), 1e-3), dtype=torch.float32))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.tanh(self.net((x - self.in_mean) / self.in_std))


def build_net(hidden: list[int], in_dim: int, act_dim: int, seed: int) -> GoalPolicyNet:
    """Seeded init without touching the caller's global torch RNG."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        return GoalPolicyNet(list(hidden), in_dim, act_dim)
