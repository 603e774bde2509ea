"""Train / val splits, shared by every family's data (navigate, ant, cube): seeding, and the split files.

Episode ``ep`` of split ``s`` draws from ``SeedSequence([data.seed, SPLITS[s], ep])`` only, so
any episode can be regenerated alone and a smaller dataset is a prefix of a larger one. Each split
is one ``<split>.npz`` whose ``observations`` [E, S, obs_dim] hold the planner's state columns; its
sha256 and the train split's state moments go to the family's manifest, written, checked and read
here the same way for every family.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from fmctd_dist.artifacts import sha256_file
from fmctd_dist.config import Config
from fmctd_dist.data.npz import load_npz, save_npz
from fmctd_dist.errors import DatasetError
from fmctd_dist.tokens import Normaliser

SPLITS = {"train": 0, "val": 1}  # split id feeds the per-episode seed


def val_episodes(cfg: Config) -> int:
    """Validation episodes beside ``data.episodes`` training ones (OGBench: 10%)."""
    return max(1, round(cfg.data.episodes * cfg.data.val_fraction))


def episode_rng(cfg: Config, split: str, ep: int) -> np.random.Generator:
    """Episode ``ep`` of ``split`` draws only from its own stream: any episode can be regenerated alone."""
    return np.random.default_rng(np.random.SeedSequence([cfg.data.seed, SPLITS[split], ep]))


def write_splits(tmp: Path, cfg: Config, generate: Callable[[str, int], dict[str, np.ndarray]],
                 cols: Any) -> tuple[dict[str, int], dict[str, str], tuple[list[float], list[float]]]:
    """Each split's arrays from ``generate(split, episodes)`` into a fresh ``tmp/<split>.npz``; returns the
    manifest's episode counts and sha256 per split, and the mean and std of the train split's state
    columns ``observations[..., cols]`` (the planner's normaliser)."""
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    episodes = {"train": cfg.data.episodes, "val": val_episodes(cfg)}
    sha, moments = {}, ([], [])
    for split, n in episodes.items():
        arrays = generate(split, n)
        if split == "train":
            states = arrays["observations"][..., cols]
            flat = states.reshape(-1, states.shape[-1]).astype(np.float64)
            moments = flat.mean(0).tolist(), flat.std(0).tolist()
        save_npz(tmp / f"{split}.npz", arrays)
        sha[split] = sha256_file(tmp / f"{split}.npz")
        del arrays  # a large split is freed before the next is generated
    return episodes, sha, moments


def verify_splits(path: Path, sha256: dict[str, str], fix: str) -> None:
    """Every split file is there with the sha256 its manifest records; else one DatasetError ending in ``fix``."""
    for split in SPLITS:
        f = path / f"{split}.npz"
        if not f.is_file():
            raise DatasetError(f"{f} is missing; {fix}")
        if sha256_file(f) != sha256.get(split):
            raise DatasetError(f"{f} is corrupt (sha256 differs from manifest.json); {fix}")


def load_split_states(path: Path, manifest: dict[str, Any], cols: Any, fix: str) -> dict[str, np.ndarray]:
    """The state columns ``observations[..., cols]`` of each split, float32 [E, S, d], after checking the
    arrays against the manifest's episodes, steps and obs_dim (2 when it records none)."""
    out = {}
    for split in SPLITS:
        want = (manifest["episodes"][split], manifest["episode_steps"], manifest.get("obs_dim", 2))
        obs = load_npz(path / f"{split}.npz", {"observations": (np.float32, want)},
                       f"it does not match {path / 'manifest.json'}; {fix}")["observations"]
        out[split] = np.ascontiguousarray(obs[..., cols], dtype=np.float32)
    return out


@dataclass
class SplitStates:
    """The planner's states [E, S, d] per split plus the manifest they were checked against: what
    ``data/windows.py`` draws training windows from. ``MOMENTS`` names the manifest's mean and std fields."""

    MOMENTS = ("obs_mean", "obs_std")

    path: Path
    manifest: dict[str, Any]
    train: np.ndarray  # [E, S, d] float32
    val: np.ndarray  # [E_val, S, d] float32

    @property
    def digest(self) -> str:
        return self.manifest["sha256"]["train"]

    @property
    def normaliser(self) -> Normaliser:
        return Normaliser.from_lists(*(self.manifest[k] for k in self.MOMENTS))
