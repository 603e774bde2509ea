"""Frames <-> tokens <-> normalised space (pure numpy).

A token is ``frame_stack`` consecutive (x, y) frames flattened to 2*frame_stack numbers;
token 0 is the start frame repeated (the clean context). The model, the sampler and the
guidance all work in normalised space; values and controllers in world units.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Normaliser:
    """Per-dimension z-score: (x - mean) / std. mean, std: [d]."""

    mean: np.ndarray
    std: np.ndarray

    @classmethod
    def from_lists(cls, mean: list[float], std: list[float]) -> "Normaliser":
        return cls(np.asarray(mean, dtype=np.float64), np.asarray(std, dtype=np.float64))

    def normalise(self, x: np.ndarray) -> np.ndarray:
        return ((x - self.mean) / self.std).astype(np.float32)

    def unnormalise(self, x: np.ndarray) -> np.ndarray:
        return (np.asarray(x, dtype=np.float64) * self.std + self.mean).astype(np.float32)


def frames_to_tokens(frames: np.ndarray, frame_stack: int) -> np.ndarray:
    """[..., F, d] -> [..., F / frame_stack, d * frame_stack]."""
    *lead, f, d = frames.shape
    assert f % frame_stack == 0, f"{f} frames do not split into tokens of {frame_stack}"
    return frames.reshape(*lead, f // frame_stack, frame_stack * d)


def tokens_to_frames(tokens: np.ndarray, frame_stack: int) -> np.ndarray:
    """[..., P, d * frame_stack] -> [..., P * frame_stack, d]."""
    *lead, p, dd = tokens.shape
    return tokens.reshape(*lead, p * frame_stack, dd // frame_stack)


def context_token(start: np.ndarray, frame_stack: int) -> np.ndarray:
    """[..., d] -> [..., 1, d * frame_stack]: the start frame repeated (padding mode 'same')."""
    return np.tile(start[..., None, :], (1,) * (start.ndim - 1) + (1, frame_stack))


@dataclass(frozen=True)
class PlanCodec:
    """Turns model tokens into world-unit plans and back; what the search uses to score plans."""

    normaliser: Normaliser
    frame_stack: int

    def decode(self, x: np.ndarray) -> np.ndarray:
        """[B, T, D] normalised tokens (token 0 = context) -> [B, (T-1)*frame_stack, d] world positions."""
        return self.normaliser.unnormalise(tokens_to_frames(x[:, 1:], self.frame_stack))

    def encode_frames(self, frames: np.ndarray) -> np.ndarray:
        """[B, F, d] world frames -> [B, F / frame_stack, D] normalised tokens."""
        return frames_to_tokens(self.normaliser.normalise(frames), self.frame_stack)

    def context(self, start_world: np.ndarray) -> np.ndarray:
        """[B, d] world start -> [B, 1, D] normalised context token."""
        return context_token(self.normaliser.normalise(start_world), self.frame_stack)
