"""RayDenoiser: the Denoiser protocol over a pool of ``DenoiserActor``s (docs/design.md §6-9).

A batch is cut in job order into micro-batches of exactly M = ``ray.micro_batch`` jobs, the cut
:class:`LocalDenoiser` makes, so every model call has the same shapes with 1 actor, N actors or no Ray
and plans are bitwise equal on CPU. The micro-batches go in one contiguous segment (one call) per live
actor, least-loaded first; a segment whose actor died or did not answer within ``ray.call_timeout_s``
per micro-batch is re-run on another live actor (counted in ``DenoiseResult.retries``). With no live
actor left, one :class:`DeviceError` is raised -- never a hang.

    pool = DenoiserPool.create(prepared, n=2)      # actors load the checkpoint (digest-checked)
    planner = make_planner(cfg, pool.denoiser(), normaliser, rules)
"""

from __future__ import annotations

import os
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import ray
from ray.exceptions import (
    GetTimeoutError, NodeDiedError, ObjectLostError, OwnerDiedError, RayActorError, RayTaskError, WorkerCrashedError,
)

from fmctd_dist.config import Config, RayConfig, config_from_dict
from fmctd_dist.denoiser.protocol import DenoiseBatch, DenoiseResult, micro_batch_indices
from fmctd_dist.errors import DeviceError, FmctdError

__all__ = ["DenoiserActor", "RayDenoiser", "DenoiserPool", "unwrap_ray_error"]


def unwrap_ray_error(e: BaseException) -> BaseException:
    """The FmctdError a remote call raised (so users read our message, not a RayTaskError)."""
    if isinstance(e, RayTaskError):
        cause = getattr(e, "cause", None)
        if isinstance(cause, FmctdError):
            return cause
        if isinstance(cause, BaseException):
            return unwrap_ray_error(cause)
    return e


