"""Planners without search: one Denoiser call over a fixed noise-level schedule.

Diffusion Forcing (pyramid rows) and Diffuser (all plan tokens at one level per row) differ
only in that schedule, so both are this class with a different ``levels`` table. The guidance
(scale and guided dims) and what the sampled plan becomes (cubes: the un-guided cubes pinned)
come from the env family's plan rules, handed in by the caller.
"""

from __future__ import annotations

import time

import numpy as np

from fmctd_dist.config import Config
from fmctd_dist.planners.base import repeat_waypoints
from fmctd_dist.tokens import Normaliser, PlanCodec
from fmctd_dist.denoiser.protocol import DenoiseBatch, Denoiser
from fmctd_dist.family import PlanRules
from fmctd_dist.planners.base import PlanOutput
from fmctd_dist.search.loop import initial_noise


class FixedSchedulePlanner:
    """One plan = context token + seeded noise, denoised through ``levels`` [R+1, P+1] at one guidance scale."""

    def __init__(self, cfg: Config, denoiser: Denoiser, normaliser: Normaliser, rules: PlanRules,
                 levels: np.ndarray):
        self.cfg = cfg
        self.denoiser = denoiser
        self.codec = PlanCodec(normaliser, cfg.model.frame_stack)
        self.levels = levels
        self.rules = rules

    def plan(self, start: np.ndarray, goal: np.ndarray, seed: int) -> PlanOutput:
        t0 = time.perf_counter()
        cfg, norm = self.cfg, self.codec.normaliser
        act, rule = self.rules.fixed(np.asarray(start, np.float64), np.asarray(goal, np.float64))
        start = np.asarray(start, np.float64)[None]
        noise = initial_noise(seed, 1, 0, 0, (cfg.plan_tokens, cfg.token_dim), cfg.diffusion.clip_noise)
        x = np.concatenate([self.codec.context(start), noise[None]], axis=1)  # [1, P+1, D]
        batch = DenoiseBatch(x, self.levels[None].copy(), act.scale.astype(np.float32),
                             norm.normalise(start), norm.normalise(np.asarray(goal, np.float64)[None]),
                             noise_seed=np.array([seed], np.int64),  # used only by schedules that re-noise
                             guide_mask=act.mask)
        t_call = time.perf_counter()
        out = self.denoiser.denoise(batch)
        t_call = time.perf_counter() - t_call
        plan = rule.prepare(self.codec.decode(out.x), start[0], act)[0]
        return PlanOutput(waypoints=repeat_waypoints(plan, cfg.jump), status="plan",
                          plan_time_s=time.perf_counter() - t0, denoise_time_s=out.denoise_time_s,
                          denoise_calls=1, retries=out.retries, denoise_call_s=t_call)
