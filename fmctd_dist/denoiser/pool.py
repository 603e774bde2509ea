"""PooledDenoiser: one in-process denoiser shared by many trees (threads), their jobs run together.

A tree alone sends small calls (MCTD and S-MCTD: one job each), which leave a batched model idle.
The pool batches continuously: a call runs at once when the pool is idle; calls that arrive while
a round runs wait, and the next round takes all of them. A round groups its calls by shape
(tokens, token and state dims), runs each group through the
inner denoiser in the usual fixed micro-batches of ``micro_batch`` jobs, and hands each call its
own rows. Since a job's bits do not depend on which jobs share its micro-batch (docs/design.md §7),
every tree gets the bits it would get alone at the same ``micro_batch`` (docs/design.md §6).
"""

from __future__ import annotations

import copy
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from fmctd_dist.denoiser.protocol import DenoiseBatch, DenoiseResult, concat_batches


@dataclass
class _Call:
    batch: DenoiseBatch
    arrived: float
    result: DenoiseResult | None = None
    error: BaseException | None = None


def signature(b: DenoiseBatch) -> tuple:
    """Calls with equal signatures share micro-batches: the same tokens and state dims. Their levels may hold
    different numbers of rows (an expansion's segment beside a simulation's jumpy rows): ``concat_batches``
    pads a job's levels with its last row, which leaves its tokens and x0 bit for bit as they were
    (``diffusion.sampler.run_levels``), and fills a missing mask or noise seed with what the sampler treats
    like none, so every job keeps the bits it has alone at the same micro-batch."""
    return (b.x.shape[1:], b.start.shape[1:])


def cost_order(b: DenoiseBatch) -> np.ndarray:
    """Jobs sorted by what their micro-batch will cost: the last row that moves a token, then guided or not. A
    micro-batch runs every row any of its jobs needs, guided if any job is, so an expansion (2 rows) cut in with a
    simulation (20 rows) would pay for 20; sorted, it shares its micro-batch with other short jobs. Which jobs
    share a micro-batch never changes a job's bits (docs/design.md §7)."""
    moves = (np.diff(b.levels, axis=1) != 0).any(axis=2)  # [B, R]
    last = (moves.shape[1] - np.argmax(moves[:, ::-1], axis=1)) * moves.any(axis=1) if moves.size else np.zeros(b.size)
    return np.lexsort((b.scale != 0, last))


class PooledDenoiser:
    """A Denoiser for many threads at once; ``inner.denoise(batch, micro_batch=M)`` runs one round's group
    (a :class:`LocalDenoiser`, or anything that cuts micro-batches the same way)."""

    def __init__(self, inner, micro_batch: int):
        if micro_batch < 1:
            raise ValueError(f"micro_batch={micro_batch} must be >= 1")
        self.inner, self.micro_batch = inner, micro_batch
        self._cv = threading.Condition()
        self._waiting: list[_Call] = []
        self._busy = False
        self._planning = 0  # trees inside a plan (see planning()): a round waits for a call from each
        self.rounds = 0

    @contextmanager
    def planning(self) -> Iterator[None]:
        """Around one tree's plan: while any tree is inside a plan, a round starts only once every such tree
        waits on the pool, so one round holds a call of each (a tree between plans, e.g. stepping its env,
        holds no one up). Without it the pool batches whatever has arrived (continuous batching)."""
        with self._cv:
            self._planning += 1
        try:
            yield
        finally:
            with self._cv:
                self._planning -= 1
                self._cv.notify_all()

    def denoise(self, batch: DenoiseBatch) -> DenoiseResult:
        """This call's rows, bitwise as ``inner.denoise(batch, micro_batch=M)`` alone; stats add ``wait_s``
        (queued before its round), ``round_calls`` / ``round_jobs`` and ``group_jobs`` (what ran with it)."""
        call = _Call(batch, time.perf_counter())
        with self._cv:
            self._waiting.append(call)
            self._cv.notify_all()  # this call may complete the quorum a waiting thread is holding its round for
            while call.result is None and call.error is None and (self._busy or len(self._waiting) < self._planning):
                self._cv.wait()
            calls = []
            if call.result is None and call.error is None:  # idle pool: this thread runs the next round
                calls, self._waiting, self._busy = self._waiting, [], True
        if calls:
            try:
                self._round(calls)
            finally:
                with self._cv:
                    for c in calls:  # an interrupted round (KeyboardInterrupt) must not leave anyone waiting
                        if c.result is None and c.error is None:
                            c.error = RuntimeError("the pool's round was interrupted")
                    self._busy = False
                    self.rounds += 1
                    self._cv.notify_all()
        if call.error is not None:
            raise _own_copy(call.error)
        return call.result

    def _round(self, calls: list[_Call]) -> None:
        start = time.perf_counter()
        groups: dict[tuple, list[_Call]] = {}
        for c in calls:
            groups.setdefault(signature(c.batch), []).append(c)
        jobs = sum(c.batch.size for c in calls)
        done = []
        try:
            for group in groups.values():
                batch = concat_batches([c.batch for c in group]) if len(group) > 1 else group[0].batch
                order = cost_order(batch)  # like jobs share micro-batches: few rows with few, guided with guided
                res = self.inner.denoise(batch.take(order), micro_batch=self.micro_batch)
                back = np.argsort(order)
                res = DenoiseResult(res.x[back], res.x0[back], res.denoise_time_s, res.retries, res.stats)
                lo = 0
                for c in group:
                    hi = lo + c.batch.size
                    share = res.denoise_time_s * c.batch.size / max(batch.size, 1)
                    stats = {**res.stats, "wait_s": start - c.arrived, "round_calls": len(calls),
                             "round_jobs": jobs, "group_jobs": batch.size}
                    done.append((c, DenoiseResult(res.x[lo:hi], res.x0[lo:hi], share, res.retries, stats)))
                    lo = hi
        except Exception as e:  # noqa: BLE001 - it reaches every call of the round, in its own thread
            for c in calls:
                c.error = e
            return
        for c, r in done:
            c.result = r


def _own_copy(e: BaseException) -> BaseException:
    """The round's exception for one waiting thread (several threads raising one object share its traceback)."""
    try:
        return copy.copy(e).with_traceback(e.__traceback__)
    except Exception:  # noqa: BLE001 - an exception that cannot be copied is raised as it is
        return e
