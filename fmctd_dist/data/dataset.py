"""Navigate datasets: generate with the noisy oracle, write .npz + manifest, load and verify.

Layout: ``<data.root>/<env>-navigate-seed<seed>-<episodes>x<steps>/{train,val}.npz, manifest.json``.
Same config -> same bytes (per-episode seeds, deterministic npz). Loading verifies every
manifest field and sha256; a corrupt or mismatched file raises DatasetError and is never
silently regenerated over.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from fmctd_dist.config import Config, resolve_path
from fmctd_dist.data.npz import save_npz
from fmctd_dist.data.oracle import NoisyOracle
from fmctd_dist.data.tokens import Normaliser
from fmctd_dist.envs import make_env
from fmctd_dist.envs.maze import MazeGeometry
from fmctd_dist.envs.pointmaze import NOISE, GOAL_TOLERANCE, PointMaze
from fmctd_dist.errors import DatasetError

GENERATOR_VERSION = 1
SPLITS = {"train": 0, "val": 1}  # split id feeds the per-episode seed
MANIFEST_FIELDS = ("generator_version", "env", "seed", "noise", "episode_steps", "episodes",
                   "sha256", "obs_mean", "obs_std")


def dataset_dir(cfg: Config) -> Path:
    d = cfg.data
    return resolve_path(d.root) / f"{cfg.env.name}-navigate-seed{d.seed}-{d.episodes}x{d.episode_steps}"


def val_episodes(cfg: Config) -> int:
    return max(1, round(cfg.data.episodes * cfg.data.val_fraction))


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def generate_episode(env: PointMaze, oracle: NoisyOracle, steps: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """One navigate episode: random start cell, random vertex goal, a new goal on each success."""
    geo: MazeGeometry = env.geometry
    free, vertices = geo.free_cells(), geo.vertex_cells()
    start = geo.cell_to_xy(free[rng.integers(len(free))]) + rng.uniform(-NOISE, NOISE, size=2)
    goal = geo.cell_to_xy(vertices[rng.integers(len(vertices))])
    env.set_position(start)
    pos = env.position()
    obs = np.empty((steps, 2), np.float32)
    act = np.empty((steps, 2), np.float32)
    goals = np.empty((steps, 2), np.float32)
    for t in range(steps):
        a = oracle.act(pos, goal, rng)
        obs[t], act[t], goals[t] = pos, a, goal
        env.goal = goal
        pos, success = env.step(a)
        if success:
            goal = geo.cell_to_xy(vertices[rng.integers(len(vertices))])
    return {"observations": obs, "actions": act, "goals": goals}


def generate_split(cfg: Config, split: str, episodes: int, progress: bool = True) -> dict[str, np.ndarray]:
    env = make_env(cfg.env.name)
    env.reset(1, cfg.data.seed)  # initialise MuJoCo state; positions are then set per episode
    oracle = NoisyOracle(env.geometry, cfg.data.noise)
    out: dict[str, list[np.ndarray]] = {"observations": [], "actions": [], "goals": []}
    for ep in tqdm(range(episodes), desc=f"{cfg.env.name} {split}", unit="ep", disable=not progress):
        rng = np.random.default_rng(np.random.SeedSequence([cfg.data.seed, SPLITS[split], ep]))
        for k, v in generate_episode(env, oracle, cfg.data.episode_steps, rng).items():
            out[k].append(v)
    env.close()
    arrays = {k: np.stack(v) for k, v in out.items()}
    terminals = np.zeros(arrays["observations"].shape[:2], dtype=bool)
    terminals[:, -1] = True
    arrays["terminals"] = terminals
    return arrays


def make_dataset(cfg: Config, progress: bool = True) -> tuple[Path, dict[str, Any]]:
    """Generate (or verify an existing) dataset; return its dir and manifest."""
    out = dataset_dir(cfg)
    if (out / "manifest.json").exists():
        return out, load_manifest(out, cfg, verify=True)
    if out.exists() and any(out.iterdir()):
        raise DatasetError(f"{out} exists but has no manifest.json (an interrupted run?); delete the directory and rerun")
    tmp = out.with_name(out.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    t0 = time.time()
    splits = {"train": cfg.data.episodes, "val": val_episodes(cfg)}
    sha, counts = {}, {}
    normaliser = None
    for split, n in splits.items():
        arrays = generate_split(cfg, split, n, progress)
        if split == "train":
            flat = arrays["observations"].reshape(-1, 2).astype(np.float64)
            normaliser = (flat.mean(0).tolist(), flat.std(0).tolist())
        save_npz(tmp / f"{split}.npz", arrays)
        sha[split] = sha256_file(tmp / f"{split}.npz")
        counts[split] = n
    manifest = {
        "generator_version": GENERATOR_VERSION,
        "env": cfg.env.name,
        "seed": cfg.data.seed,
        "noise": cfg.data.noise,
        "episode_steps": cfg.data.episode_steps,
        "episodes": counts,
        "oracle": "BFS next-cell direction + N(0, noise^2), clipped; new vertex-cell goal on success "
                  f"(within {GOAL_TOLERANCE})",
        "sha256": sha,
        "obs_mean": normaliser[0],
        "obs_std": normaliser[1],
        "keys": ["observations", "actions", "goals", "terminals"],
    }
    (tmp / "manifest.json").write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")
    os.replace(tmp, out)
    manifest["_generation_s"] = time.time() - t0
    return out, manifest


def load_manifest(path: Path, cfg: Config | None = None, verify: bool = True) -> dict[str, Any]:
    """Read and check a manifest (fields, config agreement, file sha256)."""
    mf = path / "manifest.json"
    if not mf.is_file():
        raise DatasetError(
            f"no dataset at {path} (manifest.json missing); create it with "
            f"`python jobs/make_dataset.py env={cfg.env.name if cfg else '<env>'}`"
        )
    try:
        manifest = json.loads(mf.read_text())
    except json.JSONDecodeError as e:
        raise DatasetError(f"{mf} is not valid JSON ({e}); delete {path} and regenerate") from None
    for key in MANIFEST_FIELDS:
        if key not in manifest:
            raise DatasetError(f"{mf} lacks the field {key!r}; delete {path} and regenerate it")
    if manifest["generator_version"] != GENERATOR_VERSION:
        raise DatasetError(
            f"{mf}: generator_version={manifest['generator_version']} but this code writes {GENERATOR_VERSION}; "
            f"delete {path} and regenerate"
        )
    if cfg is not None:
        expect = {"env": cfg.env.name, "seed": cfg.data.seed, "noise": cfg.data.noise,
                  "episode_steps": cfg.data.episode_steps}
        for key, want in expect.items():
            if manifest[key] != want:
                raise DatasetError(f"{mf}: {key}={manifest[key]!r} but the config asks for {want!r}; "
                                   f"regenerate or fix data.{key if key != 'env' else 'env.name'}")
    if verify:
        for split, digest in manifest["sha256"].items():
            f = path / f"{split}.npz"
            if not f.is_file():
                raise DatasetError(f"{f} is missing; delete {path} and regenerate")
            if sha256_file(f) != digest:
                raise DatasetError(f"{f} is corrupt (sha256 differs from manifest.json); delete {path} and regenerate")
    return manifest


@dataclass
class NavigateDataset:
    """Observations [E, S, 2] per split plus the manifest (digest, normaliser)."""

    path: Path
    manifest: dict[str, Any]
    train: np.ndarray  # [E, S, 2] float32
    val: np.ndarray  # [E_val, S, 2] float32

    @property
    def digest(self) -> str:
        return self.manifest["sha256"]["train"]

    @property
    def normaliser(self) -> Normaliser:
        return Normaliser.from_lists(self.manifest["obs_mean"], self.manifest["obs_std"])


def load_dataset(cfg: Config, path: Path | None = None) -> NavigateDataset:
    path = path or dataset_dir(cfg)
    manifest = load_manifest(path, cfg, verify=True)
    splits = {}
    for split in ("train", "val"):
        try:
            with np.load(path / f"{split}.npz", allow_pickle=False) as z:
                obs = z["observations"]
        except (KeyError, ValueError, OSError) as e:
            raise DatasetError(f"{path / f'{split}.npz'} is malformed ({e}); delete {path} and regenerate") from None
        want = (manifest["episodes"][split], manifest["episode_steps"], 2)
        if obs.shape != want:
            raise DatasetError(f"{path / f'{split}.npz'}: observations shape {obs.shape} != manifest {want}; "
                               "delete the directory and regenerate")
        splits[split] = obs.astype(np.float32, copy=False)
    return NavigateDataset(path, manifest, splits["train"], splits["val"])
