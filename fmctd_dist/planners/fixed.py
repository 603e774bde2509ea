"""Planners without search: one Denoiser call over a fixed noise-level schedule.

Diffusion Forcing (pyramid rows; the same checkpoint and Denoiser call as an MCTD expansion, just all rows at
once, so the comparison with MCTD isolates the search) and Diffuser (Janner et al. 2022: all plan tokens at one
level per row, :func:`uniform_levels`) differ only in that schedule, so both are this class with a different
``levels`` table, chosen by :func:`fmctd_dist.planners.make_planner`. Replanning (every 50 env steps in the paper)
is the episode loop's job (``method.replan_every``). The guidance
(scale and guided dims) and what the sampled plan becomes (cubes: the un-guided cubes pinned)
come from the env family's plan rules, handed in by the caller.
"""

from __future__ import annotations

import time

import numpy as np

from fmctd_dist.tokens import PlanCodec
from fmctd_dist.denoiser.protocol import DenoiseBatch, Denoiser
from fmctd_dist.family import PlanRules
from fmctd_dist.planners.base import PlanOutput, repeat_waypoints
from fmctd_dist.search.loop import initial_noise


def uniform_levels(plan_tokens: int, levels: int, resample: int = 1) -> np.ndarray:
    """[R+1, P+1] int64: every plan token at one level per row, L down to 0; token 0 (start) stays 0.

    Diffuser's sampler: the whole plan denoised together, one U-Net call per level, the start inpainted as the clean
    token 0. ``method.resample`` = U > 1 adds RePaint's resampling (Lugmayr et al. 2022), which pulls the generated
    frames back into agreement with the inpainted start; U = 1 is Janner's and the paper's plain DDIM.
    Resample U: after each step down to a level l > 0, U - 1 times (up to l + 1, down to l): R = L + 2 (U - 1)(L - 1)
    rows.
    """
    ladder = [levels]
    for lv in range(levels - 1, -1, -1):
        ladder.append(lv)
        if lv > 0:
            ladder += [lv + 1, lv] * (resample - 1)
    out = np.zeros((len(ladder), plan_tokens + 1), dtype=np.int64)
    out[:, 1:] = np.asarray(ladder)[:, None]
    return out


class FixedSchedulePlanner:
    """One plan = context token + seeded noise, denoised through ``levels`` [R+1, P+1] at one guidance scale."""

    def __init__(self, denoiser: Denoiser, codec: PlanCodec, levels: np.ndarray, token_dim: int, rules: PlanRules,
                 jump: int, clip_noise: float):
        self.denoiser, self.codec, self.levels, self.rules = denoiser, codec, levels, rules
        self.noise_shape = (levels.shape[1] - 1, token_dim)  # [P, D]: the plan tokens after the context token
        self.jump, self.clip_noise = jump, clip_noise

    def plan(self, start: np.ndarray, goal: np.ndarray, seed: int) -> PlanOutput:
        t0 = time.perf_counter()
        norm = self.codec.normaliser
        act, rule = self.rules.fixed(np.asarray(start, np.float64), np.asarray(goal, np.float64))
        start = np.asarray(start, np.float64)[None]
        noise = initial_noise(seed, 1, 0, 0, self.noise_shape, self.clip_noise)
        x = np.concatenate([self.codec.context(start), noise[None]], axis=1)  # [1, P+1, D]
        batch = DenoiseBatch(x, self.levels[None].copy(), act.scale.astype(np.float32),
                             norm.normalise(start), norm.normalise(np.asarray(goal, np.float64)[None]),
                             noise_seed=np.array([seed], np.int64),  # used only by schedules that re-noise
                             guide_mask=act.mask)
        t_call = time.perf_counter()
        out = self.denoiser.denoise(batch)
        t_call = time.perf_counter() - t_call
        plan = rule.prepare(self.codec.decode(out.x), start[0], act)[0]
        return PlanOutput(waypoints=repeat_waypoints(plan, self.jump), status="plan",
                          plan_time_s=time.perf_counter() - t0, denoise_time_s=out.denoise_time_s,
                          denoise_calls=1, retries=out.retries, denoise_call_s=t_call)
