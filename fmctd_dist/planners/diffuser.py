"""Diffuser baseline (Janner et al. 2022): one full-horizon plan per call, no search.

All plan tokens are denoised together, level L -> L-1 -> ... -> 0 in one Denoiser call
(L = diffusion.levels DDIM levels, one U-Net call each), with the start frame inpainted as
the clean token 0 and goal guidance at the fixed scale method.guidance_scale (paper: 0.1).
Replanning (Diffuser-Replan, every 50 env steps) is the episode loop's job
(``method.replan_every``), exactly as for Diffusion Forcing.
"""

from __future__ import annotations

import numpy as np

from fmctd_dist.config import Config
from fmctd_dist.data.tokens import Normaliser
from fmctd_dist.denoiser.protocol import Denoiser
from fmctd_dist.planners.fixed import FixedSchedulePlanner


def uniform_levels(plan_tokens: int, levels: int) -> np.ndarray:
    """[levels+1, P+1] int64: row r puts every plan token at level L - r; token 0 (start) stays at 0."""
    lv = np.zeros((levels + 1, plan_tokens + 1), dtype=np.int64)
    lv[:, 1:] = (levels - np.arange(levels + 1))[:, None]
    return lv


class DiffuserPlanner(FixedSchedulePlanner):
    def __init__(self, cfg: Config, denoiser: Denoiser, normaliser: Normaliser):
        # frame_stack 1: a token is one frame
        super().__init__(cfg, denoiser, normaliser, uniform_levels(cfg.plan_tokens, cfg.diffusion.levels))
