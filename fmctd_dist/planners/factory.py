"""Config -> planner. Planners never know whether their denoiser is local or a Ray pool, nor which family
they plan for: the caller hands in the family's plan rules (``fmctd_dist.families.plan_rules(cfg)``)."""

from __future__ import annotations

from fmctd_dist.config import Config
from fmctd_dist.tokens import Normaliser
from fmctd_dist.denoiser.protocol import Denoiser
from fmctd_dist.errors import unknown_name
from fmctd_dist.family import PlanRules


def make_planner(cfg: Config, denoiser: Denoiser, normaliser: Normaliser, rules: PlanRules,
                 time_limit_s: float = 0.0):
    if cfg.method.planner == "mctd":
        from fmctd_dist.planners.mctd import MCTDPlanner

        return MCTDPlanner(cfg, denoiser, normaliser, rules, time_limit_s)
    if cfg.method.planner == "diffusion_forcing":
        from fmctd_dist.planners.diffusion_forcing import DiffusionForcingPlanner

        return DiffusionForcingPlanner(cfg, denoiser, normaliser, rules)
    if cfg.method.planner == "diffuser":
        from fmctd_dist.planners.diffuser import DiffuserPlanner

        return DiffuserPlanner(cfg, denoiser, normaliser, rules)
    raise unknown_name("method.planner", cfg.method.planner, ["mctd", "diffusion_forcing", "diffuser"])
