"""The one search loop with object-wise actions and the cube value (issue 20): golden trees for
2 cubes (K = 1 and K = 4 with redundancy-aware claims), the guidance masks the denoiser gets,
pinning before the bad-plan test, and the early stop of replanning mode.

A deterministic fake denoiser as for the maze trees (tests/fakes.py): a job's masked cube moves
along the start->goal line at a speed set by its scale, the other cube drifts at half speed
(and is pinned back by the value rule). Cube 1's goal is where cube 0 starts, so guiding cube 1
first can never place it (its goal stays occupied): the tree has to find cube 0 first.

Regenerate the golden trees with ``FMCTD_REGEN_GOLDEN=1 python -m pytest tests/test_search_cube.py``.
"""

import numpy as np
import pytest

from fakes import FakeDenoiser, assert_golden, make_schedule
from fmctd_dist.tokens import Normaliser, PlanCodec
from fmctd_dist.search.actions import object_actions
from fmctd_dist.families.cube.value import PARTIAL, CubeValue
from fmctd_dist.search.loop import EARLY_STOP, STATUS_ACHIEVED, SearchParams, search
from fmctd_dist.search.value import ACHIEVED, NOT_REACHED

SEED = 11
Z = 0.2
START = np.array([0.0, 0.0, Z, 0.0, 3.0, Z])  # cube 0, cube 1 (obs units)
GOAL = np.array([4.0, 0.0, Z, 0.0, 0.0, Z])  # cube 1's goal is cube 0's start
SCALES = (1.0, 2.0, 4.0)  # per unsolved cube (configs/env/cube-*.yaml env.object_scales)
FRAME_STACK = 2  # 10 plan tokens x 2 = 20 frames, 19 scored


def codec() -> PlanCodec:
    return PlanCodec(Normaliser.from_lists([2.0, 1.0, 0.3] * 2, [2.0, 1.5, 0.2] * 2), FRAME_STACK)


def run(denoiser=None, seed=SEED, rule=None, **overrides):
    params = SearchParams(**{"early_stop": False, "warp_threshold": 1.0, **overrides})
    rule = rule or CubeValue(warp_threshold=1.0, replanning=True)
    acts = object_actions(rule.unsolved(START, GOAL), 2, 3, SCALES)
    fd = denoiser or FakeDenoiser(pos_dim=6)
    res = search(fd, make_schedule(), codec(), START, GOAL, params, seed, actions=acts, value=rule)
    return res, fd, acts


# ---------------------------------------------------------------- golden trees

def test_golden_object_tree_sequential_k1():
    res, _, acts = run(parallel=1, budget=15)
    tree = res.tree
    assert acts.size == tree.num_actions == 6  # 2 unsolved cubes x scales {1, 2, 4}
    assert res.iterations == 15 and tree.num_nodes == 16 and tree.depth[: tree.num_nodes].max() >= 2
    assert_golden("search_cube_k1", tree.to_json())


def test_golden_object_tree_parallel_k4_ras():
    res, _, _ = run(parallel=4, budget=64)
    tree = res.tree
    n = tree.num_nodes
    assert tree.depth[:n].max() == tree.terminal_depth == 3
    assert n - 1 == res.expansions  # redundancy-aware: one node per job
    assert_golden("search_cube_k4_ras", tree.to_json())


def test_the_tree_learns_which_cube_to_move():
    res, _, acts = run(parallel=4, budget=32)
    tree = res.tree
    n = tree.num_nodes
    obj = acts.obj[tree.slot[1:n]]
    placed = tree.status[1:n] == ACHIEVED
    assert placed.any() and (obj[placed] == 0).all()  # cube 1's goal stays occupied by the pinned cube 0
    assert tree.value[0] == pytest.approx(0.1)  # one newly placed cube of two
    assert res.status == STATUS_ACHIEVED and res.value == pytest.approx(0.1)


# ---------------------------------------------------------------- what the denoiser gets

def test_batches_carry_the_action_scale_and_mask():
    res, fd, acts = run(parallel=4, budget=24)
    tree = res.tree
    for i in range(res.iterations):
        ex, sim = fd.batches[2 * i], fd.batches[2 * i + 1]
        nodes = np.flatnonzero(tree.born[: tree.num_nodes] == i)
        for batch in (ex, sim):
            np.testing.assert_array_equal(batch.scale, acts.scale[tree.slot[nodes]])
            np.testing.assert_array_equal(batch.guide_mask, acts.mask[tree.slot[nodes]])


