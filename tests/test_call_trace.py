"""Call traces: a record says what ran (shape, model calls, micro-batches, guided jobs, seconds); a replay batch
makes the same model work; the replay benchmark's tiny mode runs and writes its table (docs/design.md §6)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from conftest import load_job
from fmctd_dist.config import DiffusionConfig
from fmctd_dist.denoiser.local import LocalDenoiser
from fmctd_dist.denoiser.protocol import DenoiseBatch
from fmctd_dist.denoiser.trace import TracingDenoiser, as_one_batch, call_record, load_trace, replay_batch
from fmctd_dist.diffusion.model import DFTransformer

pytestmark = pytest.mark.usefixtures("one_torch_thread")

M = 3


def batch(rng, jobs: int, rows: int, guided: int, renoise: bool = False) -> DenoiseBatch:
    """Pyramid rows: token k of job j goes down from level 10 + k - j until 0 (so some rows of a job do nothing);
    with ``renoise`` a first row goes up by one."""
    t = 6
    start = np.clip(10 + np.arange(t)[None, :] - 3 * np.arange(jobs)[:, None], 0, 50)
    levels = np.clip(start[:, None, :] - 4 * np.arange(rows + 1)[None, :, None], 0, 50)
    if renoise:
        levels = np.concatenate([levels[:, :1], levels[:, :1] + 1, levels[:, 1:-1]], axis=1)
    levels[:, :, 0] = 0
    scale = np.zeros(jobs, np.float32)
    scale[:guided] = 1.0
    return DenoiseBatch(rng.standard_normal((jobs, t, 4)).astype(np.float32), levels.astype(np.int64), scale,
                        np.zeros((jobs, 2), np.float32), np.ones((jobs, 2), np.float32),
                        np.arange(jobs) if renoise else None)


def test_a_trace_says_what_ran_and_a_replay_batch_makes_the_same_model_work():
    torch.manual_seed(0)
    local = LocalDenoiser(DFTransformer(4, 6, width=16, layers=1, heads=2, ff=32), DiffusionConfig(), "cpu", M)
    traced = TracingDenoiser(local)
    rng = np.random.default_rng(0)
    asked = [batch(rng, 1, 5, 1), batch(rng, 7, 3, 2), batch(rng, 4, 6, 0, renoise=True), batch(rng, 0, 2, 0)]
    results = [traced.denoise(b) for b in asked]
    trace = traced.take()
    assert traced.take() == [] and len(trace) == len(asked)
    json.dumps(trace)  # JSON-friendly
    for b, r, rec in zip(asked, results, trace):
        assert (rec["jobs"], rec["tokens"], rec["token_dim"], rec["transitions"]) == (
            b.size, 6, 4, b.levels.shape[1] - 1)
        assert rec["micro_batches"] == r.stats["micro_batches"] == -(-b.size // M)
        assert rec["model_calls"] == r.stats["model_calls"] == sum(rec["down_rows"])
        assert rec["guided"] == int((b.scale != 0).sum())
        assert rec["denoise_s"] == r.denoise_time_s and rec["seconds"] >= rec["denoise_s"]
        again = replay_batch(rec, np.random.default_rng(1))
        fields = ["jobs", "tokens", "token_dim", "micro_batches", "model_calls", "guided", "down_rows", "up_rows",
                  "guided_mbs"]
        assert {k: call_record(again, M)[k] for k in fields} == {k: rec[k] for k in fields}
        assert local.denoise(again).stats["model_calls"] == rec["model_calls"]
        # the same call as one batch of all its jobs (a GPU's micro-batch) makes the whole call's model calls
        assert max(rec["down_rows"], default=0) <= rec["call_down_rows"] <= rec["model_calls"]
        one = as_one_batch(rec)
        made = local.denoise(replay_batch(one, np.random.default_rng(2)), micro_batch=one["micro_batch"])
        assert made.stats["model_calls"] == one["model_calls"] == rec["call_down_rows"]
    assert trace[2]["up_rows"] == [1, 1] and trace[2]["seeded"]
    assert trace[1]["guided_mbs"] == [1, 0, 0] and trace[0]["model_calls"] == 4  # its last row moves no token


def test_the_replay_benchmark_records_replays_and_writes_its_table(tiny_checkpoint, tmp_path, capsys):
    args, _ = tiny_checkpoint
    replay = load_job("replay")
    assert replay.main(["--dry-run", *args, f"out={tmp_path}", "eval.threads=1"]) == 0
    table = (tmp_path / "pointmaze-medium" / "replay-cpu.md").read_text()
    for m in ("mctd", "p-mctd", "s-mctd", "fast-mctd"):
        assert f"| {m} |" in table
        trace = json.loads((tmp_path / "pointmaze-medium" / f"{m}.json").read_text())
        assert trace["calls"] and trace["plan_s"] >= trace["denoise_s"] > 0
    # the stored traces replay on their own, with random weights of the same architecture, each call as one batch
    assert replay.main([*args, f"out={tmp_path}", "mode=replay", "weights=random", "methods=[mctd,fast-mctd]",
                        "batch=call", f"report={tmp_path / 'r'}"]) == 0
    assert "| mctd |" in capsys.readouterr().out
    rows = json.loads((tmp_path / "r" / "pointmaze-medium" / "replay-cpu-call.json").read_text())
    assert [r["method"] for r in rows] == ["mctd", "fast-mctd"] and all(r["replay_s"] > 0 for r in rows)
    # and project onto the H200 table without a model
    assert replay.main([f"out={tmp_path}", "mode=project"]) == 0
    projection = (tmp_path / "projection.md").read_text()
    assert "Projection" in projection and "| pointmaze-medium | mctd |" in projection
    assert load_trace(tmp_path / "pointmaze-medium", "fast-mctd")["method"] == "fast-mctd"
