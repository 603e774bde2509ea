"""The one config loader: dataclass defaults <- YAML group files <- ``key=value`` words, for every config root.

The planner's :class:`Config` takes ``env=`` / ``method=`` group files and dotted overrides. A side root
(the ant expert's, the visual parts', the goal-conditioned policy's: dataclasses kept by their owners so
that training them never changes the planner's digest) takes the words under its own prefixes
(``sac.*``, ``vae.*``, ``policy.*``) from the same command line, through the same parsing, merging and
range checks. Unknown keys, unknown group names and ill-typed values raise one :class:`ConfigError`
with a suggestion.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable
from typing import Any

from omegaconf import OmegaConf
from omegaconf.errors import OmegaConfBaseException

from fmctd_dist.config.checks import validate
from fmctd_dist.config.ranges import get
from fmctd_dist.config.repo import CONFIG_DIR
from fmctd_dist.config.schema import Config
from fmctd_dist.errors import ConfigError, did_you_mean, unknown_name
from fmctd_dist.registry import env_config_dir

# Top-level shorthands accepted on the command line (`tasks=[1] seeds=[0] runner=local`).
ALIASES = {"tasks": "eval.tasks", "seeds": "eval.seeds", "runner": "eval.runner"}
# Keys whose value names a YAML file under configs/<group>/ instead of a plain value.
GROUPS = ("env", "method")
# The env file's section of per-method settings (:func:`group_layers`).
METHODS_KEY = "methods"
# fields that existed once: a stored config (a manifest, a row) that holds one still loads, without it; a
# command that sets one is told why it is gone
RETIRED = {"eval.resume_mixed": "removed in session 26: a run directory never mixes configs or checkpoints "
                                "(docs/design.md §10); write to eval.run=<new name>, or move the old rows aside"}

Words = list[tuple[str, str]]


def all_keys(node: Any, prefix: str = "") -> list[str]:
    """Every dotted leaf key of a dataclass config instance (what an override may name)."""
    keys: list[str] = []
    for f in dataclasses.fields(node):
        value, name = getattr(node, f.name), f"{prefix}{f.name}"
        keys += all_keys(value, name + ".") if dataclasses.is_dataclass(value) else [name]
    return keys


def group_names(group: str) -> list[str]:
    return sorted(p.stem for p in (CONFIG_DIR / group).glob("*.yaml"))


def _group_file(group: str, name: str) -> Any:
    own = env_config_dir(name) if group == "env" else None  # a family that keeps its own env configs
    path = (own or CONFIG_DIR / group) / f"{name}.yaml"
    if not path.is_file():
        raise unknown_name(group, name, group_names(group))
    return OmegaConf.load(path)


def merge_checked(base: Any, update: Any, where: str, schema: type = Config) -> Any:
    """OmegaConf.merge; a bad key or type of ``schema`` becomes one ConfigError naming the key (and its type)."""
    try:
        return OmegaConf.merge(base, update)
    except OmegaConfBaseException as e:
        key = getattr(e, "full_key", "") or ""
        msg = str(getattr(e, "msg", e)).splitlines()[0]
        valid = all_keys(schema())
        if key in valid:
            raise ConfigError(f"{where}: {key}: {msg}; expected {_type_name(schema, key)}") from None
        raise ConfigError(f"{where}: unknown config key {key!r}{did_you_mean(key, valid)}") from None


def apply_override(cfg: Any, key: str, value: str, schema: type = Config) -> Any:
    """Merge one dotted ``key=value`` into ``cfg``, the value typed as YAML (``1`` int, ``[1,2]`` list)."""
    try:
        parsed = OmegaConf.create({"v": OmegaConf.from_dotlist([f"v={value}"]).v}).v
    except OmegaConfBaseException as e:
        raise ConfigError(f"{key}={value!r} could not be parsed: {e}") from None
    upd = OmegaConf.create()
    OmegaConf.update(upd, key, parsed, force_add=True)
    return merge_checked(cfg, upd, f"override {key}={value}", schema)


def _type_name(schema: type, dotted: str) -> str:
    parent, _, leaf = dotted.rpartition(".")
    node = get(schema(), parent) if parent else schema()
    return str({f.name: f.type for f in dataclasses.fields(node)}[leaf]).replace("typing.", "")


def parse_overrides(args: list[str], side: Any = None, *, main: bool = True, special: tuple[str, ...] = (),
                    example: str = "env=pointmaze-giant or train.max_steps=200") -> tuple[dict[str, str], Words, Words]:
    """Split CLI words into group selections (``env=``, ``method=``, and ``special`` words such as ``part=``),
    the planner Config's dotted overrides, and those of ``side``: a side root's dataclass instance, whose
    top-level fields are its keys' prefixes. ``main=False``: a root that takes no planner words."""
    groups: dict[str, str] = {}
    dotted: Words = []
    side_dotted: Words = []
    seen: dict[str, str] = {}
    valid = all_keys(Config()) if main else []
    side_keys = all_keys(side) if side is not None else []
    prefixes = tuple(f"{f.name}." for f in dataclasses.fields(side)) if side is not None else ()
    names = [*GROUPS, *ALIASES] if main else []
    for arg in args:
        if "=" not in arg:
            raise ConfigError(f"override {arg!r} is not key=value; e.g. {example}")
        key, value = arg.split("=", 1)
        key = ALIASES.get(key.strip(), key.strip()) if main else key.strip()
        if key in seen:
            raise ConfigError(f"{key} is given twice ({key}={seen[key]} and {key}={value}); "
                              "give it once with the value you mean")
        seen[key] = value
        if key in special or (main and key in GROUPS):
            groups[key] = value.strip()
        elif key.startswith(prefixes):
            if key not in side_keys:
                raise ConfigError(f"unknown config key {key!r}{did_you_mean(key, side_keys)}")
            side_dotted.append((key, value.strip()))
        elif key in valid:
            dotted.append((key, value))
        elif main and key in RETIRED:
            raise ConfigError(f"{key}={value}: {RETIRED[key]}")
        else:
            raise ConfigError(f"unknown config key {key!r}{did_you_mean(key, valid + names + side_keys)}")
    return groups, dotted, side_dotted


