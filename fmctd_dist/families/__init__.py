"""The env families, one package each: maze (point and ant robots), cube (robot arm), visual (images).

Each package holds everything of its family: env, data, episode, action set and value, low-level
control, figures. Nothing below names them or looks them up (docs/design.md §2): this module is the
one door that imports a family's modules by the names its registry record gives, and only jobs and
tests ask it; they hand what it returns (plan rules, hooks, guide map, data, policy hooks) down.
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

from fmctd_dist.registry import family_record

if TYPE_CHECKING:
    from fmctd_dist.config import Config
    from fmctd_dist.family import FamilyHooks, PlanRules


def hooks_for(env_name: str) -> "FamilyHooks":
    """The hook module of ``env_name``'s family (an unknown name: one ConfigError)."""
    return importlib.import_module(family_record(env_name).hooks)  # type: ignore[return-value]


def plan_rules(cfg: "Config") -> "PlanRules":
    """What ``planners.make_planner`` takes: the action set and plan value of ``cfg``'s env."""
    return hooks_for(cfg.env.name).plan_rules(cfg)


def guide_map(env_name: str) -> Callable[["Config", dict[str, Any]], Any] | None:
    """The family's ``guide_map(cfg, manifest)`` for ``LocalDenoiser.from_checkpoint``, or None (guidance on
    the state itself)."""
    return getattr(hooks_for(env_name), "guide_map", None)


def data_module(env_name: str) -> Any:
    """The family's data module: ``make(cfg, progress) -> (dir, manifest)`` (generate if missing, verify if
    present), ``load(cfg) -> dataset`` (``train`` / ``val`` [E, S, state_dim], ``normaliser``, ``digest``: all
    ``data/windows.py`` needs), ``describe(manifest) -> lines``. Imported on first use: the cube's data never
    imports the maze's."""
    return importlib.import_module(family_record(env_name).data)


def make_dataset(cfg: "Config", progress: bool = True) -> tuple[Path, dict[str, Any]]:
    """Generate (or verify) the dataset of ``cfg.env``'s family; its dir and manifest."""
    return data_module(cfg.env.name).make(cfg, progress=progress)


def load_dataset(cfg: "Config") -> Any:
    """The checked dataset of ``cfg.env``'s family (train / val states, normaliser, digest)."""
    return data_module(cfg.env.name).load(cfg)


def policy_hooks(env_name: str) -> Any:
    """The hooks of ``env_name``'s learned low-level policy (spec, rows, noise floor, reach test; its record's
    ``policy``, "module:Class"); an env without one is one ConfigError."""
    from fmctd_dist.control.policy.spec import require_policy

    module, cls = require_policy(env_name).policy.split(":")
    return getattr(importlib.import_module(module), cls)()
