"""The visual maze's planner data: VAE latents (mu per frame) of the latent store, as trajectories.

The Diffusion Forcing model of a visual maze plans 8-D latent trajectories (docs/reference.md §14). Its
training windows are cut from the latent store (``visual/latents.py``: every frame of a seeded
subset of train episodes, rendered once and encoded by the VAE) exactly as a point maze's are cut
from positions (``data/windows.py``, any jump H): only the frame state differs, [E, S, 8] here.

We use the encoder's mean (mu), not a sampled z: with KL weight 1e-6 the posterior's std is ~0.02
against a spread of ~2.8 (docs/results.md §13.3), and the controller sees mu of each new frame.

A latent means something only to the VAE that made it, so the dataset's digest is the store's
sha256 (a function of the VAE's weights) and :attr:`VisualLatentDataset.provenance` goes into the
model's manifest: the VAE digest and dir, the store's dir, sha256 and episode ids, and the mean /
std of the train positions (the scale in which guidance measures distances, ``visual/guide.py``).
``families/visual/hooks.py`` refuses a model whose manifest names another VAE than the one it loads.

With ``visual.plan_xy=true`` each frame is [mu, estimator(mu)] (``visual/frames_xy.py``): the
digest then adds the estimator's, and the provenance says ``plan_xy``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from fmctd_dist.config import Config
from fmctd_dist.tokens import Normaliser
from fmctd_dist.errors import DatasetError
from fmctd_dist.registry import require_family, state_dim
from fmctd_dist.hints import shown
from fmctd_dist.families.visual.config import LATENT_KEY, part_dir
from fmctd_dist.families.visual.frames_xy import PlanFrames

VISUAL_FAMILY = "visual-pointmaze"


@dataclass
class VisualLatentDataset:
    """mu [E, S, D] per split (visual.plan_xy: [mu, estimated x, y], D + 2), the surface ``data/windows.py``
    reads (train, val, normaliser, digest)."""

    path: Path
    manifest: dict[str, Any]  # the latent store's manifest
    train: np.ndarray  # [E, S, D] float32
    val: np.ndarray  # [E_val, S, D] float32
    xy_mean: np.ndarray  # [2] world units, of the train frames
    xy_std: np.ndarray  # [2]
    estimator_digest: str | None = None  # visual.plan_xy: the estimator whose (x, y) the frames carry

    @property
    def plan_xy(self) -> bool:
        return self.estimator_digest is not None

    @property
    def digest(self) -> str:
        sha = str(self.manifest["sha256"])
        return f"{sha}+xy{self.estimator_digest}" if self.plan_xy else sha

    @cached_property
    def normaliser(self) -> Normaliser:
        """Per-dimension mean and std of the train frames (computed once: the store is read-only here)."""
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
                             "xy_mean": self.xy_mean.tolist(), "xy_std": self.xy_std.tolist(),
                             **({"plan_xy": True, "estimator_digest": self.estimator_digest} if self.plan_xy else {})}}

    def position_readout(self, cfg: Config) -> tuple[Any, dict[str, Any]]:
        """Normalised frames -> standardised (x, y), the map guidance reads (``visual/guide.py``): through the
        frozen position estimator of this store's VAE, or (visual.plan_xy) the frames' own (x, y); for
        train.boundary_space=position and train.position_weight."""
        from fmctd_dist.families.visual.guide import EstimatorGuide, XYReadout, load_estimator_net

        norm, dim = self.normaliser, int(self.manifest["latent_dim"])
        if self.plan_xy:
            return (XYReadout(dim, norm.mean, norm.std, self.xy_mean, self.xy_std),
                    {"readout": "the frames' (x, y) (visual.plan_xy)", "estimator_digest": self.estimator_digest})
        net, m = load_estimator_net(cfg, str(self.manifest["vae"]["digest"]), dim)
        guide = EstimatorGuide(net, norm.mean, norm.std, self.xy_mean, self.xy_std)
        return guide, {"readout": "position estimator", "estimator": shown(part_dir(cfg, "", "estimator")),
                       "estimator_digest": m.get("digest")}


def _parts(cfg: Config):
    """The default parts config (VAE and latent store dirs: checkpoints/<env>-vae, data/<env>-latents-...)."""
    from fmctd_dist.families.visual.config import PartsConfig

    require_family(cfg.env.name, (VISUAL_FAMILY,), "the visual latent data")
    return PartsConfig()


def make_visual_dataset(cfg: Config, progress: bool = True) -> tuple[Path, dict[str, Any]]:
    """Encode (rendering first if needed) the latent store of ``cfg``, or verify the existing one."""
    from fmctd_dist.families.visual.latents import make_latents

    return make_latents(cfg, _parts(cfg), progress)


def load_visual_dataset(cfg: Config) -> VisualLatentDataset:
    """The checked latent store of ``cfg`` (VAE digest, env, latent size, sha256) as planner trajectories."""
    from fmctd_dist.families.visual.latents import load_latents, vae_dir
    from fmctd_dist.families.visual.load import load_vae

    pcfg = _parts(cfg)
    vae = load_vae(vae_dir(cfg, pcfg), cfg.env.name)
    store = load_latents(cfg, pcfg, vae)
    latent_dim = state_dim(cfg.env.name)
    if vae.latent_dim != latent_dim:
        raise DatasetError(f"{store.path}: latents of {vae.latent_dim} dims, but env.name={cfg.env.name} plans "
                           f"{latent_dim}-D latents (families.ENVS); train the VAE with vae.latent_dim="
                           f"{latent_dim}")
    train, val = store.split("train"), store.split("val")
    if val["mu"].shape[0] == 0:
        raise DatasetError(f"{store.path} holds no validation episodes; rerun `python jobs/train_visual.py "
                           f"part=latents env={cfg.env.name} latents.val_episodes=5`")
    xy = train["xy"].reshape(-1, 2).astype(np.float64)
    train_frames, val_frames, est_digest = train["mu"], val["mu"], None
    if cfg.visual.plan_xy:  # [z, estimator(z)] frames
        from fmctd_dist.families.visual.guide import load_positions

        positions, est_digest = load_positions(cfg, str(store.manifest["vae"]["digest"]), latent_dim)
        frames = PlanFrames(positions, latent_dim, True)
        train_frames, val_frames = frames.of_latents(train_frames), frames.of_latents(val_frames)
    return VisualLatentDataset(store.path, store.manifest, np.ascontiguousarray(train_frames, np.float32),
                               np.ascontiguousarray(val_frames, np.float32), xy.mean(0), xy.std(0), est_digest)


__all__ = ["VisualLatentDataset", "make_visual_dataset", "load_visual_dataset", "LATENT_KEY"]


def describe(manifest: dict[str, Any]) -> list[str]:
    """What ``jobs/make_dataset.py`` prints about the visual planner's latent dataset (its manifest's keys)."""
    return [f"  {k}: {v}" for k, v in manifest.items() if not isinstance(v, (dict, list))]


make, load = make_visual_dataset, load_visual_dataset  # the family's data protocol (fmctd_dist.registry.Family.data)
