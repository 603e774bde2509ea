"""What a planner and an evaluation runner ask of an env family, in one place per family (docs/design.md §13).

A family differs in the tree's action set and plan value (mazes: guidance scales + the reach
value; cubes: (unsolved cube, scale) pairs + the cube rules) and in how an episode is driven
(PD or ant policy on waypoints; the arm's pre-defined plans + the cube policy). Planners,
``evaluation/grid.py`` and ``evaluation/ray_runner.py`` ask :func:`hooks_for` and never branch
on the family. The module of each family is named in its registry record (:mod:`fmctd_dist.registry`) and
imported by name, so nothing below the hooks imports them.
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from fmctd_dist.registry import family_record

if TYPE_CHECKING:
    from fmctd_dist.config import Config
    from fmctd_dist.planners.base import Planner
    from fmctd_dist.search.actions import Actions
    from fmctd_dist.search.value_rule import PlanValue


class PlanRules(Protocol):
    """The search's inputs that depend on the family, for one plan call from ``start`` to ``goal`` [d]."""

    def tree(self, start: np.ndarray, goal: np.ndarray) -> tuple["Actions", "PlanValue"]:
        """The tree's child slots and the plan value (MCTD family)."""
        ...

    def fixed(self, start: np.ndarray, goal: np.ndarray) -> tuple["Actions", "PlanValue"]:
        """One action (the fixed guidance of Diffuser / Diffusion Forcing) and the rule whose ``prepare``
        turns the sampled plan into the one the controller follows."""
        ...


class Episodes(Protocol):
    """An env (+ its controller) that runs whole episodes and returns their rows."""

    policy_digest: str  # digest of the low-level policy it loaded ("" when the robot has none)

    def run(self, planner: "Planner", task: int, seed: int) -> dict[str, Any]: ...


class FamilyHooks(Protocol):
    def plan_rules(self, cfg: "Config") -> PlanRules: ...

    def check_episodes(self, cfg: "Config") -> str:
        """Everything an episode needs besides the planner checkpoint (e.g. a low-level policy): one
        clear error in the job process, before any actor starts. Returns the low-level policy's
        digest ("" when the robot has none), which keys the result rows beside the planner's."""
        ...

    def episodes(self, cfg: "Config") -> Episodes: ...

    def plot_episode(self, row: dict[str, Any], path: Path) -> Path:
        """The figure of one episode's row (plan and trajectory in the family's own picture)."""
        ...


def guide_map_for(cfg: "Config", manifest: dict[str, Any]) -> Any:
    """The module the family's guidance measures distances through (``diffusion.sampler.goal_reward``), or None.

    Optional per family: a hook module may define ``guide_map(cfg, manifest) -> torch module``
    (the visual maze: latent -> estimated (x, y)); mazes and cubes do not, and guide on the state itself.
    The denoiser asks this once, when it loads the planner checkpoint whose ``manifest`` is given.
    """
    fn = getattr(hooks_for(cfg.env.name), "guide_map", None)
    return None if fn is None else fn(cfg, manifest)


def warp_threshold(cfg: "Config") -> float:
    """The plan value's warp threshold of families that set it per model density: ``env.warp_dense`` at
    jump 1, ``env.warp_sparse`` above (cubes; the visual maze on estimated positions), else the maze's
    ``method.warp_threshold`` (0 = unset)."""
    w = cfg.env.warp_dense if cfg.jump == 1 else cfg.env.warp_sparse
    return float(w or cfg.method.warp_threshold)


def hooks_for(env_name: str) -> FamilyHooks:
    """The hook module of ``env_name``'s family (an unknown name: one ConfigError)."""
    return importlib.import_module(family_record(env_name).hooks)  # type: ignore[return-value]
