"""The GPU projection of a plan trace (jobs/bench/projection.py): log-log interpolation of a throughput table, a call's
seconds at its own batch or its recorded micro-batch, plus the search's own CPU seconds; numbers done by hand."""

from __future__ import annotations

import math

import pytest

from conftest import load_job

projection = load_job("projection")
H200_FP32, call_seconds, project, throughput = (projection.H200_FP32, projection.call_seconds, projection.project,
                                                projection.throughput)

TABLE = {10: {1: 100.0, 100: 10_000.0}, 100: {1: 50.0, 100: 1_000.0}}


def rec(jobs: int, tokens: int, micro_batch: int, down: list[int], whole: int, cpu_s: float) -> dict:
    return {"jobs": jobs, "tokens": tokens, "micro_batch": micro_batch, "model_calls": sum(down), "down_rows": down,
            "call_down_rows": whole, "cpu_s": cpu_s}


def test_throughput_is_log_log_interpolated_and_clamped_at_the_edges():
    assert throughput(10, 1, TABLE) == pytest.approx(100.0) and throughput(100, 100, TABLE) == pytest.approx(1000.0)
    assert throughput(10, 10, TABLE) == pytest.approx(1000.0)  # halfway in log batch: sqrt(100 * 10,000)
    assert throughput(100, 10, TABLE) == pytest.approx(math.sqrt(50 * 1000))
    assert throughput(math.sqrt(1000), 1, TABLE) == pytest.approx(math.sqrt(100 * 50))  # halfway in log tokens
    assert throughput(10, 1000, TABLE) == pytest.approx(10_000.0)  # no gain assumed beyond the largest batch
    assert throughput(5, 1, TABLE) == pytest.approx(100.0) and throughput(500, 1, TABLE) == pytest.approx(50.0)
    assert throughput(21, 200) == pytest.approx(H200_FP32[21][200])  # the shipped table at a measured point


def test_a_hand_made_trace_projects_to_its_hand_computed_seconds():
    trace = {"method": "x", "env": "e", "plan_cpu_s": 3.0,
             "calls": [rec(1, 10, 1, [5], 5, 1.0),                 # 5 model calls at batch 1: 5 / 100 = 0.05 s
                       rec(100, 100, 10, [4] * 10, 4, 1.5),        # as one batch: 4 x 100 / 1,000 = 0.4 s
                       rec(0, 10, 8, [], 0, 0.0)]}                 # no jobs: free
    assert call_seconds(trace["calls"][0], "call", TABLE) == pytest.approx(0.05)
    assert call_seconds(trace["calls"][1], "call", TABLE) == pytest.approx(0.4)
    # at its recorded micro-batch of 10: 40 model calls x 10 jobs at sqrt(50 x 1,000) jobs/s
    assert call_seconds(trace["calls"][1], "trace", TABLE) == pytest.approx(400 / math.sqrt(50_000))
    p = project(trace, "call", TABLE)
    assert p["model_s"] == pytest.approx(0.45) and p["overhead_s"] == pytest.approx(0.5)  # 3.0 - (1.0 + 1.5)
    assert p["plan_s"] == pytest.approx(0.95)
    assert project(trace, "trace", TABLE)["plan_s"] == pytest.approx(0.05 + 400 / math.sqrt(50_000) + 0.5)
    with pytest.raises(ValueError):
        call_seconds(trace["calls"][0], "gpu", TABLE)
