"""LocalDenoiser: the Denoiser protocol in-process (torch model on cpu or cuda).

Jobs are cut in job order into micro-batches of exactly ``micro_batch`` jobs (the last
padded with copies of its last job), so every model call has the same shapes whatever the
batch size, and a job's bits do not depend on how the tree owner batched it (docs/design.md §7).
The Ray actors wrap this same class, so one process and N actors run identical code.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch

from fmctd_dist.config import Config, DiffusionConfig
from fmctd_dist.denoiser.protocol import DenoiseBatch, DenoiseResult, micro_batch_indices
from fmctd_dist.denoiser.runtime import runtime_model
from fmctd_dist.device import resolve_device
from fmctd_dist.diffusion.model import DFTransformer
from fmctd_dist.diffusion.sampler import make_consts, run_levels

__all__ = ["LocalDenoiser", "resolve_device"]


class LocalDenoiser:
    """Runs DenoiseBatch jobs with a DFTransformer; a pure function of the batch."""

    def __init__(self, model: DFTransformer, diffusion_cfg: DiffusionConfig, device: str = "cpu",
                 micro_batch: int = 64, digest: str = "", guide_map: torch.nn.Module | None = None,
                 warn: bool = True):
        if micro_batch < 1:
            raise ValueError(f"micro_batch={micro_batch} must be >= 1")
        self.device = resolve_device(device)
        self.model = model.to(self.device).eval()
        self.model.requires_grad_(False)  # guidance needs d/dx only, never parameter grads
        # what runs the network: fp32 eager (reference), bf16 weights + autocast, and/or compiled
        self.precision, self.compiled = diffusion_cfg.precision, diffusion_cfg.compile
        self.net = runtime_model(self.model, self.precision, self.compiled, warn)
        self.consts = make_consts(diffusion_cfg, self.device)
        self.guidance_path = diffusion_cfg.guidance_path  # through the whole x0 estimate, or its network branch
        self.boundary_weight = float(diffusion_cfg.boundary_guidance)  # guided jobs' boundary-continuity term
        self.micro_batch = micro_batch
        self.digest = digest  # checkpoint digest ("" for an in-memory model)
        # the space guidance measures distances in (None: the frame state; the visual maze: estimated x, y)
        self.guide_map = None if guide_map is None else guide_map.to(self.device).eval().requires_grad_(False)

    @classmethod
    def from_checkpoint(cls, path: str | Path, cfg: Config, device: str | None = None,
                        micro_batch: int | None = None, expect_digest: str | None = None, warn: bool = True,
                        guide_map: Callable[[Config, dict[str, Any]], torch.nn.Module] | None = None
                        ) -> "LocalDenoiser":
        """Load and verify a checkpoint against ``cfg`` (device/micro_batch default to cfg's); ``warn=False``:
        no emulated-bf16 warning on stderr (Ray actors return it in their info instead). ``guide_map``: the
        family's ``guide_map(cfg, manifest)`` when it guides in another space than the state
        (``fmctd_dist.families.guide_map``; the visual maze), asked once with the checkpoint's manifest."""
        from fmctd_dist.diffusion.checkpoint import load_checkpoint

        model, manifest = load_checkpoint(path, cfg, expect_digest)
        return cls(model, cfg.diffusion, device or cfg.device, micro_batch or cfg.ray.micro_batch, manifest["digest"],
                   None if guide_map is None else guide_map(cfg, manifest), warn)

    def denoise(self, batch: DenoiseBatch, micro_batch: int | None = None) -> DenoiseResult:
        """x_out, x0 [B, T, D] float32 for B jobs; denoise_time_s = wall time of the model work.

        ``micro_batch`` overrides this denoiser's cut for one call: a Ray actor runs a segment with the
        cut of the pool that sent it, so the model sees the same shapes as in any other run."""
        self._check(batch)
        b, m = batch.size, micro_batch or self.micro_batch
        xs, x0s, seconds, calls, padded = [], [], 0.0, {}, 0
        for lo, idx in zip(range(0, b, m), micro_batch_indices(b, m)):
            pad = lo + m - min(lo + m, b)
            padded += pad
            x, x0, dt = self._run(batch.take(idx), calls)
            xs.append(x[: m - pad])
            x0s.append(x0[: m - pad])
            seconds += dt
        t, d = batch.x.shape[1:]
        empty = np.zeros((0, t, d), np.float32)
        return DenoiseResult(
            x=np.concatenate(xs) if xs else empty,
            x0=np.concatenate(x0s) if x0s else empty,
            denoise_time_s=seconds,
            stats={"micro_batches": len(xs), "padded_jobs": padded, "model_calls": calls.get("model_calls", 0),
                   "device": str(self.device), "precision": self.precision, "compiled": self.compiled},
        )

    def _run(self, mb: DenoiseBatch, stats: dict) -> tuple[np.ndarray, np.ndarray, float]:
        dev = self.device
        t0 = time.perf_counter()
        x, x0 = run_levels(
            self.net, self.consts,
            torch.as_tensor(mb.x, dtype=torch.float32, device=dev),
            torch.as_tensor(mb.levels, dtype=torch.long, device=dev),
            torch.as_tensor(mb.scale, dtype=torch.float32, device=dev),
            torch.as_tensor(mb.start, dtype=torch.float32, device=dev),
            torch.as_tensor(mb.goal, dtype=torch.float32, device=dev),
            stats,
            None if mb.noise_seed is None else torch.as_tensor(mb.noise_seed, dtype=torch.long),
            self.guidance_path,
            self.compiled,
            None if mb.guide_mask is None else torch.as_tensor(mb.guide_mask, dtype=torch.float32, device=dev),
            self.guide_map,
            self.boundary_weight,
        )
        x, x0 = x.cpu().numpy(), x0.cpu().numpy()  # waits for the device
        return x, x0, time.perf_counter() - t0

    def _check(self, batch: DenoiseBatch) -> None:
        d = batch.x.shape[-1]
        if d != self.model.token_dim:
            raise ValueError(f"x has token dim {d} but the model expects {self.model.token_dim}")
        if batch.guide_mask is not None and d % batch.guide_mask.shape[1]:
            raise ValueError(f"guide_mask covers {batch.guide_mask.shape[1]} state dims, which do not divide "
                             f"the token dim {d} into frames")
        lv = batch.levels
        if lv.size and (lv.min() < 0 or lv.max() > self.consts.levels):
            raise ValueError(f"levels must lie in [0, {self.consts.levels}], got [{lv.min()}, {lv.max()}]")
        step = np.diff(lv, axis=1)  # [B, R, T]
        if (step > 0).any() and batch.noise_seed is None:
            raise ValueError("levels increase from one row to the next (re-noising) but the batch has no noise_seed")
        if ((step > 0).any(axis=2) & (step < 0).any(axis=2)).any():
            raise ValueError("a job's row both re-noises some tokens and denoises others; split it into two rows")
        if lv.size and (lv[:, :, 0] != 0).any():
            raise ValueError("token 0 is the clean context: its level must be 0 in every row")
