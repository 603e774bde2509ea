"""Diffuser baseline (Janner et al. 2022): one full-horizon plan per call, no search.

All plan tokens are denoised together, level L -> L-1 -> ... -> 0 in one Denoiser call
(L = diffusion.levels DDIM levels, one U-Net call each), with the start frame inpainted as
the clean token 0 and goal guidance at the fixed scale method.guidance_scale (paper: 0.1).
``method.resample`` = U > 1 adds RePaint's resampling (Lugmayr et al. 2022): after each step
down to a level above 0 the plan is re-noised one level up and denoised again, U - 1 times,
so the generated frames are pulled back into agreement with the inpainted start (U - 1 extra
U-Net calls per level; 1 = plain DDIM, Janner's and the paper's sampler).
Replanning (Diffuser-Replan, every 50 env steps) is the episode loop's job
(``method.replan_every``), exactly as for Diffusion Forcing.
"""

from __future__ import annotations

import numpy as np

from fmctd_dist.config import Config
from fmctd_dist.tokens import Normaliser
from fmctd_dist.denoiser.protocol import Denoiser
from fmctd_dist.family import PlanRules
from fmctd_dist.planners.fixed import FixedSchedulePlanner


def uniform_levels(plan_tokens: int, levels: int, resample: int = 1) -> np.ndarray:
    """[R+1, P+1] int64: every plan token at one level per row, L down to 0; token 0 (start) stays 0.

    resample U: after each step down to a level l > 0, U - 1 times (up to l + 1, down to l):
    R = L + 2 (U - 1)(L - 1) rows. U = 1 is the plain ladder L, L-1, ..., 0.
    """
    ladder = [levels]
    for lv in range(levels - 1, -1, -1):
        ladder.append(lv)
        if lv > 0:
            ladder += [lv + 1, lv] * (resample - 1)
    out = np.zeros((len(ladder), plan_tokens + 1), dtype=np.int64)
    out[:, 1:] = np.asarray(ladder)[:, None]
    return out


class DiffuserPlanner(FixedSchedulePlanner):
    def __init__(self, cfg: Config, denoiser: Denoiser, normaliser: Normaliser, rules: PlanRules):
        # frame_stack 1: a token is one frame
        levels = uniform_levels(cfg.plan_tokens, cfg.diffusion.levels, cfg.method.resample)
        super().__init__(cfg, denoiser, normaliser, rules, levels)
