"""Call traces: what a planner asked of its denoiser, call by call, small enough to store and replay.

A trace is a list of small dicts (JSON / parquet rows), one per ``denoise`` call: its shape (jobs,
tokens, token dim, transitions), what the model did (model calls, micro-batches, guided jobs; per
micro-batch its denoising and re-noising rows and whether it holds a guided job) and its seconds.
A plan's trace is every call of one plan; ``jobs/bench/replay.py`` replays traces on any device to
split a plan's time into the model's and the search's own (docs/design.md §6).
"""

from __future__ import annotations

import gzip
import json
import time
from pathlib import Path

import numpy as np

from fmctd_dist.denoiser.protocol import DenoiseBatch, DenoiseResult, micro_batch_indices


def call_record(batch: DenoiseBatch, micro_batch: int) -> dict:
    """The shape of one call cut into micro-batches of ``micro_batch`` jobs, and per micro-batch what its model
    work is: rows where a job goes down (one model call each, as ``run_levels`` runs them), rows that re-noise,
    whether a job is guided (a guided micro-batch also runs the gradient). ``call_down_rows``: the model calls of
    the whole call run as one batch (a GPU's micro-batch; the projection in ``jobs/bench/projection.py`` reads it)."""
    b, t, d = batch.x.shape
    guided = batch.scale != 0
    cut = micro_batch_indices(b, micro_batch)
    step = [np.diff(batch.levels[i], axis=1) for i in cut]  # per micro-batch [M, R, T]
    down = [int((s < 0).any(axis=(0, 2)).sum()) for s in step]
    whole = int((np.diff(batch.levels, axis=1) < 0).any(axis=(0, 2)).sum()) if b else 0
    return {"jobs": b, "tokens": t, "token_dim": d, "state_dim": int(batch.start.shape[1]),
            "transitions": int(batch.levels.shape[1]) - 1, "micro_batch": micro_batch, "micro_batches": len(cut),
            "model_calls": sum(down), "guided": int(guided.sum()), "down_rows": down, "call_down_rows": whole,
            "up_rows": [int((s > 0).any(axis=(0, 2)).sum()) for s in step],
            "guided_mbs": [int(guided[i].any()) for i in cut],
            "seeded": batch.noise_seed is not None, "masked": batch.guide_mask is not None}


def replay_batch(rec: dict, rng: np.random.Generator) -> DenoiseBatch:
    """A batch of a record's shape and model work: random tokens; in micro-batch i every job re-noises on
    ``up_rows[i]`` rows and then goes down on ``down_rows[i]`` rows; the record's guided jobs spread over its guided
    micro-batches (at least one each). Run with ``micro_batch=rec["micro_batch"]`` it makes the recorded model calls."""
    b, t, d, m = rec["jobs"], rec["tokens"], rec["token_dim"], rec["micro_batch"]
    rows = max([rec["transitions"]] + [u + w for u, w in zip(rec["up_rows"], rec["down_rows"])])
    levels = np.zeros((b, rows + 1, t), np.int64)
    scale = np.zeros(b, np.float32)
    slots = []  # jobs of the guided micro-batches, first jobs first
    for i, (up, down, g) in enumerate(zip(rec["up_rows"], rec["down_rows"], rec["guided_mbs"])):
        jobs = np.arange(i * m, min((i + 1) * m, b))
        path = np.concatenate([down + np.arange(up + 1), down + up - np.arange(1, down + 1)])  # level per row
        levels[jobs, :, 1:] = np.pad(path, (0, rows + 1 - len(path)), mode="edge")[:, None]
        slots += [(k, j) for k, j in enumerate(jobs)] if g else []
    scale[[j for _, j in sorted(slots)[: rec["guided"]]]] = 1.0
    state = rec["state_dim"]
    return DenoiseBatch(rng.standard_normal((b, t, d)).astype(np.float32), levels, scale,
                        rng.standard_normal((b, state)).astype(np.float32),
                        rng.standard_normal((b, state)).astype(np.float32),
                        np.arange(b, dtype=np.int64) if rec["seeded"] or any(rec["up_rows"]) else None,
                        np.ones((b, state), np.float32) if rec["masked"] else None)


def as_one_batch(rec: dict) -> dict:
    """The record of the same call run as one micro-batch of all its jobs (a GPU's setting: a call of 200 rollouts
    is one batch of 200): ``replay_batch`` of it, run at ``micro_batch=rec["micro_batch"]``, makes the whole
    call's model calls, ``call_down_rows`` (every job on one levels path; up rows: the most of any micro-batch)."""
    down = rec.get("call_down_rows", max(rec["down_rows"], default=0))
    n = int(rec["jobs"] > 0)  # micro-batches: one, or none for a call of no jobs
    return {**rec, "micro_batch": max(rec["jobs"], 1), "micro_batches": n, "model_calls": down * n,
            "down_rows": [down][:n], "up_rows": [max(rec["up_rows"], default=0)][:n],
            "guided_mbs": [int(rec["guided"] > 0)][:n], "call_down_rows": down}


class TracingDenoiser:
    """Wraps a denoiser and records each call; :meth:`take` returns one :func:`call_record` per call, with
    ``seconds`` (wall time of the call), ``cpu_s`` (this process's CPU time in it: unlike wall time, not
    stretched when other jobs share the cores) and ``denoise_s`` (the inner's model time, ``denoise_time_s``).
    Records are built in :meth:`take`, so a traced plan's time holds no tracing work beyond copying the levels."""

    def __init__(self, inner, micro_batch: int | None = None):
        self.inner = inner
        self.micro_batch = micro_batch or inner.micro_batch
        self._calls: list[tuple[DenoiseBatch, float, float, float]] = []

    def denoise(self, batch: DenoiseBatch) -> DenoiseResult:
        t0, c0 = time.perf_counter(), time.process_time()
        res = self.inner.denoise(batch)
        seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
        self._calls.append((_shape_only(batch), seconds, cpu, float(res.denoise_time_s)))
        return res

    def take(self) -> list[dict]:
        """The records of the calls since the last ``take`` (one plan's trace when called after each plan)."""
        out = [{**call_record(b, self.micro_batch), "seconds": s, "cpu_s": c, "denoise_s": d}
               for b, s, c, d in self._calls]
        self._calls = []
        return out


def _shape_only(b: DenoiseBatch) -> DenoiseBatch:
    """What a record reads: levels and scales copied (a caller may reuse its arrays), the rest zero views."""
    def zero(a):
        return None if a is None else np.broadcast_to(np.zeros((), a.dtype), a.shape)

    return DenoiseBatch(zero(b.x), b.levels.copy(), b.scale.copy(), zero(b.start), zero(b.goal), zero(b.noise_seed),
                        zero(b.guide_mask))


def load_trace(folder: Path, method: str) -> dict | None:
    """A stored plan trace, ``<folder>/<method>.json`` or gzipped ``.json.gz`` (the large committed ones in
    ``jobs/bench/traces``); None when there is none."""
    for path, opener in ((folder / f"{method}.json", open), (folder / f"{method}.json.gz", gzip.open)):
        if path.exists():
            with opener(path, "rt") as f:
                return json.load(f)
    return None
