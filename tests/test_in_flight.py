"""eval.in_flight (issue 55): episodes planned at once in one process, their denoiser jobs pooled, give the rows
a lone episode gives, bit for bit, for every method kind (MCTD family and the fixed-schedule planners)."""

from __future__ import annotations

import pytest

from fmctd_dist.config import load_config
from fmctd_dist.evaluation.grid import prepare, run_local
from fmctd_dist.evaluation.results import ResultStore
from fmctd_dist.families import hooks_for

PLAN_FIELDS = ("success", "env_steps", "expansions", "iterations", "plan_xy", "traj_xy", "plan_status")


def rows(words: list[str], out, in_flight: int) -> dict:
    cfg = load_config(words + [f"eval.out={out}", f"eval.run=f{in_flight}", f"eval.in_flight={in_flight}",
                               "runner=local", "eval.threads=1", "tasks=[1,2]", "seeds=[0,1]"])
    got = run_local(prepare(cfg, hooks_for), ResultStore(cfg.eval.out, cfg.eval.run), progress=False,
                    log=lambda s: None)
    return {(r["task"], r["seed"]): r for r in got}


@pytest.mark.parametrize("method", [
    ["method=mctd", "method.budget=12", "ray.micro_batch=4"],  # one job per call: pooled across the trees
    ["method=p-mctd", "method.parallel=4", "method.budget=12", "ray.micro_batch=4"],
    ["method=diffusion-forcing", "ray.micro_batch=4"],
])
def test_pooled_rows_equal_lone_rows(tiny_checkpoint, tmp_path, method, monkeypatch):
    from fmctd_dist.denoiser.pool import PooledDenoiser

    rounds: list[int] = []  # calls per round of the pool
    run_round = PooledDenoiser._round
    monkeypatch.setattr(PooledDenoiser, "_round", lambda self, calls: (rounds.append(len(calls)),
                                                                       run_round(self, calls))[1])
    args, _ = tiny_checkpoint
    words = args + method + ["method.early_stop=false"]
    alone = rows(words, tmp_path, 1)
    assert not rounds  # in_flight=1: no pool
    pooled = rows(words, tmp_path, 3)
    assert sorted(alone) == sorted(pooled) == [(t, s) for t in (1, 2) for s in (0, 1)]
    for key, r in alone.items():
        for field in PLAN_FIELDS:
            if field in r:
                assert r[field] == pooled[key][field], (key, field)
    assert max(rounds) > 1  # the episodes really shared rounds: some round held several trees' calls


def test_a_run_never_mixes_micro_batches(tiny_checkpoint, tmp_path):
    """ray.micro_batch shapes bits but sits outside the config hash: rows record it, and a run holding rows of
    another micro-batch refuses to resume (one ResultsError naming the field)."""
    from fmctd_dist.errors import ResultsError

    args, _ = tiny_checkpoint
    words = args + ["method=mctd", "method.budget=6", "method.early_stop=false"]
    cfg = load_config(words + [f"eval.out={tmp_path}", "eval.run=r", "runner=local", "tasks=[1]", "seeds=[0]",
                               "ray.micro_batch=1", "eval.threads=1"])
    got = run_local(prepare(cfg, hooks_for), ResultStore(tmp_path, "r"), progress=False, log=lambda s: None)
    assert got[0]["micro_batch"] == 1 and got[0]["in_flight"] == 1
    cfg = load_config(words + [f"eval.out={tmp_path}", "eval.run=r", "runner=local", "tasks=[1]", "seeds=[0,1]",
                               "ray.micro_batch=4", "eval.threads=1"])
    with pytest.raises(ResultsError, match="ray.micro_batch: 1 there, 4 now"):
        run_local(prepare(cfg, hooks_for), ResultStore(tmp_path, "r"), progress=False, log=lambda s: None)


VISUAL = "checkpoints/visual-pointmaze-medium-h1"


@pytest.mark.skipif(not __import__("os").path.exists(f"{VISUAL}/model.pt"), reason=f"{VISUAL} is not shipped")
def test_pooled_visual_rows_equal_lone_rows(tmp_path, monkeypatch):
    """The visual family pools too: its planner's guide map (latents -> estimated positions) rides in every job, and
    its rows keep their bits. One plan per episode (the time limit ends each after it): images, VAE and estimator
    run, the cost of env steps is saved."""
    from fmctd_dist.denoiser.pool import PooledDenoiser

    rounds: list[int] = []
    run_round = PooledDenoiser._round
    monkeypatch.setattr(PooledDenoiser, "_round", lambda self, calls: (rounds.append(len(calls)),
                                                                       run_round(self, calls))[1])
    words = ["env=visual-pointmaze-medium", "method=mctd", "method.budget=6", "ray.micro_batch=4",
             "method.early_stop=false", "env.warp_sparse=8.0", "eval.episode_time_limit=1",
             # the latent planner (the paper's frames): its 6 expansions fit in the 1 s limit, which the search
             # checks by the clock (the default [z, x, y] planner with boundary guidance is slower, so the limit
             # would cut its search at a time-dependent expansion)
             "visual.plan_xy=false", "visual.episodes=20", "diffusion.boundary_guidance=0"]
    alone, pooled = rows(words, tmp_path, 1), rows(words, tmp_path, 3)
    assert sorted(alone) == sorted(pooled) == [(t, s) for t in (1, 2) for s in (0, 1)]
    for key, r in alone.items():
        assert all(r[f] == pooled[key][f] for f in PLAN_FIELDS if f in r), key
        assert len(r["plan_xy"]) > 0
    assert max(rounds) > 1
