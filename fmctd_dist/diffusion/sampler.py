"""Per-token DDIM (eta = 0) with goal guidance: the whole numerical core of a denoise job.

A job moves every token from level ``a`` to level ``b`` of the 50-level DDIM ladder in one
model call; a row of the scheduling matrix gives a per token. Tokens whose level does not
change are copied through bit for bit, so a tree node's state never drifts. Initial noise is
drawn by the tree owner; the only draws here are for rows whose levels go back up (RePaint's
resampling, the Diffuser's ``method.resample``), each from its job's own seed and row index,
which keeps a denoiser a pure function of its inputs (docs/design.md §6-7). Guidance follows the
authors' ``goal_guidance`` (docs/reference.md §5): the gradient of a tanh-squashed distance reward on x0_hat, taken
w.r.t. the noisy input through the network, shifts the predicted noise. With
``guidance_path="network"`` (diffusion.guidance_path) the gradient skips the skip path of a
v / v_offset model (see diffusion.model), which hands the reward's per-frame gradient to each
noisy frame unsmoothed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from fmctd_dist.config import DiffusionConfig
from fmctd_dist.diffusion.schedule import alphas_cumprod, level_timesteps, make_betas

GUIDANCE_GAIN = 1000.0 / 16.0  # authors: x1000 x batch/16, then a batch mean -> 62.5 per sample
START_WEIGHT = 20.0  # context frames pulled toward the start ("reconstruction guidance")
GOAL_WEIGHT = 1.0  # every plan frame pulled toward the goal ("reach it at any time")


@dataclass(frozen=True)
class SamplerConsts:
    """Lookup tables indexed by level k in [0, levels]. All [levels+1].

    t_in:          network timestep for a token at level k (level 0 -> stabilization-1)
    sqrt_ab_in:    sqrt(alphabar) of that timestep (the "from" side of a transition)
    sqrt_1m_ab_in: sqrt(1 - alphabar) of that timestep
    sqrt_ab_out:   sqrt(alphabar) of level k as a target (level 0 -> 1: clean)
    sqrt_1m_ab_out: sqrt(1 - alphabar) of level k as a target (level 0 -> 0)
    """

    t_in: torch.Tensor
    sqrt_ab_in: torch.Tensor
    sqrt_1m_ab_in: torch.Tensor
    sqrt_ab_out: torch.Tensor
    sqrt_1m_ab_out: torch.Tensor

    @property
    def levels(self) -> int:
        return int(self.t_in.shape[0]) - 1

    def to(self, device: torch.device | str) -> "SamplerConsts":
        return SamplerConsts(*(getattr(self, f).to(device) for f in self.__dataclass_fields__))


def make_consts(cfg: DiffusionConfig, device: torch.device | str = "cpu") -> SamplerConsts:
    """Tables from cfg's beta schedule (float64 math, stored float32 like the authors')."""
    ab = alphas_cumprod(make_betas(cfg.beta_schedule, cfg.timesteps, cfg.beta_start, cfg.beta_end))  # [timesteps]
    lt = level_timesteps(cfg.levels, cfg.timesteps)  # [levels+1], lt[0] = -1
    stab = cfg.stabilization - 1
    t_in = np.where(lt < 0, stab, lt)
    ab_in = ab[t_in]
    ab_out = np.where(lt < 0, 1.0, ab[np.maximum(lt, 0)])
    tables = (t_in, np.sqrt(ab_in), np.sqrt(1.0 - ab_in), np.sqrt(ab_out), np.sqrt(1.0 - ab_out))
    return SamplerConsts(
        torch.as_tensor(tables[0], dtype=torch.long),
        *(torch.as_tensor(v, dtype=torch.float32) for v in tables[1:]),
    ).to(device)


def goal_reward(x0: torch.Tensor, start: torch.Tensor, goal: torch.Tensor,
                mask: torch.Tensor | None = None, guide_map: nn.Module | None = None,
                boundary_weight: float = 0.0) -> torch.Tensor:
    """R = -mean_f w_f tanh(||xy_f - target_f|| / 2) per job, in normalised space.

    x0: [B, T, D] tokens (token 0 = context), start/goal: [B, d] -> R: [B]. Tokens un-stack
    into D/d frames of d numbers; context frames target ``start`` (w 20), plan frames ``goal`` (w 1).

    ``mask`` [B, d] (object-wise guidance, docs/reference.md §13): the plan frames' distance to the goal
    counts only the masked dims (a cube job: its chosen cube's xyz), so the other cubes' goals
    pull nothing. The start term keeps every dim: it is reconstruction guidance on the observed
    frames, and every cube's current position is observed, so it anchors the un-guided cubes
    where they are rather than steering any of them. Multiplying by 1.0 is exact in both passes,
    so an all-ones mask gives the bits of ``mask=None``.

    ``guide_map`` (a module with ``in_dim``: frame states [..., in_dim] -> [..., d']): distances
    are measured on mapped frames, start and goal, e.g. the visual maze's position estimator
    reading (x, y) off a latent (``visual/guide.py``); the gradient then flows through the map. A map with a
    ``penalty`` (mapped plan frames [B, F', d'] -> [B]; a maze's walls, ``maze/wall_guide.py``) has it subtracted.

    ``boundary_weight`` (diffusion.boundary_guidance; 0 = the authors' reward, bit for bit) adds
    -w * mean over token boundaries of ||(p_first - p_last) - (p_last - p_before)||: the step across
    each boundary (including context -> first plan token) should continue the step before it. Plans
    of our models jump at token boundaries while each token is smooth inside (docs/results.md §4);
    a second difference is zero for any steady motion, so the term does not pull the plan toward
    standing still, only toward a boundary step that looks like the inside ones.
    """
    b, t, dim = x0.shape
    if guide_map is not None:
        if mask is not None:
            raise ValueError("guide_mask and a guide map together are not supported: the mask's dims are the "
                             "frame state's, the distance is the map's")
        fs = dim // int(guide_map.in_dim)
        frames = guide_map(x0.reshape(b, t * fs, dim // fs))
        start, goal = guide_map(start), guide_map(goal)
        d = frames.shape[-1]
    else:
        d = start.shape[-1]
        fs = dim // d
        frames = x0.reshape(b, t * fs, d)
    target = torch.cat((start[:, None].expand(b, fs, d), goal[:, None].expand(b, (t - 1) * fs, d)), dim=1)
    w = torch.full((t * fs,), GOAL_WEIGHT, dtype=x0.dtype, device=x0.device)
    w[:fs] = START_WEIGHT
    diff = frames - target  # [B, F, d]
    if mask is not None:
        keep = torch.cat((torch.ones_like(mask)[:, None].expand(b, fs, d),
                          mask[:, None].expand(b, (t - 1) * fs, d)), dim=1).to(diff.dtype)
        diff = diff * keep
    dist = torch.linalg.vector_norm(diff, dim=-1)  # [B, F]
    reward = -(w * torch.tanh(dist / 2)).mean(dim=1)
    if boundary_weight and t > 1 and fs >= 2:
        reward = reward - boundary_weight * boundary_kink(frames, fs)
    penalty = getattr(guide_map, "penalty", None)
    if penalty is not None:
        reward = reward - penalty(frames[:, fs:])
    return reward


def boundary_kink(frames: torch.Tensor, fs: int) -> torch.Tensor:
    """[B, F, d] frames in tokens of ``fs`` -> [B]: mean over token boundaries of the second difference's norm
    (the step into each token's first frame minus the step before it)."""
    first = torch.arange(fs, frames.shape[1], fs, device=frames.device)  # first frame of tokens 1..T-1
    across = frames[:, first] - frames[:, first - 1]
    before = frames[:, first - 1] - frames[:, first - 2]
    return torch.linalg.vector_norm(across - before, dim=-1).mean(dim=1)


def guided_estimate(model: nn.Module, x_in: torch.Tensor, t_in: torch.Tensor, scale: torch.Tensor,
                    start: torch.Tensor, goal: torch.Tensor, guidance_path: str = "input",
                    guide_mask: torch.Tensor | None = None, guide_map: nn.Module | None = None,
                    boundary_weight: float = 0.0) -> tuple[torch.Tensor, torch.Tensor]:
    """(x0_hat, d objective / d x_in), both [B, T, D]: the network's estimate and the guidance gradient.

    Eager autograd, unless the model brings its own compiled step (``model.guided_estimate``,
    denoiser.runtime): then forward, goal term and gradient run as one graph, which on a CPU
    removes the per-op overhead that dominates small batches (issue 22).
    """
    own = getattr(model, "guided_estimate", None)
    if own is not None:
        return own(x_in, t_in, scale, start, goal, guidance_path, guide_mask, guide_map, boundary_weight)
    with torch.enable_grad():
        xg = x_in.detach().requires_grad_(True)
        x0 = model(xg, t_in) if guidance_path == "input" else model(xg, t_in, skip_grad=False)
        objective = GUIDANCE_GAIN * scale * goal_reward(x0, start, goal, guide_mask, guide_map, boundary_weight)
        (grad,) = torch.autograd.grad(objective.sum(), xg)
    return x0.detach(), grad


def functional_guided_estimate(model: nn.Module, x_in: torch.Tensor, t_in: torch.Tensor, scale: torch.Tensor,
                               start: torch.Tensor, goal: torch.Tensor, guidance_path: str = "input",
                               guide_mask: torch.Tensor | None = None, guide_map: nn.Module | None = None,
                               boundary_weight: float = 0.0) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`guided_estimate` written with ``torch.func.grad``, which torch.compile traces into one
    graph (``torch.autograd.grad`` would break it); the same numbers up to float rounding."""

    def objective(xx: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        x0 = model(xx, t_in) if guidance_path == "input" else model(xx, t_in, skip_grad=False)
        return (GUIDANCE_GAIN * scale * goal_reward(x0, start, goal, guide_mask, guide_map, boundary_weight)).sum(), x0

    grad, x0 = torch.func.grad(objective, has_aux=True)(x_in)
    return x0, grad


def transition(model: nn.Module, c: SamplerConsts, x: torch.Tensor, a: torch.Tensor, b: torch.Tensor,
               scale: torch.Tensor, start: torch.Tensor, goal: torch.Tensor,
               guidance_path: str = "input", force_grad: bool = False,
               guide_mask: torch.Tensor | None = None, guide_map: nn.Module | None = None,
               boundary_weight: float = 0.0) -> tuple[torch.Tensor, torch.Tensor]:
    """One DDIM step from levels a to b. x: [B, T, D]; a, b: [B, T] long; scale: [B];
    guide_mask: [B, d] or None (the dims the goal term uses, :func:`goal_reward`); guide_map: the
    space the guidance measures distances in (None: the frame state itself).

    Returns (x_next, x0_hat), both [B, T, D]; for guided jobs x0_hat is the guided x0'. Tokens
    with a == b (and token 0, the context, always) come back bit-identical; x0_hat of a clean
    token is the token itself. ``force_grad`` runs the network in grad mode even when no job is
    guided (a compiled network's bits may depend on the grad mode; see denoiser.runtime).
    """
    clean = (a == 0)[..., None]
    x_in = torch.where(clean, c.sqrt_ab_in[0] * x, x)  # clean tokens: "stabilised" context
    t_in = c.t_in[a]
    sa, s1a = c.sqrt_ab_in[a][..., None], c.sqrt_1m_ab_in[a][..., None]
    sb, s1b = c.sqrt_ab_out[b][..., None], c.sqrt_1m_ab_out[b][..., None]
    guided = scale != 0  # [B]
    if force_grad or bool(guided.any()):
        x0, grad = guided_estimate(model, x_in, t_in, scale, start, goal, guidance_path, guide_mask, guide_map,
                                   boundary_weight)
    else:
        with torch.no_grad():
            x0 = model(x_in, t_in)
        grad = None
    eps = (x_in - sa * x0) / s1a
    if grad is not None:
        eps_g = eps - s1b * grad
        x0_g = (x_in - s1a * eps_g) / sa
        g = guided[:, None, None]
        eps, x0 = torch.where(g, eps_g, eps), torch.where(g, x0_g, x0)
    x_next = sb * x0 + s1b * eps
    move = (a > b)[..., None]
    move[:, 0] = False
    return torch.where(move, x_next, x), torch.where(clean, x, x0)


def renoise(c: SamplerConsts, x: torch.Tensor, a: torch.Tensor, b: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
    """Forward diffusion of the tokens whose level goes up (b > a), with noise z; others unchanged.

    x_b = sqrt(ab_b / ab_a) x_a + sqrt(1 - ab_b / ab_a) z: the DDPM marginal of x_b given x_a.
    x, z: [B, T, D]; a, b: [B, T].
    """
    up = (b > a)[..., None]
    ratio = (c.sqrt_ab_out[b] / c.sqrt_ab_out[a]).square()[..., None]
    return torch.where(up, ratio.sqrt() * x + (1.0 - ratio).clamp_min(0.0).sqrt() * z, x)


def renoise_draws(seeds: torch.Tensor, row: int, shape: tuple[int, ...], device: torch.device) -> torch.Tensor:
    """[B, *shape] standard normal noise, job j's drawn from (seeds[j], row) alone, so a job's
    bits do not depend on its micro-batch or actor."""
    out = []
    for s in seeds.tolist():
        g = torch.Generator().manual_seed(int(np.random.SeedSequence([int(s), row, 0x5E5A]).generate_state(1)[0]))
        out.append(torch.randn(shape, generator=g))
    return torch.stack(out).to(device)


def run_levels(model: nn.Module, c: SamplerConsts, x: torch.Tensor, levels: torch.Tensor, scale: torch.Tensor,
               start: torch.Tensor, goal: torch.Tensor, stats: dict | None = None,
               noise_seed: torch.Tensor | None = None, guidance_path: str = "input",
               force_grad: bool = False, guide_mask: torch.Tensor | None = None,
               guide_map: nn.Module | None = None, boundary_weight: float = 0.0) -> tuple[torch.Tensor, torch.Tensor]:
    """Run levels [B, R+1, T] (row r -> r+1 per transition) on x [B, T, D].

    scale [B], start/goal [B, d], noise_seed [B] (needed only if some row goes up), guide_mask
    [B, d] or None (object-wise guidance: the dims the goal term uses), guide_map: see
    :func:`goal_reward`, boundary_weight: its boundary term (guided jobs only). Returns
    (x, x0): the final tokens and, per job, the x0 estimate of that job's last DDIM transition
    that moved a token (x itself if none did), so a job's result does not depend on which
    other jobs share its micro-batch. Rows where no token of any job goes down skip the model
    call; tokens that go up are re-noised (:func:`renoise`).
    """
    assert levels.ndim == 3 and levels.shape[0] == x.shape[0] and levels.shape[2] == x.shape[1]
    down = levels[:, 1:] < levels[:, :-1]  # [B, R, T]
    up = levels[:, 1:] > levels[:, :-1]
    down_rows, up_rows = down.any(dim=(0, 2)).tolist(), up.any(dim=(0, 2)).tolist()
    assert noise_seed is not None or not any(up_rows), "rows that re-noise need per-job noise seeds"
    assert not (up.any(dim=2) & down.any(dim=2)).any(), "a job's row either re-noises or denoises, not both"
    x0 = x
    calls = 0
    for r, (active, renoising) in enumerate(zip(down_rows, up_rows)):
        if renoising:
            z = renoise_draws(noise_seed, r, tuple(x.shape[1:]), x.device)
            x = renoise(c, x, levels[:, r], levels[:, r + 1], z)
        if not active:
            continue
        x, x0_r = transition(model, c, x, levels[:, r], levels[:, r + 1], scale, start, goal, guidance_path,
                             force_grad, guide_mask, guide_map, boundary_weight)
        x0 = torch.where(down[:, r].any(dim=1)[:, None, None], x0_r, x0)
        calls += 1
    if stats is not None:
        stats["model_calls"] = stats.get("model_calls", 0) + calls
    return x, x0
