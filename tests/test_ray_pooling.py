"""eval.in_flight on Ray (issue 55): threaded denoiser actors pool the segments of several trees; rows equal the
in-process rows, and an actor killed during a pooled call loses nothing (every waiting tree's jobs re-routed)."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from fmctd_dist.config import load_config
from fmctd_dist.denoiser.local import LocalDenoiser
from fmctd_dist.denoiser.ray_pool import DenoiserPool
from fmctd_dist.evaluation.grid import prepare
from fmctd_dist.families import hooks_for

from test_ray_faults import SEARCH, KillingDenoiser, plan

pytestmark = [pytest.mark.ray, pytest.mark.usefixtures("one_torch_thread")]


def test_pooled_ray_rows_equal_local_rows(tiny_checkpoint, ray_cluster, tmp_path):
    from fmctd_dist.evaluation.grid import run_local
    from fmctd_dist.evaluation.ray_runner import evaluate
    from fmctd_dist.evaluation.results import ResultStore

    args, _ = tiny_checkpoint
    words = args + SEARCH + ["tasks=[1,2]", "seeds=[0]", "eval.threads=1"]
    local_cfg = load_config(words + [f"eval.out={tmp_path}", "eval.run=local", "runner=local"])
    local = run_local(prepare(local_cfg, hooks_for), ResultStore(tmp_path, "local"), progress=False,
                      log=lambda s: None)
    pooled = evaluate(words + [f"eval.out={tmp_path}", "eval.run=pooled", "eval.in_flight=2",
                               "ray.denoiser_actors=1"], hooks_for, progress=False)
    assert sorted((r["task"], r["seed"]) for r in pooled) == [(1, 0), (2, 0)]
    by_key = {(r["task"], r["seed"]): r for r in local}
    for r in pooled:
        for k in ("success", "env_steps", "expansions", "plan_xy", "traj_xy"):
            assert r[k] == by_key[(r["task"], r["seed"])][k], k


def test_actor_killed_during_pooled_calls_reroutes_every_waiting_tree(tiny_checkpoint, ray_cluster):
    args, _ = tiny_checkpoint
    p = prepare(load_config(args + SEARCH + ["eval.in_flight=2"]), hooks_for)
    ref, _ = plan(p, LocalDenoiser.from_checkpoint(p.checkpoint, p.cfg))
    pool = DenoiserPool.create(p, 2)  # threaded actors, each pooling what arrives together
    try:
        den = KillingDenoiser(pool.actors, 2, call_timeout_s=60, max_restarts=3, kill_at=6)
        outs: list = [None, None]

        def tree(i: int) -> None:
            outs[i] = plan(p, den)[0]

        threads = [threading.Thread(target=tree, args=(i,)) for i in range(2)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(timeout=300)
        assert den.killed == 1
        assert sum(o.retries for o in outs) > 0, "the killed actor's segments should have been re-run"
        for o in outs:  # nothing lost, nothing doubled: both trees get the lone plan
            assert np.array_equal(o.waypoints, ref.waypoints) and o.expansions == ref.expansions
    finally:
        pool.shutdown()
