"""Where the visual planner measures distances: the position estimator's (x, y) of a latent plan.

The Diffusion Forcing model of a visual maze plans normalised 8-D latents, but "how far from the
goal" is a question about positions. So guidance (docs/reference.md §14: the maze guidance on the
estimator's (x, y)) and the plan value both read positions through the estimator:

    guidance:  z_n [..., D] -> z = z_n * std + mean -> estimator(z) = (x, y) -> (x, y) / xy scale
    value:     the maze rule (reach within goal_radius, no warp) on estimator(z) in world units

The guidance map is a torch module, so the gradient of the tanh distance reward flows through the
estimator MLP into the latents (``diffusion.sampler.goal_reward`` applies it to frames, start and
goal alike). Its position scale is the mean / std of the train positions, which puts distances on
the scale the point maze's guidance uses (normalised x, y). The value rule on estimated positions
is our reading: the paper does not state the visual value rule.

With ``visual.plan_xy`` the planner's frames carry the estimator's (x, y) beside the latent
(``visual/frames_xy.py``): guidance and value then read those two numbers of the plan
(:class:`XYReadout`), not the estimator of its latents.

Which estimator: ``checkpoints/<env>-estimator``, checked against the VAE whose latents the
planner was trained on (its manifest's ``latents.vae_digest``): a mismatch is one CheckpointError.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from fmctd_dist.config import Config
from fmctd_dist.errors import CheckpointError
from fmctd_dist.families.visual.checkpoint import load_state, read_part_manifest
from fmctd_dist.families.visual.config import LATENT_KEY, part_dir
from fmctd_dist.families.visual.mlp import LatentMLP


class EstimatorGuide(nn.Module):
    """Normalised latent frames [..., D] -> normalised positions [..., 2], differentiable."""

    def __init__(self, estimator: LatentMLP, z_mean: np.ndarray, z_std: np.ndarray, xy_mean: np.ndarray,
                 xy_std: np.ndarray):
        super().__init__()
        self.estimator = estimator
        self.in_dim = int(estimator.in_dim)
        for name, a in (("z_mean", z_mean), ("z_std", z_std), ("xy_mean", xy_mean), ("xy_std", xy_std)):
            self.register_buffer(name, torch.as_tensor(np.asarray(a, np.float64), dtype=torch.float32))

    def forward(self, z_n: torch.Tensor) -> torch.Tensor:
        xy = self.estimator(z_n * self.z_std + self.z_mean)
        return (xy - self.xy_mean) / self.xy_std


class XYReadout(nn.Module):
    """Normalised [z, x, y] frames [..., D + 2] -> normalised positions [..., 2]: the frames' own (x, y)."""

    def __init__(self, latent_dim: int, f_mean: np.ndarray, f_std: np.ndarray, xy_mean: np.ndarray,
                 xy_std: np.ndarray):
        super().__init__()
        self.latent_dim = int(latent_dim)
        self.in_dim = self.latent_dim + 2  # numbers per frame (the sampler's guidance reads frames of this size)
        sl = slice(self.latent_dim, self.latent_dim + 2)
        for name, a in (("f_mean", np.asarray(f_mean)[sl]), ("f_std", np.asarray(f_std)[sl]), ("xy_mean", xy_mean),
                        ("xy_std", xy_std)):
            self.register_buffer(name, torch.as_tensor(np.asarray(a, np.float64), dtype=torch.float32))

    def forward(self, f_n: torch.Tensor) -> torch.Tensor:
        xy = f_n[..., self.latent_dim:self.latent_dim + 2] * self.f_std + self.f_mean
        return (xy - self.xy_mean) / self.xy_std


def latent_provenance(manifest: dict[str, Any], where: str | Path) -> dict[str, Any]:
    """The ``latents`` field of a planner manifest (which VAE's latents it models); else one CheckpointError."""
    prov = manifest.get(LATENT_KEY)
    if not isinstance(prov, dict) or not isinstance(prov.get("vae_digest"), str):
        env = manifest.get("config", {}).get("env", {}).get("name", "?")
        raise CheckpointError(f"checkpoint {where}: the manifest has no {LATENT_KEY}.vae_digest (env {env}), so "
                              "it was not trained on a visual maze's VAE latents; train one with `python "
                              "jobs/train.py env=visual-pointmaze-medium jump=5` and set checkpoint= to its dir")
    return prov


def load_estimator_net(cfg: Config, vae_digest: str, latent_dim: int) -> tuple[LatentMLP, dict[str, Any]]:
    """The estimator of ``cfg.env`` trained on latents of VAE ``vae_digest`` (manifest checked, weights loaded)."""
    path = part_dir(cfg, "", "estimator")
    m = read_part_manifest(path, "estimator", cfg.env.name, latent_dim, vae_digest)
    net = load_state(path, LatentMLP(latent_dim, 2, list(m["hidden"])), "estimator", cfg.env.name)
    return net.requires_grad_(False), m


def load_positions(cfg: Config, vae_digest: str, latent_dim: int) -> tuple[Positions, str]:
    """The estimator as a numpy (x, y) reader, and its digest: what planner frames and the value read."""
    net, m = load_estimator_net(cfg, vae_digest, latent_dim)
    return Positions(net), str(m["digest"])


def guide_map(cfg: Config, manifest: dict[str, Any]) -> nn.Module:
    """The guidance map of a visual planner checkpoint (the family hooks' ``guide_map``)."""
    prov = latent_provenance(manifest, cfg.checkpoint_dir())
    norm = manifest["normaliser"]
    if prov.get("plan_xy"):
        return XYReadout(int(prov["latent_dim"]), norm["mean"], norm["std"], prov["xy_mean"], prov["xy_std"])
    net, _ = load_estimator_net(cfg, prov["vae_digest"], int(prov["latent_dim"]))
    return EstimatorGuide(net, norm["mean"], norm["std"], prov["xy_mean"], prov["xy_std"])


class Positions:
    """World (x, y) of latents, numpy in and out: what the value rule and the episode's figure read."""

    def __init__(self, net: LatentMLP):
        self.net = net.eval()

    @torch.no_grad()
    def __call__(self, z: np.ndarray) -> np.ndarray:
        """z [..., D] -> float64 [..., 2]."""
        z = np.asarray(z, np.float32)
        if z.shape[-1] != self.net.in_dim:
            raise CheckpointError(f"the position estimator takes {self.net.in_dim}-D latents, got shape {z.shape}; "
                                  "plan with a model trained on this VAE's latents")
        flat = torch.from_numpy(np.ascontiguousarray(z.reshape(-1, z.shape[-1])))
        return self.net(flat).numpy().astype(np.float64).reshape(*z.shape[:-1], 2)