def auto_actors(r: RayConfig) -> int:
    """Denoiser actors for ``ray.denoiser_actors=0``: one per GPU (``ray.num_gpus`` each), else one per
    ``ray.num_cpus`` CPUs of the connected cluster, so no core the cluster offers sits idle."""
    res = ray.cluster_resources()
    if r.num_gpus > 0:
        return max(int(res.get("GPU", 0.0) // r.num_gpus), 1)
    cpus = res.get("CPU", 1.0)
    return max(int(cpus // r.num_cpus) if r.num_cpus > 0 else int(cpus), 1)


@ray.remote
class DenoiserActor:
    """One LocalDenoiser in its own process (one GPU each when ``ray.num_gpus`` = 1).

    The constructor never raises: a bad checkpoint or a missing GPU is kept and raised by
    :meth:`info` and :meth:`denoise`, because Ray drops the exception of a failed actor
    constructor and the user would read "actor died" instead of our message.
    """

    def __init__(self, checkpoint: str, digest: str, cfg_dict: dict, device: str, guide_map: Any = None):
        import torch

        from fmctd_dist.denoiser.local import LocalDenoiser
        from fmctd_dist.device import bf16_warning

        cfg = config_from_dict(cfg_dict)
        torch.set_num_threads(max(1, int(cfg.ray.num_cpus)))
        self._info: dict[str, Any] = {"gpu_ids": [str(g) for g in ray.get_gpu_ids()],
                                      "cuda_device_count": torch.cuda.device_count(),
                                      "torch_threads": torch.get_num_threads(), "requested_device": device,
                                      "niceness": os.nice(0)}
        self._error: FmctdError | None = None
        self._denoiser = None
        self._pool = None  # eval.in_flight > 1: segments that arrive together share model calls
        try:
            if device.startswith("cuda") and (not ray.get_gpu_ids() or torch.cuda.device_count() == 0):
                raise DeviceError(
                    f"device={device!r} but denoiser actor sees no GPU (ray.get_gpu_ids()={ray.get_gpu_ids()}, "
                    f"torch.cuda.device_count()={torch.cuda.device_count()}); give each actor a GPU with "
                    "ray.num_gpus=1 on a cluster with GPUs, or set device=cpu"
                )
            self._denoiser = LocalDenoiser.from_checkpoint(checkpoint, cfg, device=device, expect_digest=digest,
                                                           warn=False, guide_map=guide_map)
            if cfg.eval.in_flight > 1:  # concurrent segments of several trees run together (a threaded actor)
                from fmctd_dist.denoiser.pool import PooledDenoiser

                self._pool = PooledDenoiser(self._denoiser, cfg.ray.micro_batch)
            self._info["device"] = str(self._denoiser.device)
            # an emulated-bf16 warning goes back to the job process, which says it (actors print nothing)
            self._info["warning"] = (bf16_warning(self._denoiser.device, "diffusion.precision")
                                     if cfg.diffusion.precision == "bf16" else None)
        except FmctdError as e:
            self._error = e

    def info(self) -> dict[str, Any]:
        """What this actor sees: gpu_ids, cuda_device_count, device, torch_threads, niceness, pid, node."""
        if self._error is not None:
            raise self._error
        return {**self._info, **where()}

    def denoise(self, batch: DenoiseBatch, micro_batch: int) -> DenoiseResult:
        """One segment: whole micro-batches of ``micro_batch`` jobs in job order (the caller cut and padded
        them), run one micro-batch per model call as the caller cut them."""
        if self._error is not None:
            raise self._error
        if self._pool is not None and micro_batch == self._pool.micro_batch:
            return self._pool.denoise(batch)  # bitwise what the segment gets alone (docs/design.md §6)
        return self._denoiser.denoise(batch, micro_batch=micro_batch)


@dataclass
class _Shard:
    """One segment in flight (a call): which jobs it holds and where it was sent."""

    index: int  # segment number in job order
    batch: DenoiseBatch  # whole micro-batches of M jobs (already a copy)
    keep: int  # real (unpadded) jobs
    micro_batches: int  # how many: its call may take call_timeout_s for each
    actor: int = -1
    deadline: float = 0.0
    tried: set = field(default_factory=set)


class RayDenoiser:
    """Denoiser protocol over actor handles; safe to share between threads (trees)."""

    def __init__(self, actors: list, micro_batch: int, call_timeout_s: float = 300.0, max_restarts: int = 0):
        if not actors:
            raise DeviceError("RayDenoiser needs at least one denoiser actor; set ray.denoiser_actors >= 1")
        if micro_batch < 1:
            raise ValueError(f"micro_batch={micro_batch} must be >= 1")
        self.actors = list(actors)
        self.micro_batch = micro_batch
        self.call_timeout_s = call_timeout_s
        # an actor may fail this many times in a row (it restarts max_restarts times) before it counts as dead
        self.max_failures = max_restarts + 1
        self._lock = threading.Lock()
        self._failures = [0] * len(actors)  # consecutive failures per actor
        self._inflight = [0] * len(actors)
        self._rr = 0
        self._last_error = ""

    @classmethod
    def from_config(cls, actors: list, cfg: Config) -> "RayDenoiser":
        return cls(actors, cfg.ray.micro_batch, cfg.ray.call_timeout_s, cfg.ray.max_restarts)

    def live_actors(self) -> int:
        with self._lock:
            return sum(f < self.max_failures for f in self._failures)

    def denoise(self, batch: DenoiseBatch) -> DenoiseResult:
        """x_out, x0 [B, T, D]; bitwise equal to LocalDenoiser(micro_batch=M) on the same batch."""
        b, m = batch.size, self.micro_batch
        t, d = batch.x.shape[1:]
        if b == 0:
            empty = np.zeros((0, t, d), np.float32)
            return DenoiseResult(empty, empty.copy(), stats={"micro_batches": 0, "actors": len(self.actors)})
        cut = micro_batch_indices(b, m)
        # one contiguous segment of micro-batches per live actor (fewer when there are fewer micro-batches)
        shards = []
        for i, g in enumerate(np.array_split(np.arange(len(cut)), max(1, min(len(cut), self.live_actors())))):
            keep = min(b, (g[-1] + 1) * m) - g[0] * m  # real jobs: only the batch's last micro-batch is padded
            shards.append(_Shard(i, batch.take(np.concatenate([cut[j] for j in g])), keep, len(g)))
        xs: list[np.ndarray | None] = [None] * len(shards)
        x0s: list[np.ndarray | None] = [None] * len(shards)
        seconds, retries, used = 0.0, 0, set()
        pending: dict[Any, _Shard] = {}
        for s in shards:
            pending[self._submit(s)] = s
        while pending:
            now = time.monotonic()
            wait_s = max(0.0, min(s.deadline for s in pending.values()) - now)
            ready, _ = ray.wait(list(pending), num_returns=1, timeout=wait_s)
            if ready:
                ref = ready[0]
                s = pending.pop(ref)
                try:
                    res: DenoiseResult = ray.get(ref)
                except (RayActorError, GetTimeoutError, ObjectLostError, OwnerDiedError, NodeDiedError,
                        WorkerCrashedError) as e:  # the actor, its process or its node (with the result) is gone
                    self._failed(s, e)
                    retries += 1
                    pending[self._submit(s)] = s
                    continue
                except RayTaskError as e:  # a real error in the job (bad levels, bad checkpoint): not a fault
                    self._done(s.actor, ok=True)
                    raise unwrap_ray_error(e) from None
                self._done(s.actor, ok=True)
                used.add(s.actor)
                xs[s.index], x0s[s.index] = res.x[: s.keep], res.x0[: s.keep]
                seconds += float(res.denoise_time_s)
            now = time.monotonic()
            for ref, s in list(pending.items()):
                if s.deadline <= now:  # too slow: run it elsewhere, drop the late answer
                    del pending[ref]
                    try:
                        ray.cancel(ref)
                    except Exception:  # noqa: BLE001 - cancelling is best effort
                        pass
                    self._failed(s, TimeoutError(f"no answer within ray.call_timeout_s={self.call_timeout_s} "
                                                    f"x {s.micro_batches} micro-batch(es)"))
                    retries += 1
                    pending[self._submit(s)] = s
        return DenoiseResult(
            x=np.concatenate(xs), x0=np.concatenate(x0s), denoise_time_s=seconds, retries=retries,
            stats={"micro_batches": len(cut), "padded_jobs": len(cut) * m - b, "calls": len(shards),
                   "actors_used": len(used)},
        )

    def _submit(self, s: _Shard) -> Any:
        with self._lock:
            live = [i for i, f in enumerate(self._failures) if f < self.max_failures]
            if not live:
                raise DeviceError(
                    f"all {len(self.actors)} denoiser actors died (each failed {self.max_failures} time(s) in a "
                    f"row); last error: {self._last_error}; check the actors' logs "
                    "(`ray logs`), memory and ray.max_restarts"
                )
            n = len(self.actors)
            # prefer actors that have not failed this shard, then healthy ones, then the least loaded
            order = sorted(live, key=lambda i: (i in s.tried, self._failures[i] > 0, self._inflight[i],
                                                (i - self._rr) % n))
            a = order[0]
            self._rr = (a + 1) % n
            self._inflight[a] += 1
        s.actor, s.deadline = a, time.monotonic() + self.call_timeout_s * s.micro_batches
        s.tried.add(a)
        return self.actors[a].denoise.remote(s.batch, self.micro_batch)

    def _failed(self, s: _Shard, error: BaseException) -> None:
        with self._lock:
            self._inflight[s.actor] -= 1
            self._failures[s.actor] += 1
            self._last_error = f"{type(error).__name__}: {str(error).splitlines()[0] if str(error) else ''}"

    def _done(self, actor: int, ok: bool) -> None:
        with self._lock:
            self._inflight[actor] -= 1
            if ok:
                self._failures[actor] = 0


class DenoiserPool:
    """The denoiser actors of one run; hands out :class:`RayDenoiser` views that share them. Several trees
    may use them at once: a micro-batch's bits do not depend on who else is queued."""

    def __init__(self, actors: list, cfg: Config, infos: list[dict[str, Any]]):
        self.actors = actors
        self.cfg = cfg
        self.infos = infos  # per actor: gpu_ids, cuda_device_count, device, pid, node_id

    @classmethod
    def create(cls, prepared, n: int | None = None, timeout_s: float = 300.0) -> "DenoiserPool":
        """Start ``n`` (default ``ray.denoiser_actors``, 0 = :func:`auto_actors`) actors and wait until each
        has loaded the model (with ``prepared.guide_map``, the family's function, passed by reference).

        Raises the actors' own CheckpointError/DeviceError (not a RayTaskError).
        """
        cfg = prepared.cfg
        n = cfg.ray.denoiser_actors if n is None else n
        n = auto_actors(cfg.ray) if n == 0 else n
        if n < 1:
            raise DeviceError(f"ray.denoiser_actors={n} must be >= 1")
        opts = {"num_cpus": cfg.ray.num_cpus, "num_gpus": cfg.ray.num_gpus,
                "max_restarts": cfg.ray.max_restarts, "max_task_retries": 0,
                # eval.in_flight trees per actor send segments at once: a threaded actor pools them
                "max_concurrency": max(1, 2 * cfg.eval.in_flight) if cfg.eval.in_flight > 1 else 1}
        # max_task_retries=0: RayDenoiser re-routes a failed micro-batch itself (to a live actor, counted)
        actors = [DenoiserActor.options(**opts).remote(str(prepared.checkpoint), prepared.checkpoint_digest,
                                                       cfg.to_dict(), prepared.device, prepared.guide_map)
                  for _ in range(n)]
        pool = cls(actors, cfg, [])
        try:
            pool.infos = ray.get([a.info.remote() for a in actors], timeout=timeout_s)
        except RayTaskError as e:
            pool.shutdown()
            raise unwrap_ray_error(e) from None
        except GetTimeoutError:
            pool.shutdown()
            raise DeviceError(
                f"{n} denoiser actor(s) with num_cpus={cfg.ray.num_cpus}, num_gpus={cfg.ray.num_gpus} did not start "
                f"within {timeout_s:.0f}s; the cluster has {ray.cluster_resources()} -- lower ray.denoiser_actors "
                "or the per-actor resources"
            ) from None
        return pool

    def denoiser(self) -> RayDenoiser:
        return RayDenoiser.from_config(self.actors, self.cfg)

    def shutdown(self) -> None:
        kill_quietly(self.actors)


def kill_quietly(actors: list) -> None:
    """Kill every actor of ``actors`` that is still alive."""
    for a in actors:
        try:
            ray.kill(a, no_restart=True)
        except Exception:  # noqa: BLE001 - already gone
            pass


def where() -> dict[str, Any]:
    """Where this process runs: pid and Ray node id (what a fault test kills)."""
    return {"pid": os.getpid(), "node_id": ray.get_runtime_context().get_node_id()}
