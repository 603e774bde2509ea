"""Deterministic stand-ins for the diffusion model, shared by search/planner tests.

``FakeDenoiser`` implements the Denoiser protocol in pure numpy. For every transition it
moves the tokens whose level drops towards a target plan by the fraction of noise removed
(level 0 -> exactly the target), so a pyramid schedule behaves like the real sampler:
early tokens clean first, a finished schedule yields the target. The target is a straight
line from start towards goal whose speed grows with the guidance scale and is perturbed
by a hash of the job's input tokens, so different scales and different parents give
different plans: scale 2 usually reaches the goal, scale <= 0.5 never does. A job with a
guidance mask (object-wise guidance) moves its masked dims at that speed and the others at
``drift`` times it, like a model whose guidance pulls one object while the rest wander.
"""

from __future__ import annotations

import json
import os
import zlib
from pathlib import Path

import numpy as np

from fmctd_dist.tokens import Normaliser, PlanCodec
from fmctd_dist.denoiser.protocol import DenoiseBatch, DenoiseResult
from fmctd_dist.diffusion.schedule import PyramidSchedule

GOLDEN_DIR = Path(__file__).parent / "golden"
REGEN_ENV = "FMCTD_REGEN_GOLDEN"

START = np.array([0.0, 0.0])  # world units; 28.3 from the goal
GOAL = np.array([20.0, 20.0])


def job_hash(x: np.ndarray) -> np.ndarray:
    """[B, T, D] -> [B] float64 in [0, 1): CRC32 of each job's plan tokens (context excluded).

    Bytes-exact (no transcendental functions, no BLAS), so golden trees do not depend on
    the CPU or the numpy build.
    """
    plan = np.ascontiguousarray(np.asarray(x, np.float32)[:, 1:])
    return np.array([zlib.crc32(row.tobytes()) / 2.0**32 for row in plan], np.float64)


class FakeDenoiser:
    """Pure-numpy Denoiser that records every batch it gets.

    speed = 0.55 + 0.3 * scale + 0.4 * (hash - 0.5) (fraction of the start->goal line
    covered by the last frame); with probability ``stuck_prob`` (from a second hash) the
    plan stays at the start (speed 0), which ``barely_moves`` flags as a bad plan.
    """

    def __init__(self, pos_dim: int = 2, stuck_prob: float = 0.0, time_per_job_s: float = 1e-3, drift: float = 0.5):
        self.pos_dim = pos_dim
        self.drift = drift
        self.stuck_prob = stuck_prob
        self.time_per_job_s = time_per_job_s
        self.batches: list[DenoiseBatch] = []

    @property
    def calls(self) -> int:
        return len(self.batches)

    @property
    def jobs(self) -> int:
        return sum(b.size for b in self.batches)

    def target(self, batch: DenoiseBatch) -> np.ndarray:
        """[B, T, D] float64 fully denoised tokens for each job (token 0 = the input context)."""
        b, t, dd = batch.x.shape
        fs = dd // self.pos_dim
        frames = (t - 1) * fs
        h = job_hash(batch.x)  # [B]
        stuck = (h * 7919.0) % 1.0 < self.stuck_prob  # [B]
        speed = 0.55 + 0.3 * batch.scale.astype(np.float64) + 0.4 * (h - 0.5)  # [B]
        speed = np.where(stuck, 0.0, speed)
        u = np.arange(1, frames + 1, dtype=np.float64) / frames  # [F]
        frac = np.minimum(1.0, u[None, :] * speed[:, None])  # [B, F]
        start = batch.start.astype(np.float64)[:, None, :]  # [B, 1, d]
        goal = batch.goal.astype(np.float64)[:, None, :]
        per_dim = frac[..., None]  # [B, F, 1]
        if batch.guide_mask is not None:
            per_dim = per_dim * np.where(batch.guide_mask > 0, 1.0, self.drift)[:, None, :]  # [B, F, d]
        pos = start + (goal - start) * per_dim  # [B, F, d]
        tokens = pos.reshape(b, t - 1, dd)
        return np.concatenate([np.asarray(batch.x[:, :1], np.float64), tokens], axis=1)

    def denoise(self, batch: DenoiseBatch) -> DenoiseResult:
        # Copies: the caller may reuse its arrays after the call returns.
        arrays = (batch.x, batch.levels, batch.scale, batch.start, batch.goal)
        mask = None if batch.guide_mask is None else np.array(batch.guide_mask, copy=True)
        batch = DenoiseBatch(*(np.array(a, copy=True) for a in arrays), guide_mask=mask)
        self.batches.append(batch)
        target = self.target(batch)
        x = np.asarray(batch.x, np.float64).copy()
        lv = batch.levels.astype(np.float64)  # [B, R+1, T]
        for r in range(lv.shape[1] - 1):
            old, new = lv[:, r], lv[:, r + 1]  # [B, T]
            move = new < old
            keep = np.where(move, new / np.maximum(old, 1.0), 1.0)[..., None]  # remaining noise fraction
            x = target + (x - target) * keep
        return DenoiseResult(
            x=x.astype(np.float32),
            x0=target.astype(np.float32),
            denoise_time_s=self.time_per_job_s * batch.size,
        )


def make_codec(frame_stack: int = 10) -> PlanCodec:
    """Codec with a non-trivial normaliser (mean 10, std 5 per axis) so units matter."""
    return PlanCodec(Normaliser.from_lists([10.0, 10.0], [5.0, 5.0]), frame_stack)


def make_schedule(plan_tokens: int = 10) -> PyramidSchedule:
    """10 plan tokens, 50 levels, segments of 20: 60 rows, terminal depth 3 (like Fast-MCTD medium)."""
    return PyramidSchedule(plan_tokens)


def assert_golden(name: str, data: dict) -> None:
    """Compare ``data`` with tests/golden/<name>.json; FMCTD_REGEN_GOLDEN=1 rewrites it instead."""
    path = GOLDEN_DIR / f"{name}.json"
    text = json.dumps(data, indent=1, sort_keys=True) + "\n"
    if os.environ.get(REGEN_ENV) == "1":
        GOLDEN_DIR.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
        return
    assert path.is_file(), f"missing golden file {path}; regenerate with {REGEN_ENV}=1"
    want = json.loads(path.read_text())
    got = json.loads(text)
    for key in sorted(set(want) | set(got)):
        assert got.get(key) == want.get(key), (
            f"golden {name}: field {key!r} differs\n got {got.get(key)}\nwant {want.get(key)}"
        )
