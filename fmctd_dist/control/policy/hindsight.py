"""Hindsight subgoals, for every family: pair a dataset row with a row k steps later in the same run.

``k`` is the sum of ``draws`` Geometric(p) draws (each >= 1; mean draws / p): 2 x Geometric(0.2)
gives a mean of 10 steps (the controllers' subgoal interval), mode 5-6, 90% within 2..19.
A row's *run* ends where its subgoals must stop (an episode's end; the ant: a fall; the cube:
the end of the current pick-and-place); ``end[i] >= i`` is the last row of i's run, and rows
with ``end[i] == i`` are never sampled (they have no future).
"""

from __future__ import annotations

import numpy as np


def sample_offsets(rng: np.random.Generator, n: int, p: float, draws: int) -> np.ndarray:
    """[n] int64 offsets k = sum of ``draws`` Geometric(p) draws (support >= draws, mean draws / p)."""
    return rng.geometric(p, size=(n, draws)).sum(axis=1).astype(np.int64)


def sample_pairs(valid: np.ndarray, end: np.ndarray, rng: np.random.Generator, n: int, p: float,
                 draws: int) -> tuple[np.ndarray, np.ndarray]:
    """n (row, subgoal row) index pairs: row uniform over ``valid`` [M], subgoal row min(row + k, end[row])."""
    i = valid[rng.integers(0, valid.size, n)]
    j = np.minimum(i + sample_offsets(rng, n, p, draws), end[i])
    return i, j


def label_run_ends(labels: np.ndarray) -> np.ndarray:
    """labels [E, S] -> [E*S] flat index of the last row of each row's run of equal labels (within its episode)."""
    e, s = labels.shape
    last = np.ones((e, s), dtype=bool)
    last[:, :-1] = labels[:, :-1] != labels[:, 1:]
    idx = np.arange(e * s, dtype=np.int64)
    cand = np.where(last.reshape(-1), idx, np.iinfo(np.int64).max)
    return np.minimum.accumulate(cand[::-1])[::-1]
