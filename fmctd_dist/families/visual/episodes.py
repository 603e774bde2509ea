"""Every frame of a seeded subset of episodes, rendered once and kept: the planner's and the inverse dynamics' frames.

The VAE trains on scattered frames; the inverse dynamics needs *consecutive* ones, and the
planner's Diffusion Forcing data is whole latent trajectories. So every frame of
``visual.episodes`` seeded train episodes (:func:`~fmctd_dist.families.visual.frame_sets.episode_subset`)
and of ``latents.val_episodes`` seeded validation episodes (held-out consecutive frames) is
rendered here, one ``.npz`` per episode (images uint8 [S, 64, 64, 3], xy [S, 2], actions [S, 2]),
so rendering can run while the VAE trains and an interrupted run resumes at the next episode.
The manifest records the episode ids, the point dataset's digests, the renderer and a frames
digest (sha256 over every episode's image bytes, in order) that the latent store repeats.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from fmctd_dist.config import Config, resolve_path
from fmctd_dist.families.maze.data import dataset_dir, load_dataset
from fmctd_dist.data.manifest_io import read_manifest_json
from fmctd_dist.data.npz import load_npz, save_npz
from fmctd_dist.families.visual.frame_sets import STREAM, episode_subset, point_config, render_info
from fmctd_dist.families.visual.env import IMAGE_SIZE, FrameRenderer
from fmctd_dist.errors import DatasetError
from fmctd_dist.hints import shown
from fmctd_dist.families.visual.config import PartsConfig

EPISODES_VERSION = 1


def val_episode_subset(cfg: Config, n: int, total: int) -> np.ndarray:
    """int64 sorted validation episode ids (seeded by ``visual.frames_seed``); all when n >= total."""
    if n >= total:
        return np.arange(total, dtype=np.int64)
    rng = np.random.default_rng(np.random.SeedSequence([cfg.visual.frames_seed, STREAM, 98]))
    return np.sort(rng.choice(total, size=n, replace=False)).astype(np.int64)


def episodes_dir(cfg: Config, pcfg: PartsConfig) -> Path:
    d, v = cfg.data, cfg.visual
    return resolve_path(d.root) / (f"{cfg.env.name}-episodes-seed{v.frames_seed}-n{v.episodes}-val"
                                   f"{pcfg.latents.val_episodes}-shadow{v.shadowsize}-data{d.seed}-"
                                   f"{d.episodes}x{d.episode_steps}")


def _file(split: str, e: int) -> str:
    return f"{split}-{e:04d}.npz"


def _actions(cfg: Config, split: str) -> np.ndarray:
    path = dataset_dir(point_config(cfg))
    return load_npz(path / f"{split}.npz", {"actions": (np.float32, (None, cfg.data.episode_steps, 2))},
                    f"regenerate it: python jobs/make_dataset.py env={point_config(cfg).env.name}")["actions"]


def make_episodes(cfg: Config, pcfg: PartsConfig, progress: bool = True) -> tuple[Path, dict[str, Any]]:
    """Render (or finish, or verify) every frame of the seeded episodes; return the dir and its manifest."""
    out = episodes_dir(cfg, pcfg)
    data = load_dataset(point_config(cfg))
    if (out / "manifest.json").exists():
        return out, load_episodes_manifest(out, cfg, data.digest)
    ids = {"train": episode_subset(cfg), "val": val_episode_subset(cfg, pcfg.latents.val_episodes, data.val.shape[0])}
    out.mkdir(parents=True, exist_ok=True)
    renderer: FrameRenderer | None = None
    steps = data.train.shape[1]
    todo = [(s, int(e)) for s in ("train", "val") for e in ids[s] if not (out / _file(s, int(e))).exists()]
    t0, rendered = time.perf_counter(), 0
    actions = {s: _actions(cfg, s) for s in ("train", "val")}
    with tqdm(total=len(todo) * steps, desc=f"episodes {cfg.env.name}", unit="frame", disable=not progress) as bar:
        for split, e in todo:
            if (out / _file(split, e)).exists():  # another process of this job rendered it meanwhile
                bar.update(steps)
                continue
            renderer = renderer or FrameRenderer(cfg.env.name, shadowsize=cfg.visual.shadowsize)
            xy = getattr(data, split)[e].astype(np.float64)
            images = np.concatenate([renderer.render(xy[a:a + 100]) for a in range(0, steps, 100)])
            tmp = out / (_file(split, e) + ".tmp")
            save_npz(tmp, {"images": images, "xy": xy.astype(np.float32), "actions": actions[split][e]})
            os.replace(tmp, out / _file(split, e))
            rendered += steps
            bar.update(steps)
    wall = time.perf_counter() - t0
    info = render_info(renderer) if renderer is not None else {}
    if renderer is not None:
        renderer.close()
    h = hashlib.sha256()
    for split in ("train", "val"):
        for e in ids[split]:
            h.update(load_npz(out / _file(split, int(e)), {"images": (np.uint8, (steps, IMAGE_SIZE, IMAGE_SIZE, 3))},
                              f"delete {out} and rerun")["images"].tobytes())
    manifest = {"version": EPISODES_VERSION, "env": cfg.env.name, "frames_seed": cfg.visual.frames_seed,
                "episodes": ids["train"].tolist(), "val_episodes": ids["val"].tolist(), "episode_steps": steps,
                "dataset": {"path": shown(data.path), "digest": data.digest,
                            "val_digest": data.manifest["sha256"]["val"]},
                "render": info, "frames_digest": h.hexdigest(),
                "generation": {"rendered_frames": rendered, "wall_s": round(wall, 2),
                               "frames_per_s": round(rendered / max(wall, 1e-9), 2)}}
    (out / "manifest.json").write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n")
    return out, manifest


def load_episodes_manifest(path: Path, cfg: Config, digest: str | None = None) -> dict[str, Any]:
    m = read_manifest_json(path, f"render them with `python jobs/train_visual.py part=episodes env={cfg.env.name}`",
                           f"delete {path} and rerun", what="episode frames")
    if m.get("env") != cfg.env.name or m.get("version") != EPISODES_VERSION:
        raise DatasetError(f"{path / 'manifest.json'}: env={m.get('env')!r} version={m.get('version')!r}, but the "
                           f"config asks for env={cfg.env.name} version {EPISODES_VERSION}; delete {path} and rerun")
    if digest is not None and m["dataset"]["digest"] != digest:
        raise DatasetError(f"{path / 'manifest.json'}: rendered from dataset {m['dataset']['digest'][:12]} but the "
                           f"point dataset now holds {digest[:12]}; delete {path} and rerun")
    return m


def load_episode(path: Path, split: str, e: int, steps: int) -> dict[str, np.ndarray]:
    """images uint8 [S, 64, 64, 3], xy [S, 2], actions [S, 2] of one rendered episode."""
    return load_npz(path / _file(split, e), {"images": (np.uint8, (steps, IMAGE_SIZE, IMAGE_SIZE, 3)),
                                             "xy": (np.float32, (steps, 2)), "actions": (np.float32, (steps, 2))},
                    f"delete {path} and rerun jobs/train_visual.py part=episodes")
