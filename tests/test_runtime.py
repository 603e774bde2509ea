"""Inference options (diffusion.precision, diffusion.compile): close to fp32 eager, guidance
gradients included, and bitwise invariant to how jobs are batched within one option."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from fmctd_dist.config import DiffusionConfig, load_config
from fmctd_dist.denoiser.local import LocalDenoiser
from fmctd_dist.denoiser.runtime import RuntimeModel, runtime_model
from fmctd_dist.diffusion.sampler import goal_reward
from fmctd_dist.families import hooks_for
from test_sampler import mixed_batch, tiny_model

pytestmark = pytest.mark.usefixtures("one_torch_thread")

BF16_RTOL = 0.05  # bf16 keeps 8 bits of mantissa: ~0.4% per op, a few % through a 2-layer net and a DDIM ladder


def options(precision: str = "fp32", compile: bool = False) -> DiffusionConfig:
    return dataclasses.replace(DiffusionConfig(), precision=precision, compile=compile)


def rel_err(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def guidance_grad(model: torch.nn.Module, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(x0_hat, d reward / d x_t) on a fixed batch: what guidance takes from the network."""
    g = torch.Generator().manual_seed(seed)
    x = torch.randn(6, 5, 20, generator=g).requires_grad_(True)
    t = torch.randint(0, 1000, (6, 5), generator=g)
    start, goal = torch.randn(6, 2, generator=g), torch.randn(6, 2, generator=g)
    x0 = model(x, t)
    (grad,) = torch.autograd.grad(goal_reward(x0, start, goal).sum(), x)
    return x0.detach().numpy(), grad.numpy()


def test_bf16_keeps_linear_weights_in_bf16_and_buffers_in_fp32():
    model = RuntimeModel(tiny_model(), "bf16")
    linear = [m for m in model.modules() if isinstance(m, torch.nn.Linear)]
    assert linear and {p.dtype for m in linear for p in m.parameters()} == {torch.bfloat16}
    assert all(b.dtype != torch.bfloat16 for b in model.buffers())  # sinusoidal frequencies stay exact
    assert model.token_dim == 20 and model(torch.zeros(1, 5, 20), torch.zeros(1, 5, dtype=torch.long)).dtype == \
        torch.float32


def test_bf16_x0_and_guidance_gradient_close_to_fp32():
    ref_x0, ref_grad = guidance_grad(tiny_model())
    x0, grad = guidance_grad(runtime_model(tiny_model(), "bf16"))
    assert rel_err(x0, ref_x0) < BF16_RTOL and rel_err(grad, ref_grad) < BF16_RTOL
    assert np.sign(grad).tolist() != np.zeros_like(grad).tolist()


def test_bf16_plans_close_and_bitwise_invariant_to_batching():
    batch = mixed_batch()
    ref = LocalDenoiser(tiny_model(), DiffusionConfig(), micro_batch=4).denoise(batch)
    den = LocalDenoiser(tiny_model(), options("bf16"), micro_batch=4)
    full = den.denoise(batch)
    assert full.stats["precision"] == "bf16"
    assert rel_err(full.x, ref.x) < BF16_RTOL
    for j in range(batch.size):  # within the option: a job's bits never depend on its micro-batch
        np.testing.assert_array_equal(den.denoise(batch.take(np.array([j]))).x[0], full.x[j])


@pytest.mark.slow
def test_compiled_matches_eager_and_is_bitwise_invariant_to_batching():
    """One compile (one micro-batch shape, grad mode): a few tens of seconds of inductor on CPU."""
    batch = mixed_batch(seed=2)
    ref = LocalDenoiser(tiny_model(), DiffusionConfig(), micro_batch=4).denoise(batch)
    den = LocalDenoiser(tiny_model(), options(compile=True), micro_batch=4)
    full = den.denoise(batch)
    assert full.stats["compiled"]
    np.testing.assert_allclose(full.x, ref.x, rtol=1e-4, atol=1e-4)
    unguided = np.flatnonzero(batch.scale == 0)
    assert unguided.size  # an unguided job alone (no guided neighbour) gives the same bits
    for j in (int(unguided[0]), int(np.flatnonzero(batch.scale != 0)[0])):
        np.testing.assert_array_equal(den.denoise(batch.take(np.array([j]))).x[0], full.x[j])


def test_options_are_config_and_recorded_in_rows():
    from fmctd_dist.evaluation.identity import config_hash

    base = load_config([])
    bf16 = load_config(["diffusion.precision=bf16"])
    assert config_hash(bf16) != config_hash(base) != config_hash(load_config(["diffusion.compile=true"]))
    from pathlib import Path

    from fmctd_dist.evaluation.grid import Prepared, provenance

    row = provenance(Prepared(bf16, Path("c"), "d" * 16, "cpu", config_hash(bf16), "sha"), 1)
    assert (row["precision"], row["compiled"]) == ("bf16", False)
    assert '"diffusion.precision": "bf16"' in row["config_json"]


def test_throughput_bench_cpu_clock_runs_and_refuses_more_threads(monkeypatch):
    """`bench_denoiser --throughput clock=cpu` (work per CPU second on a shared machine) prints its
    table; with more than one torch thread process time is not one core's time, so it is refused."""
    from conftest import load_job

    bench = load_job("bench_denoiser")
    monkeypatch.setattr(bench, "peak_flops", lambda *a, **k: (1e9, 256))  # skip the square matmuls
    lines = bench.throughput(batches=(2,), tokens=(3,), options=("fp32", "bf16"), width=16, layers=1, reps=1,
                             clock="cpu")
    assert "clock cpu" in lines[0] and lines[-1].startswith("| 3 | 2 |")
    monkeypatch.setattr(torch, "get_num_threads", lambda: 2)
    with pytest.raises(SystemExit, match="one torch thread"):
        bench.throughput(batches=(2,), tokens=(3,), width=16, layers=1, reps=1, clock="cpu")


