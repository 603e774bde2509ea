"""The visual maze's planner data: VAE latents (mu per frame) of the latent store, as trajectories.

The Diffusion Forcing model of a visual maze plans 8-D latent trajectories (reference §14). Its
training windows are cut from the latent store (``visual/latents.py``: every frame of a seeded
subset of train episodes, rendered once and encoded by the VAE) exactly as a point maze's are cut
from positions (``data/windows.py``, any jump H): only the frame state differs, [E, S, 8] here.

We use the encoder's mean (mu), not a sampled z: with KL weight 1e-6 the posterior's std is ~0.02
against a spread of ~2.8 (docs/results.md §13.3), and the controller sees mu of each new frame.

A latent means something only to the VAE that made it, so the dataset's digest is the store's
sha256 (a function of the VAE's weights) and :attr:`VisualLatentDataset.provenance` goes into the
model's manifest: the VAE digest and dir, the store's dir, sha256 and episode ids, and the mean /
std of the train positions (the scale in which guidance measures distances, ``visual/guide.py``).
``hooks/visual.py`` refuses a model whose manifest names another VAE than the one it loads.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fmctd_dist.config import Config
from fmctd_dist.data.tokens import Normaliser
from fmctd_dist.errors import DatasetError
from fmctd_dist.families import require_family
from fmctd_dist.hints import shown
from fmctd_dist.visual.config import LATENT_KEY, part_dir

VISUAL_FAMILY = "visual-pointmaze"


@dataclass
class VisualLatentDataset:
    """mu [E, S, D] per split, the surface ``data/windows.py`` reads (train, val, normaliser, digest)."""

    path: Path
    manifest: dict[str, Any]  # the latent store's manifest
    train: np.ndarray  # [E, S, D] float32
    val: np.ndarray  # [E_val, S, D] float32
    xy_mean: np.ndarray  # [2] world units, of the train frames
    xy_std: np.ndarray  # [2]

    @property
    def digest(self) -> str:
        return str(self.manifest["sha256"])

    @property
    def normaliser(self) -> Normaliser:
        flat = self.train.reshape(-1, self.train.shape[-1]).astype(np.float64)
        return Normaliser(flat.mean(0), flat.std(0))

    @property
    def provenance(self) -> dict[str, Any]:
        """What a model trained on these latents must remember (written under ``latents`` in its manifest)."""
        m = self.manifest
        return {LATENT_KEY: {"vae_digest": m["vae"]["digest"], "vae_path": m["vae"]["path"],
                             "store": shown(self.path), "store_sha256": m["sha256"],
                             "latent_dim": int(m["latent_dim"]), "episodes": list(m["episodes"]),
                             "val_episodes": list(m["val_episodes"]), "frames_digest": m["frames_digest"],
                             "xy_mean": self.xy_mean.tolist(), "xy_std": self.xy_std.tolist()}}

    def position_readout(self, cfg: Config) -> tuple[Any, dict[str, Any]]:
        """Normalised latent frames -> standardised (x, y) through the frozen position estimator of this
        store's VAE, the map guidance reads (``visual/guide.py``); for train.boundary_space=position and
        train.position_weight."""
        from fmctd_dist.visual.guide import EstimatorGuide, load_estimator_net

        net, m = load_estimator_net(cfg, str(self.manifest["vae"]["digest"]), int(self.manifest["latent_dim"]))
        norm = self.normaliser
        guide = EstimatorGuide(net, norm.mean, norm.std, self.xy_mean, self.xy_std)
        return guide, {"readout": "position estimator", "estimator": shown(part_dir(cfg, "", "estimator")),
                       "estimator_digest": m.get("digest")}


def _parts(cfg: Config):
    """The default parts config (VAE and latent store dirs: checkpoints/<env>-vae, data/<env>-latents-...)."""
    from fmctd_dist.visual.config import PartsConfig

    require_family(cfg.env.name, (VISUAL_FAMILY,), "the visual latent data")
    return PartsConfig()


def make_visual_dataset(cfg: Config, progress: bool = True) -> tuple[Path, dict[str, Any]]:
    """Encode (rendering first if needed) the latent store of ``cfg``, or verify the existing one."""
    from fmctd_dist.visual.latents import make_latents

    return make_latents(cfg, _parts(cfg), progress)


def load_visual_dataset(cfg: Config) -> VisualLatentDataset:
    """The checked latent store of ``cfg`` (VAE digest, env, latent size, sha256) as planner trajectories."""
    from fmctd_dist.visual.latents import load_latents, vae_dir
    from fmctd_dist.visual.load import load_vae

    pcfg = _parts(cfg)
    vae = load_vae(vae_dir(cfg, pcfg), cfg.env.name)
    store = load_latents(cfg, pcfg, vae)
    if vae.latent_dim != cfg.frame_dim:
        raise DatasetError(f"{store.path}: latents of {vae.latent_dim} dims, but env.name={cfg.env.name} plans "
                           f"{cfg.frame_dim}-D latents (families.ENVS); train the VAE with vae.latent_dim="
                           f"{cfg.frame_dim}")
    train, val = store.split("train"), store.split("val")
    if val["mu"].shape[0] == 0:
        raise DatasetError(f"{store.path} holds no validation episodes; rerun `python jobs/train_visual.py "
                           f"part=latents env={cfg.env.name} latents.val_episodes=5`")
    xy = train["xy"].reshape(-1, 2).astype(np.float64)
    return VisualLatentDataset(store.path, store.manifest, np.ascontiguousarray(train["mu"], np.float32),
                               np.ascontiguousarray(val["mu"], np.float32), xy.mean(0), xy.std(0))


__all__ = ["VisualLatentDataset", "make_visual_dataset", "load_visual_dataset", "LATENT_KEY"]
