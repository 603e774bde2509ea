"""Device resolution: the config names the device, and a missing GPU is an error, never a fallback.

A silent CPU fallback would make a "GPU" benchmark or evaluation quietly run on CPU
(docs/design.md §12), so ``cuda`` without a visible GPU raises :class:`DeviceError`.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator

import torch

from fmctd_dist.config import DEVICES
from fmctd_dist.errors import DeviceError, did_you_mean


def resolve_device(name: str) -> torch.device:
    """Map "cpu" | "cuda" | "cuda:N" | "auto" to a torch.device; "auto" takes cuda when there is one."""
    if name == "cpu":
        return torch.device("cpu")
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" or name.startswith("cuda:"):
        if not torch.cuda.is_available():
            raise DeviceError(
                f"device={name!r} but torch sees no GPU (torch {torch.__version__}, cuda build "
                f"{torch.version.cuda}, CUDA_VISIBLE_DEVICES={os.environ.get('CUDA_VISIBLE_DEVICES', '<unset>')!r}); "
                "set device=cpu, or device=auto to use a GPU only where there is one"
            )
        dev = torch.device(name)
        if dev.index is not None and dev.index >= torch.cuda.device_count():
            n = torch.cuda.device_count()
            raise DeviceError(f"device={name!r} but only {n} GPU(s) are visible; use device=cuda")
        return dev
    raise DeviceError(
        f"device={name!r} is not known{did_you_mean(name, DEVICES)}; choose one of: {', '.join(DEVICES)}"
    )


def set_threads(n: int) -> None:
    """Torch intra-op threads for this process; 0 keeps torch's default (one per core).

    On a machine whose cores are busy with other jobs, torch's spinning threads make every
    call several times slower: jobs take ``train.threads`` / ``eval.threads`` = 1 there.
    """
    if n > 0:
        torch.set_num_threads(n)


@contextlib.contextmanager
def torch_threads(n: int) -> Iterator[None]:
    """Run a block with ``n`` torch threads, then give the old count back.

    Small per-step forwards (the ant expert in data generation) are fastest, and their
    float results independent of the machine's core count, on one thread.
    """
    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)


# CPU flags under which oneDNN runs bf16 matmuls in hardware; without them torch.autocast(bfloat16)
# still works but emulates them (AMD Zen 3 EPYC: 11-12.5x slower per training step than fp32, results 6.3)
NATIVE_BF16_FLAGS = ("avx512_bf16", "amx_bf16")


def cpu_flags(cpuinfo: str | None = None) -> set[str] | None:
    """The CPU's feature flags from /proc/cpuinfo (or the given text); None where there is none to read."""
    if cpuinfo is None:
        try:
            cpuinfo = open("/proc/cpuinfo").read()
        except OSError:
            return None
    for line in cpuinfo.splitlines():
        if line.startswith("flags"):
            return set(line.split(":", 1)[1].split())
    return None


def bf16_warning(device: torch.device, field: str, cpuinfo: str | None = None) -> str | None:
    """A one-line warning when ``field``=bf16 would run emulated on this CPU, else None.

    Not an error: the bits are as valid as on a CPU with native bf16, only far slower, and a
    machine whose flags cannot be read is given the benefit of the doubt.
    """
    if device.type != "cpu":
        return None
    flags = cpu_flags(cpuinfo)
    if flags is None or flags & set(NATIVE_BF16_FLAGS):
        return None
    return (f"warning: {field}=bf16 on a CPU without {' or '.join(NATIVE_BF16_FLAGS)}: torch emulates bf16 here "
            "(measured 11-12.5x slower per training step than fp32 on an AMD Zen 3 EPYC; "
            "jobs/bench/bench_train_step.py); "
            f"set {field}=fp32")


def warn_bf16(device: torch.device, field: str) -> None:
    """Print :func:`bf16_warning` to stderr if it applies."""
    msg = bf16_warning(device, field)
    if msg:
        print(msg, file=sys.stderr, flush=True)
