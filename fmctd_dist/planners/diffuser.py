"""Diffuser baseline (Janner et al. 2022): one full-horizon plan per call, no search.

All plan tokens are denoised together, level L -> L-1 -> ... -> 0 in one Denoiser call
(L = diffusion.levels DDIM levels, one U-Net call each), with the start frame inpainted as
the clean token 0 and goal guidance at the fixed scale method.guidance_scale (paper: 0.1).
Replanning (Diffuser-Replan, every 50 env steps) is the episode loop's job
(``method.replan_every``), exactly as for Diffusion Forcing.
"""

from __future__ import annotations

import time

import numpy as np

from fmctd_dist.config import Config
from fmctd_dist.control.pd import repeat_waypoints
from fmctd_dist.data.tokens import Normaliser, PlanCodec
from fmctd_dist.denoiser.protocol import DenoiseBatch, Denoiser
from fmctd_dist.planners.base import PlanOutput
from fmctd_dist.search.loop import initial_noise


def uniform_levels(plan_tokens: int, levels: int) -> np.ndarray:
    """[levels+1, P+1] int64: row r puts every plan token at level L - r; token 0 (start) stays at 0."""
    lv = np.zeros((levels + 1, plan_tokens + 1), dtype=np.int64)
    lv[:, 1:] = (levels - np.arange(levels + 1))[:, None]
    return lv


class DiffuserPlanner:
    def __init__(self, cfg: Config, denoiser: Denoiser, normaliser: Normaliser):
        self.cfg = cfg
        self.denoiser = denoiser
        self.codec = PlanCodec(normaliser, cfg.model.frame_stack)  # frame_stack 1: a token is one frame
        self.levels = uniform_levels(cfg.plan_tokens, cfg.diffusion.levels)  # [L+1, P+1]

    def plan(self, start: np.ndarray, goal: np.ndarray, seed: int) -> PlanOutput:
        t0 = time.perf_counter()
        cfg, norm = self.cfg, self.codec.normaliser
        start = np.asarray(start, np.float64)[None]
        noise = initial_noise(seed, 1, 0, 0, (cfg.plan_tokens, cfg.token_dim), cfg.diffusion.clip_noise)
        x = np.concatenate([self.codec.context(start), noise[None]], axis=1)  # [1, P+1, D]
        batch = DenoiseBatch(x, self.levels[None].copy(), np.array([cfg.method.guidance_scale], np.float32),
                             norm.normalise(start), norm.normalise(np.asarray(goal, np.float64)[None]))
        out = self.denoiser.denoise(batch)
        plan = self.codec.decode(out.x)[0]
        return PlanOutput(waypoints=repeat_waypoints(plan, cfg.jump), status="plan",
                          plan_time_s=time.perf_counter() - t0, denoise_time_s=out.denoise_time_s,
                          denoise_calls=1, retries=out.retries)
