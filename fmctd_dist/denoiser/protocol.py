"""The Denoiser protocol: the only thing a planner asks of a diffusion model.

A job is one partially denoised token sequence plus the per-transition noise levels it
must go through. Expansion (20 pyramid rows) and jumpy simulation (every 10th row + final)
are the same call, so one protocol serves MCTD, P-MCTD, S-MCTD, Fast-MCTD and the baselines.
Arrays are numpy (no torch here): the search imports this module and stays framework-free.
A denoiser is a pure function of its inputs; all randomness is drawn from per-job seeds the
caller chooses (initial noise by the tree owner; re-noising noise, for the rows of a schedule that
go back up, from ``noise_seed``), so results do not depend on batching or on which actor ran.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np


@dataclass(frozen=True)
class DenoiseBatch:
    """B independent jobs.

    x:      [B, T, D] float32  token sequences (token 0 = clean context, normalised space)
    levels: [B, R+1, T] int64  noise level of every token before/after each of R transitions;
            row r -> row r+1 is one DDIM transition. Padding rows repeat the last row (no-op).
            A row where a token's level goes up re-noises it (RePaint's resampling; needs noise_seed).
    scale:  [B] float32        guidance scale per job (0 = unguided)
    start:  [B, d] float32     start position, normalised (guidance target for the context)
    goal:   [B, d] float32     goal position, normalised (guidance target for plan frames)
    noise_seed: [B] int64 or None  per-job seed of the re-noising draws (None: no row may go up)
    guide_mask: [B, d] float32 or None  per job, 1 on the frame-state dims the goal term of the
            guidance uses (cubes: the chosen cube's xyz, object-wise guidance); None = every dim
    """

    x: np.ndarray
    levels: np.ndarray
    scale: np.ndarray
    start: np.ndarray
    goal: np.ndarray
    noise_seed: np.ndarray | None = None
    guide_mask: np.ndarray | None = None

    def __post_init__(self) -> None:
        b, t, _ = self.x.shape
        assert self.levels.ndim == 3 and self.levels.shape[0] == b and self.levels.shape[2] == t, (
            f"levels {self.levels.shape} does not match x {self.x.shape}"
        )
        assert self.scale.shape == (b,), f"scale {self.scale.shape} != ({b},)"
        assert self.start.shape[0] == b and self.goal.shape[0] == b
        assert self.noise_seed is None or self.noise_seed.shape == (b,), f"noise_seed {self.noise_seed.shape} != ({b},)"
        assert self.guide_mask is None or self.guide_mask.shape == self.goal.shape, (
            f"guide_mask {self.guide_mask.shape} != goal {self.goal.shape}"
        )

    @property
    def size(self) -> int:
        return int(self.x.shape[0])

    def take(self, idx: np.ndarray | slice) -> "DenoiseBatch":
        """Sub-batch (used to cut micro-batches in job order)."""
        seed = None if self.noise_seed is None else self.noise_seed[idx]
        mask = None if self.guide_mask is None else self.guide_mask[idx]
        return DenoiseBatch(self.x[idx], self.levels[idx], self.scale[idx], self.start[idx], self.goal[idx], seed, mask)


@dataclass
class DenoiseResult:
    """x: [B, T, D] tokens after the last transition; x0: [B, T, D] the model's final x0 estimate."""

    x: np.ndarray
    x0: np.ndarray
    denoise_time_s: float = 0.0  # wall time inside the model calls (summed over micro-batches)
    retries: int = 0  # calls (segments of micro-batches) re-run after a failure (Ray pool only)
    stats: dict = field(default_factory=dict)


@runtime_checkable
class Denoiser(Protocol):
    """Runs a batch of denoising jobs; must be deterministic given the batch."""

    def denoise(self, batch: DenoiseBatch) -> DenoiseResult: ...


def concat_batches(batches: list[DenoiseBatch]) -> DenoiseBatch:
    """Stack batches with possibly different R by padding levels with their last row.

    A batch without a guidance mask joins masked ones with an all-ones mask, which the sampler
    treats bit for bit like no mask."""
    r = max(b.levels.shape[1] for b in batches)
    levels = [pad_levels(b.levels, r) for b in batches]
    return DenoiseBatch(
        np.concatenate([b.x for b in batches]),
        np.concatenate(levels),
        np.concatenate([b.scale for b in batches]),
        np.concatenate([b.start for b in batches]),
        np.concatenate([b.goal for b in batches]),
        None if all(b.noise_seed is None for b in batches) else np.concatenate(
            [np.zeros(b.size, np.int64) if b.noise_seed is None else b.noise_seed for b in batches]),
        None if all(b.guide_mask is None for b in batches) else np.concatenate(
            [np.ones(b.goal.shape, np.float32) if b.guide_mask is None else b.guide_mask for b in batches]),
    )


def micro_batch_indices(size: int, micro_batch: int) -> list[np.ndarray]:
    """Job indices of each micro-batch: cut in job order into exactly ``micro_batch`` jobs, the
    last one padded with copies of its last job. Every denoiser (local or Ray) cuts this way, so
    all model calls have the same shapes and a job's bits do not depend on who ran it (docs/design.md §7)."""
    out = []
    for lo in range(0, size, micro_batch):
        idx = np.arange(lo, min(lo + micro_batch, size))
        out.append(np.concatenate([idx, np.full(micro_batch - len(idx), idx[-1])]))
    return out


def pad_levels(levels: np.ndarray, rows: int) -> np.ndarray:
    """Pad [B, R+1, T] to [B, rows, T] by repeating the last row (no-op transitions)."""
    have = levels.shape[1]
    if have >= rows:
        return levels
    tail = np.repeat(levels[:, -1:], rows - have, axis=1)
    return np.concatenate([levels, tail], axis=1)
