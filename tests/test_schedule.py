"""Exact values of the pyramid schedule and the row sets the tree search runs (docs/reference.md §5-6)."""

from __future__ import annotations

import numpy as np
import pytest

from fmctd_dist.diffusion.schedule import (
    PyramidSchedule, alphas_cumprod, expansion_rows, level_timesteps, linear_betas, pyramid, simulation_rows,
    terminal_depth,
)


def test_level_timesteps_are_20k_minus_1():
    lt = level_timesteps(50, 1000)
    assert lt.dtype == np.int64 and lt.shape == (51,)
    np.testing.assert_array_equal(lt, 20 * np.arange(51) - 1)
    assert lt[0] == -1 and lt[1] == 19 and lt[50] == 999


def test_linear_betas_and_alphas_cumprod():
    betas = linear_betas(1000, 1e-4, 0.02)
    assert betas[0] == pytest.approx(1e-4) and betas[-1] == pytest.approx(0.02)
    ab = alphas_cumprod(betas)
    assert ab[0] == pytest.approx(1 - 1e-4)
    assert np.all(np.diff(ab) < 0) and 0 < ab[-1] < 1e-4


def test_pyramid_p10():
    m = pyramid(10)
    assert m.shape == (60, 11)
    np.testing.assert_array_equal(m[0], [0] + [50] * 10)
    np.testing.assert_array_equal(m[5], [0, 45, 46, 47, 48, 49, 50, 50, 50, 50, 50])
    np.testing.assert_array_equal(m[50], [0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9])
    np.testing.assert_array_equal(m[59], [0] * 11)
    assert (m[:, 0] == 0).all()
    assert (np.diff(m, axis=0) <= 0).all()  # levels never go up


def test_pyramid_p50():
    m = pyramid(50)
    assert m.shape == (100, 51)
    np.testing.assert_array_equal(m[20], [0] + list(range(30, 50)) + [50] * 30)
    np.testing.assert_array_equal(m[50], [0] + list(range(50)))
    np.testing.assert_array_equal(m[99], [0] * 51)
    t = np.arange(50)
    for row in (0, 37, 73, 98):
        np.testing.assert_array_equal(m[row, 1:], np.clip(50 + t - row, 0, 50))


@pytest.mark.parametrize("p, rows, depth", [(50, 100, 5), (100, 150, 8), (10, 60, 3), (20, 70, 4)])
def test_rows_and_terminal_depth(p, rows, depth):
    s = PyramidSchedule(p)
    assert s.n_rows == rows
    assert s.terminal_depth == depth == terminal_depth(rows)


@pytest.mark.parametrize("p, counts", [
    (50, [9, 7, 5, 3, 1]),
    (100, [14, 12, 10, 8, 6, 4, 2, 1]),
    (10, [5, 3, 1]),
    (20, [6, 4, 2, 1]),
])
def test_jumpy_simulation_rows_per_depth(p, counts):
    s = PyramidSchedule(p)
    got = [len(simulation_rows(d, s.n_rows)) for d in range(1, s.terminal_depth + 1)]
    assert got == counts
    for d in range(1, s.terminal_depth + 1):
        rows = simulation_rows(d, s.n_rows)
        assert rows[-1] == s.n_rows - 1 and rows[0] == min(d * 20, s.n_rows - 1)
        assert s.simulation(d).shape == (len(rows), p + 1)


def test_simulation_rows_p50_depth1():
    np.testing.assert_array_equal(simulation_rows(1, 100), [20, 30, 40, 50, 60, 70, 80, 90, 99])


def test_expansion_rows_per_depth():
    np.testing.assert_array_equal(expansion_rows(1, 100), np.arange(0, 21))
    np.testing.assert_array_equal(expansion_rows(3, 100), np.arange(40, 61))
    np.testing.assert_array_equal(expansion_rows(5, 100), list(range(80, 100)) + [99])  # last row repeats
    np.testing.assert_array_equal(expansion_rows(3, 60), list(range(40, 60)) + [59])
    s = PyramidSchedule(10)
    for d in range(1, s.terminal_depth + 1):
        seg = s.expansion(d)
        assert seg.shape == (21, 11)
        if d > 1:  # segments chain: a child starts where its parent ended
            np.testing.assert_array_equal(seg[0], s.expansion(d - 1)[-1])
    np.testing.assert_array_equal(s.expansion(s.terminal_depth)[-1], np.zeros(11))
