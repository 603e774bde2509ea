"""Object-wise guidance (issue 20): a per-job mask over the frame's state dims decides which dims
the goal term of the guidance sees. No mask and an all-ones mask are the same bits; a mask on
cube 0 makes cube 1's goal irrelevant; masked jobs keep the micro-batch contract (docs/design.md §7).
The Ray pool's sharding of masked batches is checked in test_ray_determinism.py."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fmctd_dist.config import DiffusionConfig, ModelConfig
from fmctd_dist.denoiser.local import LocalDenoiser
from fmctd_dist.denoiser.protocol import DenoiseBatch, concat_batches
from fmctd_dist.diffusion.model import DFTransformer
from fmctd_dist.diffusion.sampler import goal_reward, make_consts, run_levels, transition
from fmctd_dist.diffusion.schedule import PyramidSchedule

pytestmark = pytest.mark.usefixtures("one_torch_thread")

CFG = DiffusionConfig()
CUBE0 = np.array([1, 1, 1, 0, 0, 0], np.float32)  # 2 cubes x xyz: guide cube 0 only


class Affine(torch.nn.Module):
    """x0_hat = A x + c t: differentiable, any token width."""

    def forward(self, x: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        return 0.8 * x + 1e-3 * t.to(x.dtype)[..., None]


def tiny_model() -> DFTransformer:
    torch.manual_seed(0)
    return DFTransformer.from_config(ModelConfig(width=32, layers=2, heads=2, ff=64), 5).eval()


def jobs(b: int, p: int, d: int, fs: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((b, p + 1, d * fs)).astype(np.float32)
    start = rng.standard_normal((b, d)).astype(np.float32)
    goal = rng.standard_normal((b, d)).astype(np.float32)
    x[:, 0] = np.tile(start, (1, fs))
    return x, start, goal


def t(*arrays):
    return tuple(torch.as_tensor(a) for a in arrays)


# ---------------------------------------------------------------- no mask == all ones


def test_all_ones_mask_gives_the_bits_of_no_mask():
    p = 4
    x, start, goal = jobs(3, p, 2, 10, seed=1)
    lv = np.stack([PyramidSchedule(p).full()] * 3)
    scale = np.array([0.5, 2.0, 0.0], np.float32)
    model, consts = tiny_model(), make_consts(CFG)
    none = run_levels(model, consts, *t(x, lv, scale, start, goal))
    ones = run_levels(model, consts, *t(x, lv, scale, start, goal), guide_mask=torch.ones(3, 2))
    assert torch.equal(none[0], ones[0]) and torch.equal(none[1], ones[1])
    den = LocalDenoiser(model, CFG, micro_batch=2)
    a = den.denoise(DenoiseBatch(x, lv, scale, start, goal))
    b = den.denoise(DenoiseBatch(x, lv, scale, start, goal, guide_mask=np.ones((3, 2), np.float32)))
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.x0, b.x0)
    np.testing.assert_array_equal(a.x, none[0].numpy())


# ---------------------------------------------------------------- a mask on cube 0 ignores cube 1's goal


def test_mask_on_cube_0_ignores_cube_1s_goal():
    p, fs = 4, 2
    x, start, goal = jobs(1, p, 6, fs, seed=3)
    other = goal.copy()
    other[:, 3:] += np.array([5.0, -3.0, 2.0], np.float32)  # cube 1 wants somewhere else entirely
    mask = torch.as_tensor(CUBE0[None])

    def grad(g, m, est=x):
        x0 = torch.as_tensor(est).clone().requires_grad_(True)
        (out,) = torch.autograd.grad(goal_reward(x0, torch.as_tensor(start), torch.as_tensor(g), m).sum(), x0)
        return out

    assert torch.equal(grad(goal, mask), grad(other, mask))
    assert not torch.equal(grad(goal, None), grad(other, None))
    off = x.copy()
    off[:, 0] += 0.3  # an x0 estimate whose context is off the observed start
    g = grad(goal, mask, off).reshape(1, -1, 6)
    assert (g[:, fs:, 3:] == 0).all()  # plan frames: no pull on cube 1 ...
    assert (g[:, :fs, 3:] != 0).any()  # ... while the start term still holds every cube's context

    lv = np.array([[[0, 30, 40, 50, 50], [0, 25, 35, 45, 50]]])
    a, b = torch.as_tensor(lv[:, 0]), torch.as_tensor(lv[:, 1])
    consts = make_consts(CFG)
    scale = torch.tensor([2.0])

    def step(g, m):
        return transition(Affine(), consts, torch.as_tensor(x), a, b, scale, torch.as_tensor(start),
                          torch.as_tensor(g), guide_mask=m)[0]

    assert torch.equal(step(goal, mask), step(other, mask))
    assert not torch.equal(step(goal, None), step(other, None))
    unguided = transition(Affine(), consts, torch.as_tensor(x), a, b, torch.zeros(1), torch.as_tensor(start),
                          torch.as_tensor(goal))[0]
    assert not torch.equal(step(goal, mask), unguided)  # cube 0 is still pulled


# ---------------------------------------------------------------- batching contract


def masked_batch(p: int = 4) -> DenoiseBatch:
    """Masked and unmasked parts with different R, joined as the Ray pool / cross-tree batching would."""
    sched = PyramidSchedule(p)
    x, start, goal = jobs(5, p, 2, 10, seed=4)
    m = np.array([[1, 0], [0, 1], [1, 0]], np.float32)
    parts = [
        DenoiseBatch(x[:3], np.stack([sched.expansion(1)] * 3), np.array([1.0, 2.0, 4.0], np.float32),
                     start[:3], goal[:3], guide_mask=m),
        DenoiseBatch(x[3:], np.stack([sched.simulation(1)] * 2), np.array([2.0, 0.5], np.float32),
                     start[3:], goal[3:]),
    ]
    return concat_batches(parts)


def test_masked_jobs_keep_the_micro_batch_contract():
    batch = masked_batch()
    np.testing.assert_array_equal(batch.guide_mask[3:], np.ones((2, 2), np.float32))  # unmasked part: all ones
    den = LocalDenoiser(tiny_model(), CFG, micro_batch=2)
    full = den.denoise(batch)
    for j in range(batch.size):
        alone = den.denoise(batch.take(np.array([j])))
        assert alone.x.shape[0] == 1
        np.testing.assert_array_equal(alone.x[0], full.x[j])
        np.testing.assert_array_equal(alone.x0[0], full.x0[j])
    tail = batch.take(np.arange(3, 5))
    plain = DenoiseBatch(tail.x, tail.levels, tail.scale, tail.start, tail.goal)  # the same jobs, no mask at all
    np.testing.assert_array_equal(den.denoise(plain).x, full.x[3:])
    flipped = DenoiseBatch(batch.x, batch.levels, batch.scale, batch.start, batch.goal,
                           guide_mask=1.0 - batch.guide_mask)
    assert not np.array_equal(den.denoise(flipped).x[:3], full.x[:3])  # the mask does act


def test_mask_travels_with_take_and_is_shape_checked():
    batch = masked_batch()
    sub = batch.take(np.array([4, 0]))
    np.testing.assert_array_equal(sub.guide_mask, batch.guide_mask[[4, 0]])
    with pytest.raises(AssertionError, match="guide_mask"):
        DenoiseBatch(batch.x, batch.levels, batch.scale, batch.start, batch.goal, guide_mask=np.ones((5, 3)))
    with pytest.raises(ValueError, match="guide_mask"):
        LocalDenoiser(tiny_model(), CFG).denoise(
            DenoiseBatch(batch.x, batch.levels, batch.scale, np.zeros((5, 3), np.float32),
                         np.zeros((5, 3), np.float32), guide_mask=np.ones((5, 3), np.float32)))
