"""The search loop with a deterministic fake denoiser: golden trees, budget, early stop,
bad-plan resampling, batching contract and determinism.

Regenerate the golden trees with ``FMCTD_REGEN_GOLDEN=1 python -m pytest tests/test_search_loop.py``.
"""

import dataclasses
import subprocess
import sys

import numpy as np
import pytest

from fakes import GOAL, START, FakeDenoiser, assert_golden, make_codec, make_schedule
from fmctd_dist.config import MethodConfig
from fmctd_dist.search.loop import (
    EARLY_STOP,
    STATUS_ACHIEVED,
    STATUS_STAY,
    SearchParams,
    initial_noise,
    search,
)
from fmctd_dist.search.tree import ROOT
from fmctd_dist.search.value import ACHIEVED, plan_values

SEED = 7


def run(denoiser=None, seed=SEED, **overrides):
    params = SearchParams(**{"early_stop": False, **overrides})
    fd = denoiser or FakeDenoiser()
    return search(fd, make_schedule(), make_codec(), START, GOAL, params, seed), fd


def parents_per_iteration(tree):
    n = tree.num_nodes
    return [sorted(set(tree.parent[1:n][tree.born[1:n] == i].tolist())) for i in range(tree.born[:n].max() + 1)]


# ---------------------------------------------------------------- golden trees

def test_golden_tree_sequential_k1():
    res, _ = run(parallel=1, budget=15)
    assert res.iterations == 15 and res.tree.num_nodes == 16
    assert res.tree.depth[: res.tree.num_nodes].max() >= 2
    assert_golden("search_k1", res.tree.to_json())


def test_golden_tree_parallel_k4_ras():
    res, _ = run(parallel=4, budget=32)
    tree = res.tree
    assert tree.depth[: tree.num_nodes].max() == tree.terminal_depth == 3
    assert tree.num_nodes - 1 == res.expansions  # redundancy-aware: one node per job
    assert_golden("search_k4_ras", tree.to_json())


def test_without_redundancy_awareness_jobs_duplicate():
    ras, _ = run(parallel=4, budget=32)
    dup, _ = run(parallel=4, budget=32, redundancy_aware=False)
    assert dup.tree.to_json() != ras.tree.to_json()
    assert dup.expansions >= 32 and dup.tree.num_nodes - 1 < dup.expansions
    assert any(s.new_nodes < s.jobs for s in dup.stats)
    assert all(s.new_nodes == s.jobs for s in ras.stats)


def test_zero_virtual_weight_follows_one_path_per_batch():
    w1, _ = run(parallel=4, budget=32)
    w0, _ = run(parallel=4, budget=32, virtual_weight=0.0)
    assert all(len(p) == 1 for p in parents_per_iteration(w0.tree))  # every batch under one parent
    assert any(len(p) > 1 for p in parents_per_iteration(w1.tree))
    assert sum(s.wasted for s in w0.stats) > sum(s.wasted for s in w1.stats)
    nodes_per_iter = lambda r: (r.tree.num_nodes - 1) / r.iterations  # noqa: E731
    assert nodes_per_iter(w0) < nodes_per_iter(w1)


# ---------------------------------------------------------------- budget and batching

@pytest.mark.parametrize("k,budget", [(1, 6), (4, 10), (200, 30)])
def test_budget_counts_expansion_jobs(k, budget):
    res, fd = run(parallel=k, budget=budget)
    before = np.cumsum([0] + [s.jobs for s in res.stats])[:-1]
    assert np.all(before < budget)  # no iteration starts at or over the budget
    assert res.expansions == sum(s.jobs for s in res.stats) >= budget
    assert res.expansions == sum(b.size for b in fd.batches[0::2])
    assert res.stop_reason == "budget"


def test_one_expansion_and_one_simulation_call_per_iteration():
    res, fd = run(parallel=4, budget=24)
    schedule = make_schedule()
    assert res.denoise_calls == fd.calls == 2 * res.iterations
    assert res.denoise_time_s == pytest.approx(1e-3 * fd.jobs)
    tree = res.tree
    for i in range(res.iterations):
        ex, sim = fd.batches[2 * i], fd.batches[2 * i + 1]
        nodes = np.flatnonzero(tree.born[: tree.num_nodes] == i)  # ascending = job order (RAS on)
        depth = tree.depth[nodes]
        assert ex.size == sim.size == nodes.size
        for j, d in enumerate(depth):
            np.testing.assert_array_equal(ex.levels[j], schedule.expansion(int(d)))
            sim_rows = schedule.simulation(int(d))
            np.testing.assert_array_equal(sim.levels[j, : len(sim_rows)], sim_rows)
            assert (sim.levels[j, len(sim_rows):] == sim_rows[-1]).all()  # padded with no-op rows
        scales = np.asarray(SearchParams().guidance_scales, np.float32)
        np.testing.assert_array_equal(ex.scale, scales[tree.slot[nodes]])
        np.testing.assert_array_equal(sim.x, tree.x[nodes])  # simulation starts from the expansion result


def test_depth1_jobs_start_from_context_plus_seeded_noise():
    res, fd = run(parallel=5, budget=5)
    codec, ex = make_codec(), fd.batches[0]
    ctx = codec.context(START[None])[0]
    for j, node in enumerate(range(1, 6)):
        np.testing.assert_array_equal(ex.x[j, :1], ctx)
        np.testing.assert_array_equal(ex.x[j, 1:], initial_noise(SEED, node, 0, 0, (10, 20), 20.0))
    np.testing.assert_allclose(ex.start, np.repeat(codec.normaliser.normalise(START)[None], 5, 0))
    np.testing.assert_allclose(ex.goal[0], [2.0, 2.0])