class _Map(torch.nn.Module):
    """A stand-in guide map (the visual maze's position estimator): frame -> 2-D point."""

    in_dim = 4

    def __init__(self):
        super().__init__()
        torch.manual_seed(1)
        self.lin = torch.nn.Linear(4, 2)

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        return torch.tanh(self.lin(z))


@pytest.mark.slow
@pytest.mark.parametrize("variant", ["mask", "network", "map"])
def test_compiled_step_matches_eager_guidance(variant):
    """The compiled guided estimate (forward + goal term + gradient as one graph) gives the eager
    autograd numbers for every guidance form the families use: object-wise masks (cubes), the
    network-branch path (v models) and a guide map (the visual maze's estimator)."""
    from fmctd_dist.diffusion.sampler import guided_estimate

    g = torch.Generator().manual_seed(3)
    x = torch.randn(4, 5, 20, generator=g)
    t = torch.randint(0, 1000, (4, 5), generator=g)
    scale = torch.tensor([0.0, 1.0, 2.0, 4.0])
    kw = {"mask": dict(guide_mask=(torch.rand(4, 2, generator=g) > 0.5).float()),
          "network": dict(guidance_path="network"), "map": dict(guide_map=_Map().eval().requires_grad_(False))}[variant]
    start, goal = torch.randn(4, 2, generator=g), torch.randn(4, 2, generator=g)
    if variant == "map":  # the map's space: start and goal are latent frames
        start, goal = torch.randn(4, 4, generator=g), torch.randn(4, 4, generator=g)
    model = tiny_model().requires_grad_(False)
    ref_x0, ref_grad = guided_estimate(model, x, t, scale, start, goal, **kw)
    compiled = runtime_model(tiny_model().requires_grad_(False), "fp32", compile=True)
    x0, grad = guided_estimate(compiled, x, t, scale, start, goal, **kw)
    np.testing.assert_allclose(x0.numpy(), ref_x0.numpy(), rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(grad.numpy(), ref_grad.numpy(), rtol=1e-4, atol=1e-6)
    assert grad[0].abs().max() == 0 and grad[1:].abs().max() > 0  # scale 0: no pull; others pulled


def test_compile_without_a_cxx_compiler_is_one_clear_error_before_anything_starts(monkeypatch):
    """diffusion.compile on a CPU needs g++/clang++ for inductor: without one, prepare() (what every job
    calls before an actor or episode starts) names the field and both fixes."""
    import shutil

    from fmctd_dist.errors import ConfigError
    from fmctd_dist.evaluation.grid import prepare

    monkeypatch.setattr(shutil, "which", lambda name: None)
    monkeypatch.delenv("CXX", raising=False)
    with pytest.raises(ConfigError, match=r"diffusion.compile=true.*apt-get install g\+\+.*diffusion.compile=false"):
        prepare(load_config(["diffusion.compile=true"]), hooks_for)
    from fmctd_dist.denoiser.runtime import check_compile

    check_compile(False, "cpu")  # off: nothing needed
    check_compile(True, "cuda")  # a GPU's kernels are triton's, not g++'s


def test_bf16_warning_only_where_the_cpu_emulates_it(capsys):
    """bf16 on a CPU without avx512_bf16 / amx_bf16 runs ~12x slower than fp32: one warning line naming the fix."""
    from fmctd_dist.device import bf16_warning, cpu_flags

    zen3 = "processor\t: 0\nflags\t\t: fpu sse2 avx avx2 fma\n"
    sapphire = "processor\t: 0\nflags\t\t: fpu avx2 avx512f avx512_bf16 amx_bf16\n"
    cpu = torch.device("cpu")
    assert cpu_flags(zen3) == {"fpu", "sse2", "avx", "avx2", "fma"}
    msg = bf16_warning(cpu, "train.precision", zen3)
    assert msg.startswith("warning: train.precision=bf16") and "train.precision=fp32" in msg
    assert bf16_warning(cpu, "train.precision", sapphire) is None
    assert bf16_warning(cpu, "train.precision", "no flags line") is None  # unknown: no warning
    assert bf16_warning(torch.device("meta"), "diffusion.precision", zen3) is None  # only CPUs
    # the inference path says it too, where this machine emulates bf16
    runtime_model(tiny_model(), "bf16")
    emulated = bf16_warning(cpu, "diffusion.precision") is not None
    assert ("diffusion.precision=bf16" in capsys.readouterr().err) == emulated


def test_peak_matmul_stays_within_its_time_budget():
    """The peak's matmul side stops growing once the next size would pass the budget, so an emulated
    dtype (bf16 without avx512_bf16/amx_bf16) costs seconds instead of minutes (session 13's CI)."""
    from conftest import load_job

    bench = load_job("bench_denoiser")
    flops, n = bench.peak_flops(torch.float32, n_max=2048, reps=1, budget_s=0.0)
    assert n == 256 and flops > 0
    assert bench.peak_flops(torch.float32, n_max=512, reps=1, budget_s=1e9)[1] == 512


def test_bench_denoiser_quality_mode_names_an_unknown_word():
    """The quality mode takes checkpoint dirs and samples=N; any other key=value is one clear error."""
    from conftest import load_job

    bench = load_job("bench_denoiser")
    with pytest.raises(SystemExit, match=r"unknown \['sample'\]; the quality mode takes samples=N"):
        bench.main(["sample=100", "checkpoints/pointmaze-medium-h5"])
