"""A plan's time on a GPU we do not have, projected from its call trace and a measured throughput table (issue 55).

    python jobs/bench/projection.py jobs/bench/traces/pointmaze-giant/*.json*   # one line per trace
    (jobs/bench/replay.py mode=project writes the tables of docs/results.md from the same functions)

Why: the paper's 16-110x MCTD / Fast-MCTD ratios come from a GPU, where a batch of 200 jobs costs about what one
does; our CPUs cannot show that half of the speed-up. A trace (``denoiser.trace``) says what model work each call
of a real plan made, a throughput table measured on a GPU says what that work costs, and the search's own CPU
seconds (measured) are added back. Everything this module returns is a **projection**, until
``jobs/gpu/gpu_replay.py`` has replayed the same traces on a GPU.

A call's micro-batch on the GPU is either the call itself (``batch="call"``: the paper's setting, a call of 200
rollouts is one batch of 200; its model calls are the rows where any job of the call goes down, the record's
``call_down_rows``) or the micro-batch it was recorded at (``batch="trace"``: e.g. 8 for Fast-MCTD on our CPUs).
A micro-batch of B jobs making r model calls costs r x B / throughput(tokens, B) seconds.
"""

from __future__ import annotations

import math

# Guided DDIM job-transitions per second of the 6 x 128 model, fp32, tokens -> {batch: jobs/s}. Measured on the
# H200 lent to session 24 (torch 2.11 + CUDA 13, random weights, median of 2 interleaved rounds):
#   python3 jobs/bench_denoiser.py --throughput device=cuda batches=1,25,200,1000 tokens=11,21,101 \
#       options=fp32,bf16 rounds=2
# docs/notebook/speed.md section 6.4; docs/results.md "Planning time: MCTD against Fast-MCTD, side by side".
H200_FP32: dict[int, dict[int, float]] = {
    11: {1: 176.0, 25: 4_739.0, 200: 38_049.0, 1000: 179_165.0},
    21: {1: 168.0, 25: 3_901.0, 200: 34_309.0, 1000: 127_103.0},
    101: {1: 121.0, 25: 3_361.0, 200: 24_370.0, 1000: 34_012.0},
}
H200_SOURCE = ("H200, session 24 (docs/notebook/speed.md 6.4): python3 jobs/bench_denoiser.py --throughput "
               "device=cuda batches=1,25,200,1000 tokens=11,21,101 options=fp32,bf16 rounds=2 (fp32 column)")
BATCHES = ("call", "trace")


def _interp_log(x: float, points: dict[int, float]) -> float:
    """Piecewise-linear interpolation of log(value) over log(x), clamped at the end points (no extrapolation)."""
    keys = sorted(points)
    x = min(max(x, keys[0]), keys[-1])
    for lo, hi in zip(keys, keys[1:]):
        if x <= hi:
            w = (math.log(x) - math.log(lo)) / (math.log(hi) - math.log(lo))
            return math.exp((1 - w) * math.log(points[lo]) + w * math.log(points[hi]))
    return points[keys[-1]]  # a table of one point


def throughput(tokens: int, batch: int, table: dict[int, dict[int, float]] = H200_FP32) -> float:
    """Job-transitions/s at ``tokens`` and ``batch``: log-log interpolation over batch within each measured token
    count, then log-log over tokens between them; clamped at the table's edges (beyond batch 1000 no further
    gain is assumed, below 11 or above 101 tokens the edge row is used)."""
    per_tokens = {t: _interp_log(batch, row) for t, row in table.items()}
    return _interp_log(tokens, per_tokens)


def call_seconds(rec: dict, batch: str = "call", table: dict[int, dict[int, float]] = H200_FP32) -> float:
    """Projected model seconds of one call record (``batch``: the GPU's micro-batch, module docstring)."""
    if batch not in BATCHES:
        raise ValueError(f"batch={batch}: one of {BATCHES}")
    if not rec["jobs"]:
        return 0.0
    if batch == "call":
        b = rec["jobs"]
        calls = rec.get("call_down_rows", max(rec["down_rows"], default=0))  # traces before the field: a floor
    else:
        b, calls = rec["micro_batch"], rec["model_calls"]
    return calls * b / throughput(rec["tokens"], b, table)


def search_cpu_s(trace: dict) -> float:
    """The search's own CPU seconds in a recorded plan: the plan's CPU time less its calls' (CPU seconds, because
    wall time on a shared CPU is stretched by load)."""
    return max(0.0, trace["plan_cpu_s"] - sum(c["cpu_s"] for c in trace["calls"]))


def project(trace: dict, batch: str = "call", table: dict[int, dict[int, float]] = H200_FP32) -> dict:
    """A recorded plan's projection: model seconds from the table, plus the search's own CPU seconds as measured."""
    model_s = sum(call_seconds(c, batch, table) for c in trace["calls"])
    overhead_s = search_cpu_s(trace)
    return {"method": trace["method"], "env": trace["env"], "batch": batch, "model_s": model_s,
            "overhead_s": overhead_s, "plan_s": model_s + overhead_s}


def main(argv: list[str]) -> int:
    import sys
    from pathlib import Path

    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__)
        return 0
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    from fmctd_dist.denoiser.trace import load_trace

    for path in map(Path, argv):  # <folder>/<method>.json or .json.gz
        stored = load_trace(path.parent, path.name.split(".json")[0])
        one, trace = project(stored, "call"), project(stored, "trace")
        print(f"{path}: {one['method']} on {one['env']}: projected plan {one['plan_s']:.2f} s (calls as one batch), "
              f"{trace['plan_s']:.2f} s (at the recorded micro-batch); search {one['overhead_s']:.2f} CPU s")
    return 0


if __name__ == "__main__":
    import sys

    raise SystemExit(main(sys.argv[1:]))
