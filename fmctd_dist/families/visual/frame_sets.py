"""Visual PointMaze frames, rendered on demand from the point maze's states (issue 21).

The visual maze's data is the point maze's navigate data (BFS-subgoal oracle, noise 0.5, 1000 x
1001 steps + validation), stored once as states and actions by ``jobs/make_dataset.py
env=pointmaze-<maze>``. Raw images would be ~12 GB per maze, and CPU Mesa renders tens of frames
per second (docs/results.md section 13), so we render only what training needs:

- the VAE: a seeded subset of ``visual.frames`` train-split frames, plus ``data.val_fraction`` as
  many from the validation split for held-out reconstruction error (this module: one .npz of
  uint8 images + a manifest with the seed, the frame indices, the dataset digest and sha256);
- the planner's latent data: every frame of ``visual.episodes`` seeded train episodes (0 = all),
  rendered once and encoded by the VAE (:func:`episode_subset` says which, :func:`episode_frames`
  renders them; the latent store records them in its manifest).

Same config -> same frame indices -> same bytes (``save_npz`` has fixed zip headers; MuJoCo +
Mesa draw the same pixels for the same state on the same software stack, recorded below).
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import time
from pathlib import Path
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from fmctd_dist.config import Config, resolve_path
from fmctd_dist.artifacts import sha256_file
from fmctd_dist.families.maze.data import SPLITS, NavigateDataset, load_dataset
from fmctd_dist.data.manifest_io import read_manifest_json
from fmctd_dist.data.npz import load_npz, save_npz
from fmctd_dist.families.visual.env import (CAMERA, CAMERA_POS, CAMERA_XYAXES, IMAGE_SIZE, FrameRenderer,
                                              point_env_name)
from fmctd_dist.errors import ConfigError, DatasetError
from fmctd_dist.hints import shown  # relative paths: manifests read the same on every checkout

FRAMES_VERSION = 2  # 2: validation frames beside the train ones
CHUNK = 100  # frames per progress-bar step
STREAM = 21  # second SeedSequence word: these draws differ from any other use of the same seed
MANIFEST_FIELDS = ("version", "env", "point_env", "frames_seed", "frames", "frame_index", "val_frames",
                   "val_frame_index", "dataset", "render", "sha256")


def point_config(cfg: Config) -> Config:
    """The point maze config whose dataset the visual env ``cfg.env.name`` renders (same data.* fields)."""
    return dataclasses.replace(cfg, env=dataclasses.replace(cfg.env, name=point_env_name(cfg.env.name)))


def frames_dir(cfg: Config) -> Path:
    d, v = cfg.data, cfg.visual
    return resolve_path(d.root) / (f"{cfg.env.name}-frames-seed{v.frames_seed}-n{v.frames}-shadow{v.shadowsize}"
                                   f"-data{d.seed}-{d.episodes}x{d.episode_steps}")


def frame_subset(seed: int, episodes: int, steps: int, n: int, split: str = "train") -> np.ndarray:
    """int64 [n] sorted flat indices (episode * steps + step) of ``split``, drawn without replacement from ``seed``."""
    total = episodes * steps
    if n > total:
        raise ConfigError(f"visual.frames={n} exceeds the {total} {split} frames ({episodes} x {steps}); "
                          f"use at most {total}")
    rng = np.random.default_rng(np.random.SeedSequence([seed, STREAM, SPLITS[split]]))
    return np.sort(rng.choice(total, size=n, replace=False)).astype(np.int64)


def episode_subset(cfg: Config) -> np.ndarray:
    """int64 sorted train episode ids whose every frame the planner's latent data holds (``visual.episodes``).

    0 = all ``data.episodes``; otherwise a seeded draw (``visual.frames_seed``) without replacement.
    """
    n, total = cfg.visual.episodes, cfg.data.episodes
    if n == 0 or n == total:
        return np.arange(total, dtype=np.int64)
    if n > total:
        raise ConfigError(f"visual.episodes={n} exceeds data.episodes={total}; use at most {total} (0 = all)")
    rng = np.random.default_rng(np.random.SeedSequence([cfg.visual.frames_seed, STREAM, 99]))
    return np.sort(rng.choice(total, size=n, replace=False)).astype(np.int64)


def episode_frames(cfg: Config, data: NavigateDataset, renderer: FrameRenderer):
    """Yield (episode id, uint8 [S, 64, 64, 3]) for every train episode of :func:`episode_subset`, in order.

    One episode's frames at a time (1001 frames = 12 MB), for the latent store to encode and drop.
    """
    for e in episode_subset(cfg):
        yield int(e), renderer.render(data.train[e].astype(np.float64))


def render_info(renderer: FrameRenderer) -> dict[str, Any]:
    """What drew the pixels: camera, shadow map, and the software that rasterised them."""
    from importlib.metadata import version

    import mujoco

    gl = "unknown"
    try:
        from OpenGL import GL

        renderer.renderer._gl_context.make_current()
        gl = f"{GL.glGetString(GL.GL_RENDERER).decode()} / {GL.glGetString(GL.GL_VERSION).decode()}"
    except Exception:  # the record is informative; rendering itself has already worked
        pass
    return {"camera": CAMERA, "camera_pos": list(CAMERA_POS), "camera_xyaxes": list(CAMERA_XYAXES),
            "camera_mode": "trackcom", "size": IMAGE_SIZE, "shadowsize": renderer.shadowsize,
            "mujoco": mujoco.__version__, "ogbench": version("ogbench"),
            "mujoco_gl": os.environ.get("MUJOCO_GL", ""), "gl": gl}


def make_frames(cfg: Config, progress: bool = True) -> tuple[Path, dict[str, Any]]:
    """Render (or verify existing) VAE frames for ``cfg``; return the dir and its manifest.

    Needs the point maze dataset (``jobs/make_dataset.py env=pointmaze-<maze>``); its train split's
    sha256 is recorded, and a later load refuses frames made from other data.
    """
    out = frames_dir(cfg)
    data = load_dataset(point_config(cfg))  # DatasetError naming the make_dataset command if missing
    if (out / "manifest.json").exists():
        return out, load_manifest(out, cfg, data.digest)
    if out.exists() and any(out.iterdir()):
        raise DatasetError(f"{out} exists but has no manifest.json (an interrupted run?); delete it and rerun")
    episodes, steps, _ = data.train.shape
    n_val = min(max(1, round(cfg.visual.frames * cfg.data.val_fraction)), data.val.shape[0] * steps)
    index = {"train": frame_subset(cfg.visual.frames_seed, episodes, steps, cfg.visual.frames),
             "val": frame_subset(cfg.visual.frames_seed, data.val.shape[0], steps, n_val, "val")}
    xy = {s: getattr(data, s).reshape(-1, 2)[index[s]].astype(np.float64) for s in index}
    renderer = FrameRenderer(cfg.env.name, shadowsize=cfg.visual.shadowsize)
    images = {s: np.empty((len(index[s]), IMAGE_SIZE, IMAGE_SIZE, 3), dtype=np.uint8) for s in index}
    t0 = time.perf_counter()
    total = sum(len(i) for i in index.values())
    with tqdm(total=total, desc=f"render {cfg.env.name}", unit="frame", disable=not progress) as bar:
        for s in index:
            for a in range(0, len(index[s]), CHUNK):
                images[s][a:a + CHUNK] = renderer.render(xy[s][a:a + CHUNK])
                bar.update(len(xy[s][a:a + CHUNK]))
    wall = time.perf_counter() - t0
    info = render_info(renderer)
    renderer.close()
    tmp = out.with_name(out.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    save_npz(tmp / "frames.npz", {"images": images["train"], "frame_index": index["train"],
                                  "xy": xy["train"].astype(np.float32), "val_images": images["val"],
                                  "val_frame_index": index["val"], "val_xy": xy["val"].astype(np.float32)})
    manifest = {
        "version": FRAMES_VERSION, "env": cfg.env.name, "point_env": point_env_name(cfg.env.name),
        "frames_seed": cfg.visual.frames_seed, "frames": len(index["train"]), "val_frames": n_val,
        "frame_index": index["train"].tolist(),  # flat: episode * episode_steps + step, train split
        "val_frame_index": index["val"].tolist(),  # the same over the validation split's episodes
        "dataset": {"path": shown(data.path), "digest": data.digest, "val_digest": data.manifest["sha256"]["val"],
                    "seed": cfg.data.seed, "episodes": episodes, "val_episodes": data.val.shape[0],
                    "episode_steps": steps},
        "render": info, "sha256": sha256_file(tmp / "frames.npz"),
        "generation": {"wall_s": round(wall, 2), "frames_per_s": round(total / max(wall, 1e-9), 2)},
    }
    (tmp / "manifest.json").write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n")
    os.replace(tmp, out)
    return out, manifest


def load_manifest(path: Path, cfg: Config, digest: str | None = None) -> dict[str, Any]:
    """Read and check a frames manifest against ``cfg`` (and the dataset's ``digest``) and its file's sha256."""
    mf = path / "manifest.json"
    m = read_manifest_json(path, f"render them with `python jobs/render_frames.py env={cfg.env.name}`",
                           f"delete {path} and rerun jobs/render_frames.py", what="frames")
    missing = [k for k in MANIFEST_FIELDS if k not in m]
    if missing:
        raise DatasetError(f"{mf} lacks the field {missing[0]!r}; delete {path} and rerun jobs/render_frames.py")
    want = {"version": FRAMES_VERSION, "env": cfg.env.name, "frames_seed": cfg.visual.frames_seed,
            "frames": cfg.visual.frames}
    for key, value in want.items():
        if m[key] != value:
            raise DatasetError(f"{mf}: {key}={m[key]!r} but the config asks for {value!r}; delete {path} and rerun")
    if m["render"].get("shadowsize") != cfg.visual.shadowsize:
        raise DatasetError(f"{mf}: rendered with shadowsize={m['render'].get('shadowsize')} but visual.shadowsize="
                           f"{cfg.visual.shadowsize}; delete {path} and rerun")
    if digest is not None and m["dataset"]["digest"] != digest:
        raise DatasetError(f"{mf}: rendered from dataset {m['dataset']['digest'][:12]} but "
                           f"{m['dataset']['path']} now holds {digest[:12]}; delete {path} and rerun")
    if sha256_file(path / "frames.npz") != m["sha256"]:
        raise DatasetError(f"{path / 'frames.npz'} does not match its manifest sha256 (corrupt or edited); "
                           f"delete {path} and rerun jobs/render_frames.py")
    return m


def load_frames(cfg: Config, split: str = "train",
                path: Path | None = None) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """(images uint8 [N, 64, 64, 3], frame_index int64 [N], manifest) of ``split``, checked against cfg and sha256."""
    if split not in SPLITS:
        raise ValueError(f"split={split!r}: use 'train' or 'val'")
    path = path or frames_dir(cfg)
    m = load_manifest(path, cfg)
    pre = "" if split == "train" else "val_"
    n = m[f"{pre}frames"]
    z = load_npz(path / "frames.npz", {f"{pre}images": (np.uint8, (n, IMAGE_SIZE, IMAGE_SIZE, 3)),
                                       f"{pre}frame_index": (np.int64, (n,))},
                 f"delete {path} and rerun jobs/render_frames.py")
    if z[f"{pre}frame_index"].tolist() != m[f"{pre}frame_index"]:
        raise DatasetError(f"{path / 'frames.npz'}: {pre}frame_index differs from its manifest; "
                           f"delete {path} and rerun")
    return z[f"{pre}images"], z[f"{pre}frame_index"], m
