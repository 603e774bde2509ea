"""How a denoiser runs its network: fp32 eager (the reference), bf16, and/or torch.compile.

98-100% of planning time is inside the network, so these are the speed levers
(``diffusion.precision``, ``diffusion.compile``; issue 22). Each keeps the model's interface
``(x [B, T, D] float32, t [B, T]) -> x0_hat [B, T, D] float32``, so the sampler never branches.

- ``bf16``: linear and conv *parameters* are stored in bfloat16 once (no per-call weight casts) and the
  forward runs under ``torch.autocast(bfloat16)``, which feeds matmuls and convolutions bf16
  and keeps normalisations in fp32. Buffers (the sinusoidal frequencies, v's sqrt(alphabar)
  tables) stay fp32: a bf16 frequency times a timestep of 999 would be off by radians.
- ``compile``: the whole guided estimate (forward, goal term and its gradient to the input,
  ``sampler.functional_guided_estimate``) is one ``torch.compile(dynamic=False, fullgraph=True)``
  graph, with inductor's C++ wrapper. Compiling the network alone and differentiating it with
  autograd outside gained nothing on this CPU (section 6 of docs/results.md): at batch 1 the time
  is per-op overhead of forward *and* backward, so both must be inside the graph. Micro-batches
  have one shape, so there is one graph per model and shape; each RuntimeModel compiles its own
  copy of the function, so dynamo's recompile limit counts shapes, not models, and hitting it
  is an error rather than a silent fall-back to eager (which would change a plan's bits). A
  compiled denoiser runs every transition through this guided graph, guided or not (scale 0),
  which keeps a job's bits independent of the micro-batch it lands in (docs/design.md §7).

Within one option a plan stays a pure function of (config, checkpoint, seed); across options
the bits differ (bf16 by ~1e-2 relative), which is why the option is part of the config hash.
"""

from __future__ import annotations

import os
import shutil
import types

import torch
from torch import nn

from fmctd_dist.device import warn_bf16
from fmctd_dist.diffusion.sampler import functional_guided_estimate
from fmctd_dist.errors import ConfigError

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


# the inference options by name, as the benches spell them ("bf16+compiled")
OPTION_NAMES = ("fp32", "bf16", "compiled")


def option_settings(name: str) -> tuple[str, bool]:
    """(diffusion.precision, diffusion.compile) of an option name: ``fp32``, ``bf16``, ``compiled`` or a
    '+' join of them."""
    parts = name.split("+")
    bad = [p for p in parts if p not in OPTION_NAMES]
    if bad:
        raise ConfigError(f"inference option {name!r}: {bad} not among {list(OPTION_NAMES)}; "
                          f"join options with '+', e.g. bf16+compiled")
    return ("bf16" if "bf16" in parts else "fp32"), "compiled" in parts


def option_overrides(name: str) -> list[str]:
    """Config overrides of an option name (:func:`option_settings`)."""
    precision, compile = option_settings(name)
    return ((["diffusion.precision=bf16"] if precision == "bf16" else [])
            + (["diffusion.compile=true"] if compile else []))


def check_compile(compile: bool, device: str) -> None:
    """``diffusion.compile`` on a CPU needs a C++ compiler (inductor writes C++ kernels and, here, its
    wrapper): without one, one clear error before any actor starts instead of a failure mid-plan."""
    if not compile or not device.startswith("cpu"):
        return
    if not any(shutil.which(c) for c in (os.environ.get("CXX", ""), "g++", "c++", "clang++") if c):
        raise ConfigError("diffusion.compile=true on device=cpu needs a C++ compiler for torch.compile's kernels "
                          "and none was found (g++, c++, clang++ or $CXX); install one (apt-get install g++) "
                          "or run with diffusion.compile=false")


# inductor options of the compiled step: the C++ wrapper calls kernels without Python in between
COMPILE_OPTIONS = {"cpp_wrapper": True}


def _fresh_copy(f: types.FunctionType) -> types.FunctionType:
    """``f`` with new code objects, nested ones included: dynamo keeps its graphs and counts
    recompiles per code object, so each copy has its own cache."""

    def fresh(code: types.CodeType) -> types.CodeType:
        consts = tuple(fresh(c) if isinstance(c, types.CodeType) else c for c in code.co_consts)
        return code.replace(co_consts=consts)

    return types.FunctionType(fresh(f.__code__), f.__globals__, f.__name__, f.__defaults__, f.__closure__)


class CompiledStep:
    """The guided estimate of one network as a compiled graph (``sampler.guided_estimate`` calls it)."""

    def __init__(self, net: nn.Module):
        torch._dynamo.config.fail_on_recompile_limit_hit = True  # never fall back to eager silently
        self.net = net
        # compiled as a plain function (a functools.partial would be compiled through one shared wrapper frame)
        self.fn = torch.compile(_fresh_copy(functional_guided_estimate), dynamic=False, fullgraph=True,
                                options=COMPILE_OPTIONS)

    def __call__(self, *args) -> tuple[torch.Tensor, torch.Tensor]:
        with torch.no_grad():  # one grad mode, one graph: no input requires grad, func.grad does the rest
            return self.fn(self.net, *args)


def runtime_model(model: nn.Module, precision: str = "fp32", compile: bool = False, warn: bool = True) -> nn.Module:
    """``model`` (eval mode, no parameter grads) prepared for inference; fp32 eager returns it as is.
    ``warn=False`` leaves the emulated-bf16 warning to the caller (a Ray actor prints nothing).

    With ``compile`` the returned module carries ``guided_estimate`` (a :class:`CompiledStep`);
    calling the module itself stays eager (the sampler takes the compiled step for every transition).
    """
    if precision == "fp32" and not compile:
        return model
    if precision == "bf16" and warn:
        warn_bf16(next(model.parameters()).device, "diffusion.precision")
    wrapped = RuntimeModel(model, precision)
    if compile:
        wrapped.guided_estimate = CompiledStep(wrapped)
    return wrapped