def test_tree_plans_move_only_the_guided_cube():
    res, _, acts = run(parallel=4, budget=24)
    tree = res.tree
    for node in range(1, tree.num_nodes):
        still = acts.mask[tree.slot[node]] == 0
        np.testing.assert_array_equal(tree.sim_plan[node][:, still],
                                      np.broadcast_to(START[still].astype(np.float32), (20, 3)))


# ---------------------------------------------------------------- bad plans, early stop, partial credit

class GuidedCubeFrozen(FakeDenoiser):
    """The guided cube never leaves its start; only the un-guided one drifts."""

    def target(self, batch):
        out = super().target(batch)
        b, t, dd = out.shape
        frames = out[:, 1:].reshape(b, -1, 6)
        keep = batch.guide_mask[:, None, :] > 0
        frames[:] = np.where(keep, batch.start.astype(np.float64)[:, None, :], frames)
        out[:, 1:] = frames.reshape(b, t - 1, dd)
        return out


def test_bad_plan_resampling_sees_the_pinned_plan():
    """Raw plans move (the un-guided cube drifts), pinned ones do not: every depth-1 job is resampled."""
    fd = GuidedCubeFrozen(pos_dim=6)
    res, _, _ = run(fd, parallel=6, budget=6, bad_plan_tries=3)
    assert res.resampled == 6 * 3 and res.denoise_calls == 2 * (1 + 3)
    assert (res.tree.attempts[1:7] == 3).all()
    assert (res.tree.status[1:7] == NOT_REACHED).all()


def test_early_stop_returns_the_plan_cut_at_the_newly_placed_cube():
    rule = CubeValue(warp_threshold=1.0, replanning=True)
    res, _, acts = run(parallel=6, budget=200, early_stop=True, rule=rule)
    assert res.status == EARLY_STOP == res.stop_reason
    tree = res.tree
    new = np.flatnonzero(tree.born[: tree.num_nodes] == res.iterations - 1)  # the last iteration's nodes
    own = rule.prepare(codec().decode(tree.x[new]), START, acts.take(tree.slot[new]))
    v, s, t = rule.values(own, START, GOAL, acts.take(tree.slot[new]))
    i = int(np.argmax(np.where(s == ACHIEVED, v, -1)))
    assert res.value == v[i] and len(res.plan) == t[i] + 1
    np.testing.assert_array_equal(res.plan, own[i, : t[i] + 1])
    assert np.linalg.norm(res.plan[-1, :3] - GOAL[:3]) < rule.goal_tol  # cube 0 on its goal ...
    np.testing.assert_array_equal(res.plan[:, 3:], np.broadcast_to(START[3:].astype(np.float32), (len(res.plan), 3)))


def test_without_replanning_the_best_partial_plan_comes_back():
    res, _, _ = run(parallel=4, budget=32, rule=CubeValue(warp_threshold=1.0, replanning=False))
    n = res.tree.num_nodes
    assert (res.tree.status[1:n] == PARTIAL).any() and not (res.tree.status[1:n] == ACHIEVED).any()
    assert res.status == "partial" and res.value == pytest.approx(0.1)
    assert len(res.plan) == 19  # the whole plan but the dummy frame


def test_cube_search_is_deterministic_and_seeded():
    a, _, _ = run(parallel=4, budget=32)
    b, _, _ = run(parallel=4, budget=32)
    assert a.tree.to_json() == b.tree.to_json()
    np.testing.assert_array_equal(a.plan, b.plan)
    np.testing.assert_array_equal(a.tree.x, b.tree.x)
    c, _, _ = run(parallel=4, budget=32, seed=SEED + 1)
    assert c.tree.to_json() != a.tree.to_json()


def test_masks_must_match_the_state():
    with pytest.raises(ValueError, match="state dims"):
        search(FakeDenoiser(pos_dim=6), make_schedule(), codec(), START, GOAL, SearchParams(budget=4), 0,
               actions=object_actions([0], 3, 3, SCALES))
