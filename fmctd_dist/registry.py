"""Env families: one record per family package, the only registry (docs/design.md §13).

A family is one package (``fmctd_dist/families/<name>/`` for ours; any importable package for a new
one) whose ``record`` module holds a :class:`Family`: its env names and planner state, and the
modules that implement its hooks (plan rules, episodes, figures), its data (make / load / describe)
and, per robot, its learned low-level policy. :data:`FAMILIES` maps a family's name to that module;
adding a family is adding its package, one line here, and its env configs. Record modules are light
(names and small specs only), so config, data and the jobs read them without import cycles; only the
door :mod:`fmctd_dist.families` imports the modules a record names.

Code written for some families only guards its entry with :func:`require_family`, so a name from
another family stops there with one ConfigError naming what to run instead.
"""

from __future__ import annotations

import importlib
from functools import cache
from pathlib import Path

from fmctd_dist.errors import ConfigError, unknown_name
from fmctd_dist.records import EnvSpec, Family, Table  # noqa: F401 - re-exported for the record modules' readers

# family name -> the module holding its record
FAMILIES: dict[str, str] = {
    "maze": "fmctd_dist.families.maze.record",
    "cube": "fmctd_dist.families.cube.record",
    "visual": "fmctd_dist.families.visual.record",
}


@cache
def records() -> dict[str, Family]:
    """Every registered family's record (imported once; ``records.cache_clear()`` after editing FAMILIES)."""
    out = {}
    for name, module in FAMILIES.items():
        rec = importlib.import_module(module).FAMILY
        if rec.name != name:
            raise ConfigError(f"registry: {module} holds family {rec.name!r}, registered as {name!r}")
        out[name] = rec
    return out


@cache
def env_specs() -> dict[str, EnvSpec]:
    return {e.name: e for rec in records().values() for e in rec.envs}


def tables() -> dict[str, Table]:
    """Every paper table the registered families reproduce, by name, in registry order."""
    return {t.name: t for rec in records().values() for t in rec.tables}


def env_names() -> tuple[str, ...]:
    return tuple(env_specs())


def env_spec(name: str, field: str = "env.name") -> EnvSpec:
    """The spec of ``name``; an unknown name is one ConfigError with the closest valid one."""
    specs = env_specs()
    if name not in specs:
        raise unknown_name(field, name, tuple(specs))
    return specs[name]


def family_record(env_name: str) -> Family:
    """The record of the family package that serves ``env_name``."""
    env_spec(env_name)
    return next(rec for rec in records().values() if any(e.name == env_name for e in rec.envs))


def family(name: str) -> str:
    """``name``'s kind (pointmaze, antmaze, cube, visual-pointmaze): what per-robot rules are keyed by."""
    return env_spec(name).family


def state_dim(name: str) -> int:
    return env_spec(name).state_dim


def env_config_dir(env_name: str) -> Path | None:
    """Where ``env_name``'s config lives when its family keeps its own (None: the repository's configs/env)."""
    specs = env_specs()
    if env_name not in specs:
        return None
    rec = family_record(env_name)
    return Path(rec.configs) / "env" if rec.configs else None


def env_field_readers() -> dict[str, tuple[str, ...]]:
    """env field -> the kinds that read it, for the fields only some families read (config.validate refuses
    such a field set away from its default on an env that never reads it)."""
    out: dict[str, dict[str, None]] = {}
    for spec in env_specs().values():
        for f in spec.env_fields:
            out.setdefault(f, {})[spec.family] = None
    return {f: tuple(kinds) for f, kinds in out.items()}


def require_family(name: str, families: tuple[str, ...], what: str) -> str:
    """``name`` if its kind is one of ``families``; else one ConfigError saying what is not built for it."""
    spec = env_spec(name)
    if spec.family in families:
        return name
    hint = family_record(name).hint
    raise ConfigError(f"env.name={name} is a {spec.family} env, but {what} is built for "
                      f"{' / '.join(families)} envs only" + (f". {hint}" if hint else ""))
