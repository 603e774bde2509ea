"""What produced a result row: its plan config (hashed) and checkpoint, so runs never mix.

A row is only comparable with rows of the same *identity*: the config fields that shape a
plan and the checkpoint digest. The hash covers every field except where and how the grid is
run (``ray.*``, ``data.workers``, and ``eval.*`` but ``eval.episode_time_limit``, which decides time-outs), and it
is taken over the fields that differ from their defaults, so adding a config field (with a
default that keeps the old behaviour) does not orphan earlier results. Changing what a default
*means* must bump :data:`CONFIG_SCHEMA`; ``tests/golden/config_defaults.json`` fails the tests
until that is done.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from typing import Any

from fmctd_dist.config import Config
from fmctd_dist.errors import ResultsError

CONFIG_SCHEMA = 1  # bump when a config default changes meaning (tests/golden/config_defaults.json)
RUN_ONLY = ("ray",)  # sections that say where a grid runs, never what a plan is
RUN_ONLY_FIELDS = ("data.workers",)  # fields that say how something is made, never what
EVAL_PLAN_FIELDS = ("episode_time_limit",)  # eval.* fields that change a row's outcome
# Row columns that say which settings made a row: compared when a row predates ``config_json``.
KNOB_COLUMNS = ("parallel", "virtual_weight", "redundancy_aware", "leaf_parallel", "jump", "budget",
                "episode_time_limit")


def _flat(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flat(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def plan_fields(cfg: Config) -> dict[str, Any]:
    """Dotted key -> value of every field that shapes a plan or a row's outcome."""
    flat = _flat(dataclasses.asdict(cfg))
    return {k: v for k, v in flat.items()
            if k.split(".")[0] not in RUN_ONLY and k not in RUN_ONLY_FIELDS
            and (not k.startswith("eval.") or k.split(".", 1)[1] in EVAL_PLAN_FIELDS)}


def plan_config(cfg: Config) -> dict[str, Any]:
    """The plan fields that differ from the defaults (what the hash and ``config_json`` hold)."""
    default = plan_fields(Config())
    return {k: v for k, v in plan_fields(cfg).items() if k not in default or default[k] != v}


def config_hash(cfg: Config) -> str:
    """16 hex digits naming the plan config; equal configs give equal hashes across versions."""
    blob = json.dumps({"schema": CONFIG_SCHEMA, "fields": plan_config(cfg)}, sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def identity_columns(cfg: Config) -> dict[str, Any]:
    """Columns every row carries so that a later run can say exactly what differs."""
    return {"config_hash": config_hash(cfg), "config_schema": CONFIG_SCHEMA,
            "config_json": json.dumps(plan_config(cfg), sort_keys=True, default=str)}


def recorded_config(row: dict[str, Any]) -> Config:
    """The plan config a row was made with: ``Config()``'s defaults with the row's ``config_json`` on top (a row
    records the fields off those defaults, not off its env's and method's config files). Fields outside the plan
    (``eval.out``, ``ray``) keep their defaults. For probes that replay an episode (``jobs/probes/rewalk.py``)."""
    from fmctd_dist.config.loader import config_from_dict

    if not row.get("config_json"):
        raise ResultsError(f"the row of {row.get('method')} {row.get('env')} task {row.get('task')} seed "
                           f"{row.get('seed')} records no config (written before rows recorded one)")
    d = Config().to_dict()
    for key, value in json.loads(row["config_json"]).items():
        *groups, name = key.split(".")
        target = d
        for group in groups:
            target = target[group]
        target[name] = value
    return config_from_dict(d)


def row_identity(row: dict[str, Any]) -> tuple:
    """What a table groups by: rows with different identities are never averaged together.

    Rows written before ``eval.episode_time_limit`` entered the hash carry it as a column.
    """
    return row.get("config_hash"), row.get("checkpoint_digest"), row.get("episode_time_limit")


def changed_fields(row: dict[str, Any], cfg: Config) -> dict[str, tuple[Any, Any]]:
    """Plan fields whose value in a row's recorded config (``config_json``) differs from ``cfg``'s: key ->
    (the row's value, ``cfg``'s value), each read against ``Config()``'s defaults where not recorded."""
    theirs, ours = json.loads(row.get("config_json") or "{}"), plan_config(cfg)
    default = plan_fields(Config())
    pairs = {k: (theirs.get(k, default.get(k)), ours.get(k, default.get(k))) for k in sorted(set(theirs) | set(ours))}
    return {k: (a, b) for k, (a, b) in pairs.items() if a != b}


def differences(row: dict[str, Any], cfg: Config, checkpoint_digest: str, policy_digest: str = "") -> list[str]:
    """Human-readable ``field: rows have A, this run has B`` lines (empty = same identity)."""
    out = []
    if row.get("checkpoint_digest") != checkpoint_digest:
        out.append(f"checkpoint digest: rows have {row.get('checkpoint_digest')}, this run has {checkpoint_digest}")
    if (row.get("policy_digest") or "") != policy_digest:
        out.append(f"low-level policy digest: rows have {row.get('policy_digest') or 'none recorded'}, "
                   f"this run has {policy_digest or 'none'}")
    if row.get("config_hash") == config_hash(cfg):
        return out
    if row.get("config_json"):
        out += [f"{key}: rows have {a!r}, this run has {b!r}" for key, (a, b) in changed_fields(row, cfg).items()]
        if not out or (len(out) == 1 and out[0].startswith("checkpoint")):
            out.append(f"config schema: rows have {row.get('config_schema')}, this run has {CONFIG_SCHEMA} "
                       "(a config default changed meaning)")
        return out
    now = {**dataclasses.asdict(cfg.method), "jump": cfg.jump, "episode_time_limit": cfg.eval.episode_time_limit}
    knobs = [f"{k}: rows have {row[k]!r}, this run has {now[k]!r}" for k in KNOB_COLUMNS
             if k in row and k in now and row[k] != now[k]]
    return out + (knobs or [f"config hash: rows have {row.get('config_hash')}, this run has {config_hash(cfg)} "
                            "(rows written before results recorded their config, so the fields cannot be listed)"])
