"""What a planner and an evaluation runner ask of an env family (docs/design.md §13): the protocol, no lookup.

A family differs in the tree's action set and plan value (mazes: guidance scales + the reach
value; cubes: (unsolved cube, scale) pairs + the cube rules) and in how an episode is driven
(PD or ant policy on waypoints; the arm's pre-defined plans + the cube policy). Planners and
``evaluation/`` never branch on the family: their caller hands them what the family's hook module
gives (its plan rules, episodes, guide map). The one place that finds that module from an env name
is the door above every family, :mod:`fmctd_dist.families`; this module sits below the search and
planners, so it names their types in words only.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Protocol

import numpy as np

if TYPE_CHECKING:
    from fmctd_dist.config import Config


class PlanRules(Protocol):
    """The search's inputs that depend on the family, for one plan call from ``start`` to ``goal`` [d]."""

    def tree(self, start: np.ndarray, goal: np.ndarray) -> tuple[Any, Any]:
        """The tree's child slots and the plan value (``search.actions.Actions``, ``search.value_rule.PlanValue``;
        MCTD family)."""
        ...

    def fixed(self, start: np.ndarray, goal: np.ndarray) -> tuple[Any, Any]:
        """One action (the fixed guidance of Diffuser / Diffusion Forcing) and the rule whose ``prepare``
        turns the sampled plan into the one the controller follows."""
        ...


class Episodes(Protocol):
    """An env (+ its controller) that runs whole episodes and returns their rows."""

    policy_digest: str  # digest of the low-level policy it loaded ("" when the robot has none)

    def run(self, planner: Any, task: int, seed: int) -> dict[str, Any]:
        """One episode driven by ``planner`` (``planners.base.Planner``): its row."""
        ...


class FamilyHooks(Protocol):
    """A family's hook module. Optional: ``guide_map(cfg, manifest) -> torch module`` (the visual maze: latent
    -> estimated (x, y)), the space the denoiser's guidance measures distances in; mazes and cubes guide on
    the state itself."""

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


HooksFor = Callable[[str], FamilyHooks]  # env name -> its family's hook module: fmctd_dist.families.hooks_for


def warp_threshold(cfg: "Config") -> float:
    """The plan value's warp threshold of families that set it per model density: ``env.warp_dense`` at
    jump 1, ``env.warp_sparse`` above (cubes; the visual maze on estimated positions), else the maze's
    ``method.warp_threshold`` (0 = unset)."""
    w = cfg.env.warp_dense if cfg.jump == 1 else cfg.env.warp_sparse
    return float(w or cfg.method.warp_threshold)
