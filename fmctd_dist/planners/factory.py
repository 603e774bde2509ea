"""Config -> planner: the one place that reads the config for planning (diffusers' ``from_config`` shape).

Planners take their parts (schedule, codec, search parameters, noise-level table, H) and never the whole config,
never know whether their denoiser is local or a Ray pool, nor which family they plan for: the caller hands in the
family's plan rules (``fmctd_dist.families.plan_rules(cfg)``).
"""

from __future__ import annotations

from fmctd_dist.config import Config
from fmctd_dist.denoiser.protocol import Denoiser
from fmctd_dist.diffusion.schedule import PyramidSchedule
from fmctd_dist.errors import unknown_name
from fmctd_dist.family import PlanRules
from fmctd_dist.tokens import Normaliser, PlanCodec


def make_planner(cfg: Config, denoiser: Denoiser, normaliser: Normaliser, rules: PlanRules,
                 time_limit_s: float = 0.0):
    m, codec = cfg.method, PlanCodec(normaliser, cfg.model.frame_stack)
    if m.planner == "mctd":
        from fmctd_dist.planners.mctd import MCTDPlanner
        from fmctd_dist.search.loop import SearchParams

        schedule = PyramidSchedule(cfg.plan_tokens, cfg.diffusion.levels, m.segment_transitions, m.sim_skip)
        params = SearchParams.from_method(m, time_limit_s=time_limit_s, clip_noise=cfg.diffusion.clip_noise)
        return MCTDPlanner(denoiser, schedule, codec, params, rules, cfg.jump)
    if m.planner in ("diffusion_forcing", "diffuser"):
        from fmctd_dist.planners.fixed import FixedSchedulePlanner, uniform_levels

        levels = (PyramidSchedule(cfg.plan_tokens, cfg.diffusion.levels).full() if m.planner == "diffusion_forcing"
                  else uniform_levels(cfg.plan_tokens, cfg.diffusion.levels, m.resample))
        return FixedSchedulePlanner(denoiser, codec, levels, cfg.token_dim, rules, cfg.jump, cfg.diffusion.clip_noise)
    raise unknown_name("method.planner", m.planner, ["mctd", "diffusion_forcing", "diffuser"])
