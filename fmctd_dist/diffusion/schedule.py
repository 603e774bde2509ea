"""Noise schedules and the pyramid scheduling matrix (pure numpy, no torch).

MCTD turns Diffusion Forcing's semi-autoregressive "pyramid" schedule into a tree: tree
depth d owns rows [(d-1)*S, d*S] of the matrix (S = 20 DDIM transitions), and a
simulation finishes the plan by jumping every 10th remaining row. Everything the search
needs to know about noise levels lives here, so the search never touches the model.
"""

from __future__ import annotations

import math

import numpy as np


def linear_betas(timesteps: int = 1000, start: float = 1e-4, end: float = 0.02) -> np.ndarray:
    """[timesteps] float64 linear beta schedule (DDPM)."""
    return np.linspace(start, end, timesteps, dtype=np.float64)


def cosine_betas(timesteps: int = 100, s: float = 0.008, max_beta: float = 0.999) -> np.ndarray:
    """[timesteps] float64 cosine schedule (Nichol & Dhariwal 2021), as in Diffuser.

    alphabar(t) = f(t) / f(0), f(t) = cos(((t / T + s) / (1 + s)) * pi / 2)^2, and
    beta_t = 1 - alphabar(t) / alphabar(t - 1) for t = 1..T, clipped to ``max_beta``.
    """
    t = np.arange(timesteps + 1, dtype=np.float64) / timesteps
    f = np.cos((t + s) / (1 + s) * np.pi / 2) ** 2
    ab = f / f[0]
    return np.clip(1.0 - ab[1:] / ab[:-1], 0.0, max_beta)


BETA_SCHEDULES = ("linear", "cosine")


def make_betas(schedule: str, timesteps: int, start: float = 1e-4, end: float = 0.02) -> np.ndarray:
    """[timesteps] float64 betas of the named schedule; ``start``/``end`` only apply to linear."""
    if schedule == "linear":
        return linear_betas(timesteps, start, end)
    if schedule == "cosine":
        return cosine_betas(timesteps)
    raise ValueError(f"unknown beta schedule {schedule!r}; expected one of {BETA_SCHEDULES}")


def alphas_cumprod(betas: np.ndarray) -> np.ndarray:
    """[timesteps] float64 cumulative product of (1 - beta)."""
    return np.cumprod(1.0 - betas)


def level_timesteps(levels: int = 50, timesteps: int = 1000) -> np.ndarray:
    """[levels+1] int64: DDIM level k -> training timestep (level 0 -> -1 = clean).

    floor(linspace(-1, timesteps-1, levels+1)): for 50 levels over 1000 steps, 20k - 1.
    """
    return np.floor(np.linspace(-1, timesteps - 1, levels + 1)).astype(np.int64)


def pyramid(plan_tokens: int, levels: int = 50, context_tokens: int = 1) -> np.ndarray:
    """[levels + P, context + P] int64 pyramid scheduling matrix.

    Row m gives every token's level: context tokens 0 (clean), plan token t (0-based)
    clip(levels + t - m, 0, levels). Row 0 is all noise, the last row all clean; later
    tokens stay noisier for longer (semi-autoregressive).
    """
    m = np.arange(levels + plan_tokens)[:, None]
    t = np.arange(plan_tokens)[None, :]
    plan = np.clip(levels + t - m, 0, levels)
    ctx = np.zeros((plan.shape[0], context_tokens), dtype=np.int64)
    return np.concatenate([ctx, plan], axis=1).astype(np.int64)


def terminal_depth(n_rows: int, segment: int = 20) -> int:
    """Depth at which the plan is fully denoised: ceil((rows - 1) / segment)."""
    return math.ceil((n_rows - 1) / segment)


def expansion_rows(depth: int, n_rows: int, segment: int = 20) -> np.ndarray:
    """Row indices [segment + 1] run by expanding a node at ``depth`` (>= 1).

    Rows [(d-1)*segment, d*segment]; past the end of the matrix the last row repeats.
    """
    assert depth >= 1
    rows = np.arange((depth - 1) * segment, depth * segment + 1)
    return np.minimum(rows, n_rows - 1)


def simulation_rows(depth: int, n_rows: int, segment: int = 20, skip: int = 10) -> np.ndarray:
    """Row indices of the jumpy simulation from the end of a depth-``depth`` node.

    Rows d*segment, d*segment + skip, ... (below the last row) plus the last row. A plan
    already at the last row simulates with a single row (no transitions).
    """
    rows = list(range(depth * segment, n_rows - 1, skip))
    return np.asarray(rows + [n_rows - 1], dtype=np.int64)


class PyramidSchedule:
    """The pyramid matrix for P plan tokens plus the row sets a tree search needs."""

    def __init__(self, plan_tokens: int, levels: int = 50, segment: int = 20, skip: int = 10):
        self.plan_tokens = plan_tokens
        self.levels = levels
        self.segment = segment
        self.skip = skip
        self.matrix = pyramid(plan_tokens, levels)  # [n_rows, P+1]
        self.n_rows = self.matrix.shape[0]
        self.terminal_depth = terminal_depth(self.n_rows, segment)

    def expansion(self, depth: int) -> np.ndarray:
        """[segment+1, P+1] levels for expanding a node at ``depth``."""
        return self.matrix[expansion_rows(depth, self.n_rows, self.segment)]

    def simulation(self, depth: int) -> np.ndarray:
        """[R+1, P+1] levels for the jumpy simulation from a depth-``depth`` node."""
        return self.matrix[simulation_rows(depth, self.n_rows, self.segment, self.skip)]

    def full(self) -> np.ndarray:
        """[n_rows, P+1] the whole pyramid (Diffusion Forcing baseline)."""
        return self.matrix
