"""Loading the three parts for a visual env, each checked against the env and against each other.

    vae = load_vae(dir, env)                          # frames -> z, z -> frames
    est = load_estimator(dir, env, vae)               # z [..., D] -> (x, y) [..., 2]
    inv = load_invdyn(dir, env, vae)                  # (z_{t-1}, z_t, z_{t+1}) -> a_t [..., 2]

A head is only meaningful on the latents of the VAE it was trained on, so it is loaded
*with* that VAE: another VAE (digest), another latent size or another env is one
:class:`~fmctd_dist.errors.CheckpointError`, as is a point maze planner's checkpoint given
in place of any part, and latents of the wrong size handed to a loaded head.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from fmctd_dist.errors import CheckpointError
from fmctd_dist.families.visual.checkpoint import load_state, read_part_manifest
from fmctd_dist.families.visual.mlp import LatentMLP
from fmctd_dist.families.visual.vae import ConvVAE, encode_frames


@dataclass
class LoadedVAE:
    net: ConvVAE
    manifest: dict[str, Any]
    path: Path

    @property
    def digest(self) -> str:
        return str(self.manifest["digest"])

    @property
    def latent_dim(self) -> int:
        return int(self.manifest["latent_dim"])

    def encode(self, images: np.ndarray) -> np.ndarray:
        """uint8 [N, 64, 64, 3] -> mu float32 [N, D] (deterministic; the controller's view of an observation)."""
        return encode_frames(self.net, np.asarray(images, dtype=np.uint8))[0]

    @torch.no_grad()
    def decode(self, z: np.ndarray) -> np.ndarray:
        """z [N, D] -> uint8 [N, 64, 64, 3] (for looking at plans)."""
        z = _check_latents(np.asarray(z, dtype=np.float32), self.latent_dim, 1, f"VAE {self.path}")
        x = self.net.decode(torch.from_numpy(z)).permute(0, 2, 3, 1).numpy()
        return np.clip(np.rint(x * 255.0), 0, 255).astype(np.uint8)


@dataclass
class LoadedHead:
    net: LatentMLP
    manifest: dict[str, Any]
    path: Path
    part: str
    latent_dim: int
    window: int  # latents per input: 1 (estimator) or 3 (inverse dynamics)

    @torch.no_grad()
    def __call__(self, z: np.ndarray) -> np.ndarray:
        """z [..., window * D] (estimator: [..., D]) -> float64 [..., 2]."""
        z = _check_latents(np.asarray(z, dtype=np.float32), self.latent_dim, self.window, f"{self.part} {self.path}")
        flat = torch.from_numpy(np.ascontiguousarray(z.reshape(-1, z.shape[-1])))
        return self.net(flat).numpy().astype(np.float64).reshape(*z.shape[:-1], 2)


def _check_latents(z: np.ndarray, latent_dim: int, window: int, who: str) -> np.ndarray:
    want = latent_dim * window
    if z.ndim < 1 or z.shape[-1] != want:
        what = f"{window} x {latent_dim}-D latents concatenated" if window > 1 else f"{latent_dim}-D latents"
        raise CheckpointError(f"{who}: got latents of shape {z.shape}, last axis {z.shape[-1] if z.ndim else None}, "
                              f"but it takes {what} (last axis {want}); encode frames with the VAE it was trained "
                              f"on (latent_dim={latent_dim})")
    return z


def load_vae(path: str | Path, env: str, latent_dim: int | None = None) -> LoadedVAE:
    """The VAE in ``path``, trained for ``env`` (and ``latent_dim`` when given)."""
    path = Path(path)
    m = read_part_manifest(path, "vae", env, latent_dim)
    net = load_state(path, ConvVAE(int(m["latent_dim"]), list(m["channels"])), "vae", env)
    return LoadedVAE(net, m, path)


def _load_head(path: str | Path, part: str, env: str, vae: LoadedVAE, window: int) -> LoadedHead:
    path = Path(path)
    m = read_part_manifest(path, part, env, vae.latent_dim, vae.digest)
    if m.get("window") != window:
        raise CheckpointError(f"visual {part} checkpoint {path}: window={m.get('window')!r} but a {part} reads "
                              f"{window} latent(s); retrain it with jobs/train_visual.py part={part}")
    net = LatentMLP(window * vae.latent_dim, 2, list(m["hidden"]))
    return LoadedHead(load_state(path, net, part, env), m, path, part, vae.latent_dim, window)


def load_estimator(path: str | Path, env: str, vae: LoadedVAE) -> LoadedHead:
    """The position estimator z -> (x, y) trained on ``vae``'s latents of ``env``."""
    return _load_head(path, "estimator", env, vae, 1)


def load_invdyn(path: str | Path, env: str, vae: LoadedVAE) -> LoadedHead:
    """The inverse dynamics (z_{t-1}, z_t, z_{t+1}) -> a_t trained on ``vae``'s latents of ``env``."""
    return _load_head(path, "invdyn", env, vae, 3)