def test_deeper_jobs_start_from_parent_payload():
    res, fd = run(parallel=4, budget=24)
    tree = res.tree
    ex = fd.batches[4]  # iteration 2: children of depth-1 nodes
    nodes = np.flatnonzero(tree.born[: tree.num_nodes] == 2)
    np.testing.assert_array_equal(ex.x, tree.x[tree.parent[nodes]])


# ---------------------------------------------------------------- early stop and fallbacks

def test_early_stop_on_first_iteration_whose_new_node_reaches():
    full, _ = run(parallel=4, budget=200)
    codec, tree = make_codec(), full.tree
    n = tree.num_nodes
    own = codec.decode(tree.x[1:n])
    _, st, _ = plan_values(own, START, GOAL, 2.0, 2.0)
    first = int(tree.born[1:n][st == ACHIEVED].min())
    res, _ = run(parallel=4, budget=200, early_stop=True)
    assert res.status == EARLY_STOP == res.stop_reason
    assert res.iterations == first + 1
    assert res.tree.num_nodes == int((tree.born[1:n] <= first).sum()) + 1
    np.testing.assert_array_equal(res.plan[-1], GOAL.astype(np.float32))
    new = np.flatnonzero(res.tree.born[: res.tree.num_nodes] == first)
    v, s, t = plan_values(codec.decode(res.tree.x[new]), START, GOAL, 2.0, 2.0)
    i = int(np.argmax(np.where(s == ACHIEVED, v, -1)))
    assert res.value == v[i] and len(res.plan) == t[i] + 2


def test_budget_fallback_is_best_achieved_simulation():
    res, _ = run(parallel=4, budget=32)
    tree = res.tree
    n = tree.num_nodes
    v, _, _ = plan_values(tree.sim_plan[1:n], START, GOAL, 2.0, 2.0)
    assert res.status == STATUS_ACHIEVED
    assert res.value == v.max() >= tree.value[ROOT]  # a parent's value is its children's max, not its own
    np.testing.assert_array_equal(res.plan[-1], GOAL.astype(np.float32))


def test_stay_plan_when_every_plan_warps():
    res, _ = run(parallel=5, budget=5, warp_threshold=0.01)
    assert res.status == STATUS_STAY
    np.testing.assert_array_equal(res.plan, np.repeat(START[None], 99, 0).astype(np.float32))


def test_time_limit_with_a_fake_clock():
    ticks = iter(range(10_000))
    params = SearchParams(parallel=1, budget=100, early_stop=False, time_limit_s=10.0)
    res = search(FakeDenoiser(), make_schedule(), make_codec(), START, GOAL, params, SEED,
                 clock=lambda: float(next(ticks)))
    assert res.timed_out and res.stop_reason == "time"
    assert 0 < res.iterations < 10 and res.expansions < 100


# ---------------------------------------------------------------- bad plans and determinism

def test_bad_plans_are_resampled_alone_with_new_seeds():
    fd = FakeDenoiser(stuck_prob=0.35)
    res, _ = run(fd, parallel=5, budget=5, bad_plan_tries=3)
    ex0, sim0, ex1 = fd.batches[0], fd.batches[1], fd.batches[2]
    stuck = fd.target(sim0)[:, 1:].std(axis=(1, 2)) == 0  # plans that never left the start
    assert 0 < stuck.sum() < 5
    assert ex1.size == stuck.sum() and fd.batches[3].size == stuck.sum()
    nodes = np.arange(1, 6)[stuck]
    for j, node in enumerate(nodes):
        np.testing.assert_array_equal(ex1.x[j, 1:], initial_noise(SEED, int(node), 1, 0, (10, 20), 20.0))
    tree = res.tree
    assert (tree.attempts[nodes] >= 1).all() and (tree.attempts[np.arange(1, 6)[~stuck]] == 0).all()
    assert res.resampled == sum(b.size for b in fd.batches[2::2])
    assert res.denoise_calls == fd.calls == 2 + 2 * len(fd.batches[2::2])


def test_same_search_twice_is_bitwise_equal():
    a, _ = run(parallel=4, budget=40, early_stop=True)
    b, _ = run(parallel=4, budget=40, early_stop=True)
    np.testing.assert_array_equal(a.plan, b.plan)
    for f in dataclasses.fields(a.tree):
        va, vb = getattr(a.tree, f.name), getattr(b.tree, f.name)
        assert np.array_equal(va, vb), f.name
    c, _ = run(parallel=4, budget=40, early_stop=True, seed=SEED + 1)
    assert c.tree.to_json() != a.tree.to_json() or not np.array_equal(c.plan, a.plan)


def test_params_from_method_config():
    m = MethodConfig(parallel=3, virtual_weight=0.5, redundancy_aware=False, guidance_scales=[0.0, 1.0])
    p = SearchParams.from_method(m, time_limit_s=2.0)
    assert (p.parallel, p.virtual_weight, p.redundancy_aware, p.guidance_scales) == (3, 0.5, False, (0.0, 1.0))
    assert (p.budget, p.warp_threshold, p.uct_c, p.time_limit_s, p.clip_noise) == (500, 2.0, m.uct_c, 2.0, 20.0)


def test_search_package_imports_neither_torch_nor_ray():
    code = ("import importlib, pkgutil, sys, fmctd_dist.search as s\n"
            "for m in pkgutil.iter_modules(s.__path__): importlib.import_module(f'fmctd_dist.search.{m.name}')\n"
            "bad = [m for m in ('torch', 'ray', 'omegaconf') if m in sys.modules]; assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_params_reject_nonsense():
    with pytest.raises(ValueError, match="parallel"):
        SearchParams(parallel=0)
    with pytest.raises(ValueError, match="guidance_scales"):
        SearchParams(guidance_scales=())
