"""AntMaze subgoal schedule (docs/reference.md §7): 10 plan points ahead, advanced within 1.0, held at the end."""

import numpy as np
import pytest

from fmctd_dist.families.maze.subgoal import SubgoalTracker


def straight_plan(n=45, step=0.2):
    return np.stack([np.arange(n) * step, np.zeros(n)], axis=1)


def test_first_subgoal_is_interval_ahead_and_held_until_reached():
    tr = SubgoalTracker(straight_plan(), interval=10, radius=1.0)
    assert tr.index == 10
    # far from point 10 (x=2.0): the subgoal does not move however often we ask
    for _ in range(5):
        np.testing.assert_array_equal(tr.update(np.array([0.0, 0.0])), [2.0, 0.0])
    tr.update(np.array([1.05, 0.0]))  # 0.95 from x=2.0: within 1.0 -> advance to point 20
    assert tr.index == 20


def test_fake_agent_walks_the_subgoals_in_order_and_stops_at_the_last_point():
    plan = straight_plan()
    tr = SubgoalTracker(plan, interval=10, radius=1.0)
    pos, seen = np.zeros(2), []
    for _ in range(200):  # a fake env: the agent moves 0.1 toward its subgoal per step
        goal = tr.update(pos)
        if not seen or seen[-1] != tr.index:
            seen.append(tr.index)
        d = goal - pos
        pos = pos + d / max(np.linalg.norm(d), 1e-9) * min(0.1, np.linalg.norm(d))
    assert seen == [10, 20, 30, 40, 44]  # the last subgoal is the last plan point, not past it
    assert tr.done and np.linalg.norm(pos - plan[-1]) < 1e-9


def test_one_advance_per_step_while_the_subgoal_stays_within_reach():
    tr = SubgoalTracker(straight_plan(n=100, step=0.05), interval=10, radius=1.0)
    pos = np.array([0.6, 0.0])  # points 10 (0.5), 20 (1.0), 30 (1.5) are within 1.0 of it, 40 (2.0) is not
    assert [int(tr.update(pos)[0] / 0.05 + 0.5) for _ in range(5)] == [20, 30, 40, 40, 40]


def test_short_plan_and_bad_input():
    assert SubgoalTracker(straight_plan(n=4)).index == 3
    with pytest.raises(ValueError, match=r"\[F, 2\]"):
        SubgoalTracker(np.zeros((5, 3)))
    with pytest.raises(ValueError, match="interval"):
        SubgoalTracker(straight_plan(), interval=0)
