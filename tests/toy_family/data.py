"""The toy family's data (make / load / describe): noisy straight walks between random points."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fmctd_dist.config import Config, resolve_path
from fmctd_dist.tokens import Normaliser

from toy_family.env import STEP


@dataclass
class ToyDataset:
    train: np.ndarray  # [E, S, 2]
    val: np.ndarray
    normaliser: Normaliser
    digest: str


def _dir(cfg: Config) -> Path:
    name = f"{cfg.env.name}-seed{cfg.data.seed}-{cfg.data.episodes}x{cfg.data.episode_steps}"
    return resolve_path(cfg.data.root) / name


def _walks(rng: np.random.Generator, n: int, steps: int) -> np.ndarray:
    out = np.empty((n, steps, 2))
    for e in range(n):
        pos, goal = rng.uniform(0, 8, 2), rng.uniform(0, 8, 2)
        for s in range(steps):
            out[e, s] = pos
            if np.linalg.norm(goal - pos) < 0.5:
                goal = rng.uniform(0, 8, 2)
            d = goal - pos
            pos = np.clip(pos + STEP * d / np.linalg.norm(d) + rng.normal(0, 0.02, 2), 0, 8)
    return out.astype(np.float32)


def make(cfg: Config, progress: bool = True) -> tuple[Path, dict[str, Any]]:
    path = _dir(cfg)
    if not (path / "manifest.json").exists():
        rng = np.random.default_rng(cfg.data.seed)
        train, val = _walks(rng, cfg.data.episodes, cfg.data.episode_steps), _walks(rng, 4, cfg.data.episode_steps)
        path.mkdir(parents=True, exist_ok=True)
        np.savez(path / "data.npz", train=train, val=val)
        digest = hashlib.sha256((path / "data.npz").read_bytes()).hexdigest()
        (path / "manifest.json").write_text(json.dumps({"env": cfg.env.name, "sha256": digest}))
    return path, json.loads((path / "manifest.json").read_text())


def load(cfg: Config) -> ToyDataset:
    path, manifest = make(cfg)
    arrays = np.load(path / "data.npz")
    train = arrays["train"]
    flat = train.reshape(-1, 2)
    return ToyDataset(train, arrays["val"], Normaliser(flat.mean(0), flat.std(0)), manifest["sha256"][:16])


def describe(manifest: dict[str, Any]) -> list[str]:
    return [f"  sha256={manifest['sha256']}"]