def build(schema: type, dotted: Iterable[tuple[str, str]], check: Callable[[Any], None],
          layers: Iterable[tuple[Any, str]] = ()) -> Any:
    """``schema``'s defaults <- each (YAML node, where) layer <- dotted overrides in order, then ``check``."""
    cfg = OmegaConf.structured(schema)
    for node, where in layers:
        cfg = merge_checked(cfg, node, where, schema)
    for key, value in dotted:
        cfg = apply_override(cfg, key, value, schema)
    obj = OmegaConf.to_object(cfg)
    check(obj)
    return obj


def from_dict(schema: type, d: dict[str, Any]) -> Any:
    """Rebuild a config from its ``to_dict()`` output (manifests, train states, Ray payloads)."""
    cfg = merge_checked(OmegaConf.structured(schema), OmegaConf.create(d), "config dict", schema)
    return OmegaConf.to_object(cfg)


def group_layers(env: str, method: str) -> Iterable[tuple[Any, str]]:
    """(YAML node, where) of the env file, the method file, then the env file's own settings for that method.

    An env file may hold a ``methods:`` section, ``{method name: settings}``, applied after the method's file:
    the defaults one method has on one env (the visual maze's Diffusers keep the paper's latent frames there
    while its other planners plan [z, x, y]), so every (method, env) still has exactly one default config."""
    env_node = _group_file("env", env)
    per_method = env_node.pop(METHODS_KEY, None) if METHODS_KEY in env_node else None
    yield env_node, "configs/env"
    yield _group_file("method", method), "configs/method"
    if per_method is not None:
        names = group_names("method")
        for name in per_method:
            if name not in names:
                raise ConfigError(f"configs/env/{env}.yaml: {METHODS_KEY}.{name} names no method"
                                  f"{did_you_mean(str(name), names)}; the section's keys are method names: "
                                  f"{', '.join(names)}")
        if method in per_method:
            yield per_method[method], f"configs/env/{env}.yaml {METHODS_KEY}.{method}"


def planner_config(groups: dict[str, str], dotted: Words, env: str, method: str) -> Config:
    """The planner's Config from parsed words (:func:`parse_overrides`); ``env``/``method``: the default groups.
    Order: dataclass defaults, the env then the method YAML (:func:`group_layers`), then the overrides in order."""
    return build(Config, dotted, validate, group_layers(groups.get("env", env), groups.get("method", method)))


def load_config(args: list[str] | None = None, *, env: str = "pointmaze-medium", method: str = "fast-mctd") -> Config:
    """Build and validate a Config from group defaults and ``key=value`` words (see :func:`planner_config`)."""
    groups, dotted, _ = parse_overrides(list(args or []))
    return planner_config(groups, dotted, env, method)


def config_from_dict(d: dict[str, Any]) -> Config:
    """Rebuild a Config from ``Config.to_dict()`` output (checkpoint manifests, Ray payloads); RETIRED fields
    are dropped."""
    d = {k: dict(v) if isinstance(v, dict) else v for k, v in d.items()}
    for key in RETIRED:
        group, _, name = key.partition(".")
        if isinstance(d.get(group), dict):
            d[group].pop(name, None)
    return from_dict(Config, d)
