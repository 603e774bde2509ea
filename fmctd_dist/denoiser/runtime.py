"""How a denoiser runs its network: fp32 eager (the reference), bf16, and/or torch.compile.

98-100% of planning time is inside the network, so these are the speed levers
(``diffusion.precision``, ``diffusion.compile``; issue 22). Each keeps the model's interface
``(x [B, T, D] float32, t [B, T]) -> x0_hat [B, T, D] float32``, so the sampler never branches.

- ``bf16``: linear and conv *parameters* are stored in bfloat16 once (no per-call weight casts) and the
  forward runs under ``torch.autocast(bfloat16)``, which feeds matmuls and convolutions bf16
  and keeps normalisations in fp32. Buffers (the sinusoidal frequencies, v's sqrt(alphabar)
  tables) stay fp32: a bf16 frequency times a timestep of 999 would be off by radians.
- ``compile``: ``torch.compile(dynamic=False)``. Micro-batches have one shape, so there is one
  graph per (shape, grad mode). A compiled graph's bits may depend on the grad mode, so a
  compiled denoiser runs every transition through the guidance (grad) path, guided or not,
  which keeps a job's bits independent of the micro-batch it lands in (design §4).

Within one option a plan stays a pure function of (config, checkpoint, seed); across options
the bits differ (bf16 by ~1e-2 relative), which is why the option is part of the config hash.
"""

from __future__ import annotations

import torch
from torch import nn

PRECISIONS = ("fp32", "bf16")  # same names as config.PRECISIONS
# Layers whose parameters are stored in bf16; normalisations keep fp32 parameters (CPU layer/group
# norm take bf16 or fp32 input with fp32 parameters, and autocast runs them in fp32 anyway).
BF16_LAYERS = (nn.Linear, nn.Conv1d)


class RuntimeModel(nn.Module):
    """Wraps a network for inference at ``precision``; float32 in, float32 out."""

    def __init__(self, model: nn.Module, precision: str = "fp32"):
        super().__init__()
        if precision not in PRECISIONS:
            raise ValueError(f"precision={precision!r} is not one of {PRECISIONS}")
        self.model = model
        self.precision = precision
        if precision == "bf16":
            for m in model.modules():
                if isinstance(m, BF16_LAYERS):
                    for p in m.parameters(recurse=False):
                        p.data = p.data.to(torch.bfloat16)
        # carried through so that samplers and checkpoints see the wrapped model's identity
        for name in ("kind", "token_dim", "n_tokens", "param"):
            if hasattr(model, name):
                setattr(self, name, getattr(model, name))

    def forward(self, x: torch.Tensor, t: torch.Tensor, **kw) -> torch.Tensor:
        if self.precision == "fp32":
            return self.model(x, t, **kw)
        with torch.autocast(x.device.type, dtype=torch.bfloat16):
            out = self.model(x, t, **kw)
        return out.float()


def runtime_model(model: nn.Module, precision: str = "fp32", compile: bool = False) -> nn.Module:
    """``model`` (eval mode, no parameter grads) prepared for inference; fp32 eager returns it as is."""
    if precision == "fp32" and not compile:
        return model
    wrapped: nn.Module = RuntimeModel(model, precision)
    return torch.compile(wrapped, dynamic=False) if compile else wrapped
