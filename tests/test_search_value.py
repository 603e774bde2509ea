"""Maze value on hand-made plans (exact): warp, reach time, dummy last frame, batching."""

import numpy as np
import pytest

from fmctd_dist.search.value import (
    ACHIEVED,
    NOT_REACHED,
    WARP,
    barely_moves,
    plan_values,
    truncate_at_goal,
)

START = np.array([0.0, 0.0])
GOAL = np.array([5.0, 0.0])


def line(*xs: float) -> np.ndarray:
    """[1, F, 2] plan along the x axis; the last frame is the dummy."""
    return np.array([[[x, 0.0] for x in xs]])


def score(plans, warp=1.5, radius=2.0):
    return plan_values(plans, START, GOAL, warp, radius)


def test_reach_at_t_gives_scanned_length_fraction():
    # F = 7 frames, F' = 6 scanned; |p_t - goal| < 2 first at t = 3 (x = 3.5).
    v, s, t = score(line(0.5, 1.5, 2.5, 3.5, 4.5, 5.0, 99.0))
    assert s[0] == ACHIEVED and t[0] == 3
    assert v[0] == pytest.approx((6 - 3) / 6)


def test_warp_before_goal_is_zero():
    v, s, t = score(line(0.5, 2.5, 3.5, 4.5, 5.0, 5.0))  # 0.5 -> 2.5 is a 2.0 jump > 1.5
    assert (v[0], s[0], t[0]) == (0.0, WARP, -1)


def test_first_step_is_measured_from_start():
    v, s, _ = score(line(1.6, 2.0, 3.0, 4.0, 5.0, 5.0))  # |p_0 - start| = 1.6
    assert s[0] == WARP and v[0] == 0.0


def test_never_reaching_is_zero():
    v, s, t = score(line(0.5, 1.0, 1.5, 2.0, 2.5, 2.5))
    assert (v[0], s[0], t[0]) == (0.0, NOT_REACHED, -1)


def test_warp_after_reaching_does_not_matter():
    v, s, t = score(line(1.0, 2.0, 3.5, 4.0, 40.0, -40.0, 0.0))
    assert s[0] == ACHIEVED and t[0] == 2  # x = 3.5 is within 2 of 5
    assert v[0] == pytest.approx((6 - 2) / 6)


def test_warp_at_the_reach_frame_is_a_warp():
    v, s, _ = score(line(0.5, 1.0, 4.0, 5.0, 5.0))  # 1.0 -> 4.0 jumps 3.0 into the goal radius
    assert s[0] == WARP and v[0] == 0.0


def test_reaching_only_in_the_dummy_frame_is_not_reached():
    v, s, _ = score(line(0.5, 1.0, 1.5, 2.0, 3.5))  # only the dropped last frame is near
    assert s[0] == NOT_REACHED and v[0] == 0.0


def test_radius_is_strict():
    _, s, _ = score(line(1.0, 2.0, 3.0, 3.0))  # |3 - 5| = 2.0 is not < 2.0
    assert s[0] == NOT_REACHED


def test_batch_equals_one_by_one():
    plans = np.concatenate([
        line(0.5, 1.5, 2.5, 3.5, 4.5, 5.0, 99.0),
        line(0.5, 2.5, 3.5, 4.5, 5.0, 5.0, 5.0),
        line(0.5, 1.0, 1.5, 2.0, 2.5, 2.5, 2.5),
        line(1.0, 2.0, 3.5, 4.0, 40.0, -40.0, 0.0),
    ])
    v, s, t = score(plans)
    for b in range(plans.shape[0]):
        vb, sb, tb = score(plans[b:b + 1])
        assert (v[b], s[b], t[b]) == (vb[0], sb[0], tb[0])
    assert v.shape == s.shape == t.shape == (4,)
    assert s.tolist() == [ACHIEVED, WARP, NOT_REACHED, ACHIEVED]


def test_barely_moves():
    still = np.zeros((1, 5, 2))
    creep = np.cumsum(np.full((1, 5, 2), 0.05), axis=1)  # steps of 0.0707
    step = line(0.0, 0.0, 0.1, 0.1)  # one step of exactly 0.1 is not "barely"
    assert barely_moves(np.concatenate([still, creep]), 0.1).tolist() == [True, True]
    assert barely_moves(step, 0.1).tolist() == [False]


def test_truncate_at_goal_appends_goal():
    plan = line(0.5, 1.5, 2.5, 3.5, 4.5)[0]
    out = truncate_at_goal(plan, 3, GOAL)
    assert out.dtype == np.float32 and out.shape == (5, 2)
    np.testing.assert_array_equal(out[:4], plan[:4])
    np.testing.assert_array_equal(out[-1], GOAL)


def test_blocked_steps_count_as_warps_before_the_reach_only():
    plans = line(0.5, 1.5, 2.5, 3.5, 4.5, 5.0, 99.0)  # reaches at t = 3
    blocked = np.zeros((1, 6), bool)
    blocked[0, 1] = True  # a wall between 0.5 and 1.5
    assert score(plans)[1][0] == ACHIEVED
    v, s, t = plan_values(plans, START, GOAL, 1.5, 2.0, blocked)
    assert (v[0], s[0], t[0]) == (0.0, WARP, -1)
    blocked[:] = False
    blocked[0, 4] = True  # after the reach: does not matter, as for a warp
    assert plan_values(plans, START, GOAL, 1.5, 2.0, blocked)[1][0] == ACHIEVED
