"""The VAE's frames with their positions, loaded once and checked (sha256, config, dataset) by the frames store.

The estimator and the VAE's linear probe need the point's (x, y) beside each frame; the frames
store (:mod:`fmctd_dist.families.visual.frame_sets`) keeps them in the same ``frames.npz``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fmctd_dist.config import Config
from fmctd_dist.data.npz import load_npz
from fmctd_dist.families.visual.frame_sets import frames_dir, load_frames
from fmctd_dist.hints import shown


@dataclass
class FrameSet:
    path: Path
    manifest: dict[str, Any]
    train_images: np.ndarray  # [N, 64, 64, 3] uint8
    train_xy: np.ndarray  # [N, 2] float32, world units
    val_images: np.ndarray  # [N_val, 64, 64, 3] uint8, frames of validation episodes
    val_xy: np.ndarray  # [N_val, 2] float32

    @property
    def sha256(self) -> str:
        return str(self.manifest["sha256"])

    def record(self) -> dict[str, Any]:
        """What a part's manifest says about the frames it was trained on."""
        m = self.manifest
        return {"path": shown(self.path), "sha256": m["sha256"], "frames": m["frames"], "val_frames": m["val_frames"],
                "frames_seed": m["frames_seed"], "shadowsize": m["render"]["shadowsize"],
                "dataset_digest": m["dataset"]["digest"], "dataset_val_digest": m["dataset"]["val_digest"]}


def load_frame_set(cfg: Config, path: Path | None = None) -> FrameSet:
    """Both splits of ``cfg``'s frames (DatasetError naming jobs/render_frames.py when missing or stale)."""
    path = path or frames_dir(cfg)
    train, _, m = load_frames(cfg, "train", path)
    val, _, _ = load_frames(cfg, "val", path)
    xy = load_npz(path / "frames.npz", {"xy": (np.float32, (len(train), 2)), "val_xy": (np.float32, (len(val), 2))},
                  f"delete {path} and rerun jobs/render_frames.py")
    return FrameSet(path, m, train, xy["xy"], val, xy["val_xy"])
