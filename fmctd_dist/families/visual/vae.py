"""The visual maze's beta-VAE: 64x64 RGB chase-camera frames <-> an 8-D latent.

    encoder: uint8 [B, 64, 64, 3] -> n x (Conv 4x4 stride 2 -> SiLU) -> Linear -> (mu, logvar) [B, 2 x D]
    decoder: z [B, D] -> Linear -> n x (ConvTranspose 4x4 stride 2 -> SiLU, none on the last) -> sigmoid

The planner diffuses latent trajectories, so the latent must be small (8-D, the paper's) and
smooth in position; a tiny KL weight (the authors' ~1e-6 against a per-pixel MSE) keeps it an
almost deterministic autoencoder whose sampled z is still a little noisy, which the authors use.
The decoder is only for looking at plans (and for the reconstruction error that says how much
of the frame the latent kept); the estimator and inverse dynamics read z.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

IMAGE_SIZE = 64


class ConvVAE(nn.Module):
    """Conv encoder/decoder with widths ``channels`` (one stride-2 block each) and a ``latent_dim`` latent."""

    def __init__(self, latent_dim: int = 8, channels: list[int] | tuple[int, ...] = (32, 64, 128, 256)):
        super().__init__()
        channels = list(channels)
        self.latent_dim = latent_dim
        self.side = IMAGE_SIZE >> len(channels)  # spatial size after the encoder's convs
        if self.side < 1 or IMAGE_SIZE % (1 << len(channels)):
            raise ValueError(f"{len(channels)} stride-2 blocks do not fit a {IMAGE_SIZE}-px image; use at most 6")
        enc: list[nn.Module] = []
        width = 3
        for c in channels:
            enc += [nn.Conv2d(width, c, 4, stride=2, padding=1), nn.SiLU()]
            width = c
        self.encoder = nn.Sequential(*enc, nn.Flatten())
        flat = width * self.side * self.side
        self.to_stats = nn.Linear(flat, 2 * latent_dim)
        self.from_z = nn.Linear(latent_dim, flat)
        dec: list[nn.Module] = []
        for c in reversed([3] + channels[:-1]):
            dec += [nn.ConvTranspose2d(width, c, 4, stride=2, padding=1), nn.SiLU()]
            width = c
        self.decoder = nn.Sequential(*dec[:-1])  # no activation before the sigmoid

    @staticmethod
    def to_input(images: torch.Tensor) -> torch.Tensor:
        """uint8 [B, 64, 64, 3] -> float [B, 3, 64, 64] in [0, 1]."""
        return images.permute(0, 3, 1, 2).float().div_(255.0)

    def encode(self, images: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """uint8 [B, 64, 64, 3] -> (mu, logvar), each [B, D]."""
        h = self.encoder(self.to_input(images) * 2.0 - 1.0)
        mu, logvar = self.to_stats(h).chunk(2, dim=-1)
        return mu, logvar.clamp(-30.0, 10.0)

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        """z [B, D] -> float [B, 3, 64, 64] in (0, 1)."""
        w = self.from_z(z).view(len(z), -1, self.side, self.side)
        return torch.sigmoid(self.decoder(w))

    def forward(self, images: torch.Tensor, generator: torch.Generator | None = None
                ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(reconstruction [B, 3, 64, 64], mu, logvar) from the sampled z."""
        mu, logvar = self.encode(images)
        eps = torch.randn(mu.shape, generator=generator, dtype=mu.dtype)
        return self.decode(mu + eps * (0.5 * logvar).exp()), mu, logvar


def vae_loss(model: ConvVAE, images: torch.Tensor, kl_weight: float,
             generator: torch.Generator | None = None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(loss, per-pixel MSE, KL per frame): MSE on [0, 1] pixels + kl_weight * KL(q(z|x) || N(0, I))."""
    recon, mu, logvar = model(images, generator)
    mse = (recon - model.to_input(images)).square().mean()
    kl = 0.5 * (mu.square() + logvar.exp() - 1.0 - logvar).sum(-1).mean()
    return mse + kl_weight * kl, mse, kl


def psnr(mse: float) -> float:
    """Peak signal-to-noise ratio in dB of a per-pixel MSE on [0, 1] pixels."""
    return float(10.0 * np.log10(1.0 / max(mse, 1e-12)))


@torch.no_grad()
def encode_frames(model: ConvVAE, images: np.ndarray, batch: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """uint8 [N, 64, 64, 3] -> (mu, logvar) float32 [N, D] each, in batches (no sampling: deterministic)."""
    model.eval()
    mus, logvars = [], []
    for a in range(0, len(images), batch):
        mu, logvar = model.encode(torch.from_numpy(np.ascontiguousarray(images[a:a + batch])))
        mus.append(mu.numpy())
        logvars.append(logvar.numpy())
    d = model.latent_dim
    cat = (lambda xs: np.concatenate(xs).astype(np.float32)) if mus else (lambda xs: np.zeros((0, d), np.float32))
    return cat(mus), cat(logvars)


@torch.no_grad()
def recon_mse(model: ConvVAE, images: np.ndarray, batch: int = 256) -> float:
    """Per-pixel MSE on [0, 1] of decode(mu) vs the frames (the held-out reconstruction error)."""
    model.eval()
    total = 0.0
    for a in range(0, len(images), batch):
        x = torch.from_numpy(np.ascontiguousarray(images[a:a + batch]))
        mu, _ = model.encode(x)
        total += float((model.decode(mu) - model.to_input(x)).square().sum())
    return total / (images.size if len(images) else 1)
