"""CPU seconds per training step, fp32 against bf16 autocast, on this machine (docs/results.md 6.3).

    python jobs/bench/bench_train_step.py                 # 6 x 128 model, 51 tokens x batch 128, one thread
    python jobs/bench/bench_train_step.py 11 256          # n_tokens, batch
    python jobs/bench/bench_train_step.py 11 256 compiled # also a torch.compile'd copy of the model (same init)

Whether bf16 pays depends on the CPU (native on avx512_bf16 / amx_bf16, emulated elsewhere), so
measure before choosing ``train.precision``: fp32 runs first and last, so drift shows. ``compiled``
adds both precisions through ``nn.Module.compile`` (its compile time is printed, not counted): the
lever issue 17 names as fused ops, measured here before any training option is built on it.
"""

from __future__ import annotations

import sys
import time

import torch

from fmctd_dist.cli import run
from fmctd_dist.device import NATIVE_BF16_FLAGS, cpu_flags
from fmctd_dist.diffusion.model import DFTransformer


def step_times(model: DFTransformer, opt: torch.optim.Optimizer, x: torch.Tensor, t: torch.Tensor,
               precision: str, steps: int = 4) -> list[float]:
    out = []
    for _ in range(steps):
        c0 = time.process_time()
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=precision == "bf16"):
            loss = model(x, t).float().pow(2).mean()
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        out.append(time.process_time() - c0)
    return out


def main(n_tokens: int = 51, batch: int = 128, compiled: bool = False) -> None:
    torch.set_num_threads(1)
    torch.manual_seed(0)
    model = DFTransformer(token_dim=20, n_tokens=n_tokens, width=128, layers=6)
    opt = torch.optim.AdamW(model.parameters(), lr=1e-4)
    x, t = torch.randn(batch, n_tokens, 20), torch.randint(0, 1000, (batch, n_tokens))
    flags = cpu_flags() or set()
    print(f"native bf16 flags: {sorted(flags & set(NATIVE_BF16_FLAGS)) or 'none'}; {n_tokens} tokens x batch {batch}")
    print("| precision | CPU s / step (each of 4) |\n|---|---|")
    for precision in ("fp32", "bf16", "fp32"):
        times = step_times(model, opt, x, t, precision)
        print(f"| {precision} | {' / '.join(f'{s:.3f}' for s in times)} |")
    if compiled:
        torch.manual_seed(0)
        twin = DFTransformer(token_dim=20, n_tokens=n_tokens, width=128, layers=6)
        twin.compile()  # in place: the state_dict keys stay the eager model's
        twin_opt = torch.optim.AdamW(twin.parameters(), lr=1e-4)
        for precision in ("fp32", "bf16"):
            c0 = time.process_time()
            step_times(twin, twin_opt, x, t, precision, steps=2)  # compiles (and recompiles for autocast)
            warm = time.process_time() - c0
            times = step_times(twin, twin_opt, x, t, precision)
            print(f"| {precision}, compiled ({warm:.0f} CPU s to compile) | {' / '.join(f'{s:.3f}' for s in times)} |")


if __name__ == "__main__":
    run(lambda args: main(*(int(a) for a in args if a != "compiled"), compiled="compiled" in args))
