"""Planners: thin compositions of a Denoiser with a search (MCTD family) or a fixed schedule."""

from fmctd_dist.planners.base import PlanOutput, Planner, plan_seed
from fmctd_dist.planners.factory import make_planner

__all__ = ["PlanOutput", "Planner", "plan_seed", "make_planner"]
