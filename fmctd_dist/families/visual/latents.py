"""The latent store: every rendered episode frame encoded once by the VAE (the planner's and inverse dynamics' data).

    latents.npz: episodes [E] int64, mu / logvar [E, S, D] float32, xy / actions [E, S, 2] float32,
                 and the same with a ``val_`` prefix for the held-out validation episodes
    manifest.json: env, episode ids, the VAE (dir, digest, latent size), the frames digest of the
                 rendered episodes, the point dataset's digests, sha256 of latents.npz

Stored as (mu, logvar) rather than one draw, so every user samples its own z (the authors use
the sampled z) and encoding is deterministic: the same states, renderer and VAE give the same
bytes. The dir is named by the VAE's digest, so latents of another VAE never mix with these.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from fmctd_dist.artifacts import sha256_file
from fmctd_dist.config import Config, resolve_path
from fmctd_dist.data.manifest_io import read_manifest_json
from fmctd_dist.data.npz import load_npz, save_npz
from fmctd_dist.hints import shown
from fmctd_dist.errors import DatasetError
from fmctd_dist.families.visual.config import PartsConfig, part_dir
from fmctd_dist.families.visual.episodes import load_episode, make_episodes
from fmctd_dist.families.visual.load import LoadedVAE, load_vae
from fmctd_dist.families.visual.vae import encode_frames

LATENTS_VERSION = 1


@dataclass
class LatentStore:
    path: Path
    manifest: dict[str, Any]
    arrays: dict[str, np.ndarray]  # see the module docstring

    def split(self, split: str) -> dict[str, np.ndarray]:
        """mu, logvar, xy, actions, episodes of 'train' or 'val'."""
        pre = "" if split == "train" else "val_"
        return {k: self.arrays[pre + k] for k in ("episodes", "mu", "logvar", "xy", "actions")}


def vae_dir(cfg: Config, pcfg: PartsConfig) -> Path:
    return part_dir(cfg, pcfg.latents.vae or pcfg.vae.out, "vae")


def latents_dir(cfg: Config, pcfg: PartsConfig, vae_digest: str) -> Path:
    if pcfg.latents.out:
        return resolve_path(pcfg.latents.out)
    d, v = cfg.data, cfg.visual
    return resolve_path(d.root) / (f"{cfg.env.name}-latents-seed{v.frames_seed}-n{v.episodes}-val"
                                   f"{pcfg.latents.val_episodes}-vae{vae_digest}-data{d.seed}")


def make_latents(cfg: Config, pcfg: PartsConfig, progress: bool = True,
                 vae: LoadedVAE | None = None) -> tuple[Path, dict[str, Any]]:
    """Encode (rendering first if needed) every frame of the seeded episodes; verify an existing store instead."""
    vae = vae or load_vae(vae_dir(cfg, pcfg), cfg.env.name)
    out = latents_dir(cfg, pcfg, vae.digest)
    if (out / "manifest.json").exists():
        return out, load_latents(cfg, pcfg, vae, out).manifest
    ep_dir, em = make_episodes(cfg, pcfg, progress)
    steps = em["episode_steps"]
    arrays: dict[str, np.ndarray] = {}
    t0 = time.perf_counter()
    total = (len(em["episodes"]) + len(em["val_episodes"])) * steps
    with tqdm(total=total, desc=f"encode {cfg.env.name}", unit="frame", disable=not progress) as bar:
        for split, ids in (("train", em["episodes"]), ("val", em["val_episodes"])):
            parts: dict[str, list[np.ndarray]] = {"mu": [], "logvar": [], "xy": [], "actions": []}
            for e in ids:
                ep = load_episode(ep_dir, split, int(e), steps)
                mu, logvar = encode_frames(vae.net, ep["images"], pcfg.latents.batch)
                for k, a in (("mu", mu), ("logvar", logvar), ("xy", ep["xy"]), ("actions", ep["actions"])):
                    parts[k].append(a)
                bar.update(steps)
            pre = "" if split == "train" else "val_"
            arrays[pre + "episodes"] = np.asarray(ids, dtype=np.int64)
            for k, xs in parts.items():
                arrays[pre + k] = (np.stack(xs) if xs else np.zeros((0, steps, vae.latent_dim if k in ("mu", "logvar")
                                                                     else 2))).astype(np.float32)
    wall = time.perf_counter() - t0
    tmp = out.with_name(out.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    save_npz(tmp / "latents.npz", arrays)
    manifest = {"version": LATENTS_VERSION, "env": cfg.env.name, "latent_dim": vae.latent_dim,
                "episodes": list(em["episodes"]), "val_episodes": list(em["val_episodes"]), "episode_steps": steps,
                "frames": total, "vae": {"path": shown(vae.path), "digest": vae.digest},
                "frames_dir": shown(ep_dir), "frames_digest": em["frames_digest"], "dataset": em["dataset"],
                "render": {k: em["render"].get(k) for k in ("camera", "shadowsize", "mujoco", "ogbench", "gl")},
                "sha256": sha256_file(tmp / "latents.npz"),
                "generation": {"encode_wall_s": round(wall, 2), "render": em["generation"]}}
    (tmp / "manifest.json").write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n")
    if out.exists():
        shutil.rmtree(out)
    os.replace(tmp, out)
    return out, manifest


def load_latents(cfg: Config, pcfg: PartsConfig, vae: LoadedVAE, path: Path | None = None) -> LatentStore:
    """A latent store checked against the VAE that reads it (digest, latent size), the env and its sha256."""
    path = path or latents_dir(cfg, pcfg, vae.digest)
    make = f"python jobs/train_visual.py part=latents env={cfg.env.name} visual.episodes={cfg.visual.episodes}"
    m = read_manifest_json(path, f"make it with `{make}`", f"delete {path} and rerun `{make}`", what="latent store")
    mf = path / "manifest.json"
    for key, want in (("version", LATENTS_VERSION), ("env", cfg.env.name), ("latent_dim", vae.latent_dim)):
        if m.get(key) != want:
            raise DatasetError(f"{mf}: {key}={m.get(key)!r} but this run needs {want!r}; point latents.out at a "
                               f"store made for it, or delete {path} and rerun `{make}`")
    if m.get("vae", {}).get("digest") != vae.digest:
        raise DatasetError(f"{mf}: encoded by VAE {m.get('vae', {}).get('digest')!r} but the VAE here is "
                           f"{vae.digest!r} ({vae.path}); its latents mean something else: rerun `{make}`")
    if sha256_file(path / "latents.npz") != m.get("sha256"):
        raise DatasetError(f"{path / 'latents.npz'} does not match its manifest sha256 (corrupt or edited); delete "
                           f"{path} and rerun `{make}`")
    e, v, s, d = len(m["episodes"]), len(m["val_episodes"]), m["episode_steps"], m["latent_dim"]
    expect: dict[str, tuple[Any, tuple[int, ...]]] = {}
    for pre, n in (("", e), ("val_", v)):
        expect.update({pre + "episodes": (np.int64, (n,)), pre + "mu": (np.float32, (n, s, d)),
                       pre + "logvar": (np.float32, (n, s, d)), pre + "xy": (np.float32, (n, s, 2)),
                       pre + "actions": (np.float32, (n, s, 2))})
    return LatentStore(path, m, load_npz(path / "latents.npz", expect, f"delete {path} and rerun `{make}`"))
