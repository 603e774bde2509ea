"""Diffusion Forcing baseline: the whole pyramid schedule at one fixed guidance scale, no search.

Same checkpoint, same Denoiser call as an MCTD expansion (just all rows at once), so the
comparison with MCTD isolates the search. Replanning (every 50 env steps in the paper) is
the episode loop's job (``method.replan_every``).
"""

from __future__ import annotations

from fmctd_dist.config import Config
from fmctd_dist.tokens import Normaliser
from fmctd_dist.denoiser.protocol import Denoiser
from fmctd_dist.diffusion.schedule import PyramidSchedule
from fmctd_dist.family import PlanRules
from fmctd_dist.planners.fixed import FixedSchedulePlanner


class DiffusionForcingPlanner(FixedSchedulePlanner):
    def __init__(self, cfg: Config, denoiser: Denoiser, normaliser: Normaliser, rules: PlanRules):
        levels = PyramidSchedule(cfg.plan_tokens, cfg.diffusion.levels).full()  # [n_rows, P+1]
        super().__init__(cfg, denoiser, normaliser, rules, levels)
