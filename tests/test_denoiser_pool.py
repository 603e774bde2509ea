"""Contract: through a PooledDenoiser shared by N threads (trees), every tree gets the bits of its own calls run
alone through the inner denoiser at the same micro-batch; errors reach every tree of their round; nothing is
swapped between trees (docs/design.md §6-7). CPU, a small random-weight model, one torch thread."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
import torch

from fmctd_dist.config import DiffusionConfig
from fmctd_dist.denoiser.local import LocalDenoiser
from fmctd_dist.denoiser.pool import PooledDenoiser
from fmctd_dist.denoiser.protocol import DenoiseBatch, DenoiseResult
from fmctd_dist.diffusion.model import DFTransformer

pytestmark = pytest.mark.usefixtures("one_torch_thread")

M = 4  # micro-batch: trees of 1..9 jobs fill, split and pad micro-batches in every way
D = 4  # token dim: two frames of (x, y)


@pytest.fixture(scope="module")
def local():
    torch.manual_seed(0)
    model = DFTransformer(D, 12, width=32, layers=2, heads=2, ff=64)
    return LocalDenoiser(model, DiffusionConfig(), "cpu", micro_batch=M)


def make_batch(rng, jobs: int, tokens: int = 8, rows: int = 3, guided: float = 0.5, seeded: bool = False,
               masked: bool = False) -> DenoiseBatch:
    """Pyramid-like levels (each plan token goes down from its own level), a first row that re-noises when
    seeded, a share of guided jobs."""
    top = rng.integers(rows, 50, size=(jobs, 1, tokens))
    down = np.clip(top - np.arange(rows + 1)[None, :, None], 0, 50)
    if seeded:
        down = np.concatenate([np.clip(top - 1, 0, 50), down], axis=1)[:, : rows + 1]
    down[:, :, 0] = 0
    scale = np.where(rng.random(jobs) < guided, rng.choice([0.1, 1.0, 2.0], jobs), 0.0).astype(np.float32)
    mask = (rng.random((jobs, 2)) < 0.5).astype(np.float32) if masked else None
    return DenoiseBatch(rng.standard_normal((jobs, tokens, D)).astype(np.float32), down.astype(np.int64), scale,
                        rng.standard_normal((jobs, 2)).astype(np.float32),
                        rng.standard_normal((jobs, 2)).astype(np.float32),
                        rng.integers(0, 2**40, jobs) if seeded else None, mask)


MIXES = {  # per tree: the kwargs of its calls (each tree sends them one after the other)
    "same shape, different sizes": [[{"jobs": j}] * 2 for j in (1, 3, 5, 9)],
    "sequential trees (one job per call)": [[{"jobs": 1, "guided": g}] * 3 for g in (0.0, 1.0, 1.0, 0.0, 1.0)],
    "mixed R, T, seeds, masks": [
        [{"jobs": 3, "rows": 3}, {"jobs": 2, "rows": 5, "seeded": True}],
        [{"jobs": 5, "rows": 5, "seeded": True}, {"jobs": 1, "rows": 3}],
        [{"jobs": 2, "rows": 3, "masked": True}, {"jobs": 4, "rows": 3, "masked": True, "seeded": True}],
        [{"jobs": 6, "tokens": 11, "rows": 3}, {"jobs": 3, "rows": 3, "guided": 0.0}],
        [{"jobs": 1, "tokens": 11, "rows": 3, "guided": 1.0}, {"jobs": 7, "rows": 5}],
    ],
}


def run_trees(pool, trees: list[list[DenoiseBatch]]) -> list[list]:
    """Every tree in its own thread, all starting together; a tree's outcomes (results or exceptions) in order."""
    out = [[] for _ in trees]
    go = threading.Barrier(len(trees))

    def tree(i):
        go.wait()
        for b in trees[i]:
            try:
                out[i].append(pool.denoise(b))
            except Exception as e:  # noqa: BLE001 - the test looks at it
                out[i].append(e)

    threads = [threading.Thread(target=tree, args=(i,)) for i in range(len(trees))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert not any(t.is_alive() for t in threads), "a tree never got its answer"
    return out


class Gate:
    """The inner denoiser, whose first call waits until ``n`` calls wait on the pool: the next round then takes
    all of them at once, whatever the threads' timing."""

    def __init__(self, inner, n: int):
        self.inner, self.n, self.pool, self.calls = inner, n, None, []

    def denoise(self, batch, micro_batch):
        if not self.calls:
            deadline = time.monotonic() + 30
            while len(self.pool._waiting) < self.n and time.monotonic() < deadline:
                time.sleep(0.001)
        self.calls.append(batch.size)
        return self.inner.denoise(batch, micro_batch=micro_batch)


def gated_pool(inner, n: int) -> PooledDenoiser:
    gate = Gate(inner, n)
    gate.pool = PooledDenoiser(gate, M)
    return gate.pool


@pytest.mark.parametrize("mix", list(MIXES))
def test_each_tree_gets_the_bits_it_gets_alone(local, mix):
    rng = np.random.default_rng(len(mix))
    trees = [[make_batch(rng, **kw) for kw in calls] for calls in MIXES[mix]]
    pool = gated_pool(local, len(trees) - 1)
    out = run_trees(pool, trees)
    pooled = 0
    for batches, results in zip(trees, out):
        for b, r in zip(batches, results):
            assert isinstance(r, DenoiseResult), r
            alone = local.denoise(b, micro_batch=M)
            assert np.array_equal(r.x, alone.x) and np.array_equal(r.x0, alone.x0), mix
            pooled = max(pooled, r.stats["round_calls"])
    assert pooled >= len(trees) - 1, "the trees' calls were never pooled"
    assert pool.rounds < sum(map(len, trees))


def test_an_error_reaches_every_tree_of_its_round_and_the_pool_keeps_working(local):
    rng = np.random.default_rng(1)
    bad = make_batch(rng, 2)
    bad = DenoiseBatch(bad.x, bad.levels + 60, bad.scale, bad.start, bad.goal)  # levels beyond the ladder
    first, goods = make_batch(rng, 1), [make_batch(rng, j) for j in (1, 3)]
    pool = gated_pool(local, 3)
    head = []
    lone = threading.Thread(target=lambda: head.append(pool.denoise(first)))
    lone.start()  # its round runs alone and holds the pool until the three others wait
    while not pool._busy:
        time.sleep(0.001)
    out = run_trees(pool, [[bad], [goods[0]], [goods[1]]])
    lone.join(timeout=60)
    assert isinstance(head[0], DenoiseResult)
    errors = [o[0] for o in out]
    assert all(isinstance(e, ValueError) and "levels must lie" in str(e) for e in errors), errors
    assert len({id(e) for e in errors}) == 3  # each thread raised its own copy
    again = run_trees(pool, [[g] for g in goods])  # the pool is usable after a failed round
    for g, (r,) in zip(goods, again):
        assert np.array_equal(r.x, local.denoise(g, micro_batch=M).x)


class Echo:
    """A fake inner denoiser: x0 is the batch's own x, x is 2x; it checks it is never called concurrently."""

    def __init__(self):
        self.busy = False

    def denoise(self, batch, micro_batch):
        assert not self.busy, "the inner denoiser ran two rounds at once"
        self.busy = True
        time.sleep(0.0005)
        self.busy = False
        return DenoiseResult(batch.x * 2, batch.x.copy(), denoise_time_s=1.0, stats={"model_calls": 1})


def test_results_are_never_swapped_between_trees():
    rng = np.random.default_rng(2)
    trees = [[make_batch(rng, int(rng.integers(0, 6)), rows=int(rng.integers(2, 4))) for _ in range(20)]
             for _ in range(12)]
    pool = PooledDenoiser(Echo(), M)
    out = run_trees(pool, trees)
    for batches, results in zip(trees, out):
        for b, r in zip(batches, results):
            assert isinstance(r, DenoiseResult), r
            assert np.array_equal(r.x0, b.x) and np.array_equal(r.x, 2 * b.x)
            assert r.stats["wait_s"] >= 0 and r.stats["group_jobs"] >= b.size
            assert r.denoise_time_s == pytest.approx(b.size / max(r.stats["group_jobs"], 1))  # its share
    assert pool.rounds < 240


def test_calls_of_different_rows_share_one_group(local):
    """An expansion (a few rows) and a simulation (more rows, re-noising, a mask) of two trees run in the same
    micro-batches, each with its own bits (a third tree's call takes the first round, which the gate holds until
    the other two wait)."""
    rng = np.random.default_rng(7)
    trees = [[make_batch(rng, jobs=1, rows=3)], [make_batch(rng, jobs=1, rows=3)],
             [make_batch(rng, jobs=1, rows=6, seeded=True, masked=True)]]
    out = run_trees(gated_pool(local, 2), trees)
    groups = []
    for (b,), (r,) in zip(trees, out):
        alone = local.denoise(b, micro_batch=M)
        assert np.array_equal(r.x, alone.x) and np.array_equal(r.x0, alone.x0)
        groups.append(r.stats["group_jobs"])
    assert sorted(groups) == [1, 2, 2]
