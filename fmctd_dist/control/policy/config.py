"""Config of the goal-conditioned policy (ant, cube): ``policy.*`` (network, data, training), ``reach.*`` (its test).

A config of its own, like the expert's (:mod:`fmctd_dist.families.maze.expert.config`): the planner's config
digest is recorded with every result row, and training a low-level policy must not change
it. The dataset is still named by the planner's keys (``env=``, ``data.root``,
``data.episodes``, ...), so a job's words are split: ``policy.*`` / ``reach.*`` go here,
everything else to :func:`fmctd_dist.config.load_config`. A field's default is the ant's unless
``FAMILY_DEFAULTS`` gives the cube another (words on the command line win over both).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from omegaconf import OmegaConf

from fmctd_dist.config import ALIASES, GROUPS, Config, all_keys, apply_override, load_config, merge_checked, \
    resolve_path
from fmctd_dist.control.policy.spec import require_policy
from fmctd_dist.errors import ConfigError, did_you_mean

PREFIXES = ("policy.", "reach.")
# Per-family defaults that differ from the ant's (the dataclass defaults). The cube's reach test follows a
# whole pick-and-place (up to ~100 steps) to OGBench's 0.04 m success radius (0.4 obs units).
FAMILY_DEFAULTS: dict[str, dict[str, Any]] = {
    "cube": {"reach.rows": 100, "reach.max_steps": 150, "reach.radius": 0.4},
}


@dataclass
class PolicyTrainConfig:
    out: str = ""  # policy dir (training writes it, evaluation reads it); "" -> runs/<env>-policy
    hidden: list[int] = field(default_factory=lambda: [256, 256, 256])  # MLP widths, each Linear -> LayerNorm -> ReLU
    # Hindsight subgoal of row t = the ant's x, y at t + k, k = the sum of geom_draws Geometric(geom_p) draws
    # (each >= 1), cut at the episode's (or the upright run's) end. 2 x Geometric(0.2): mean 10 steps, mode 5-6,
    # 90% within 2..19 steps (see fmctd_dist.families.maze.ant_policy_rows.sample_offsets).
    geom_p: float = 0.2
    geom_draws: int = 2
    max_subgoal_dist: float = 4.0  # the relative subgoal's norm is clipped here (input and training); 0 = no clip
    drop_fallen: bool = True  # ant: train only on rows where it is healthy and upright (a fallen ant never recovers)
    # Optimiser steps. 100k x 256 ~ 29 passes over full medium data (~0.88M upright rows), ~9 min on one busy
    # core. Small data overfits: 20 episodes peak at ~2k steps (manifest metrics best_val_step tells).
    max_steps: int = 100_000
    batch_size: int = 256
    lr: float = 3e-4  # Adam
    weight_decay: float = 0.0  # AdamW decoupled weight decay
    seed: int = 0  # init, batches and the fixed validation set
    threads: int = 1  # torch intra-op threads; 0 = torch default (one per core; slow on busy cores)
    time_budget_s: float = 0.0  # stop at the first checkpoint after this many seconds of this call (0 = none)
    ckpt_every: int = 1000  # steps between checkpoints (model.pt + manifest.json + train_state.pt)
    val_every: int = 1000  # steps between validation losses
    val_rows: int = 4096  # fixed (row, subgoal) pairs drawn once from the val split
    log_every: int = 50  # steps between progress-bar updates


@dataclass
class ReachConfig:
    rows: int = 200  # val rows tried (0 = no reach evaluation at the end of training)
    offset: int = 10  # ant: subgoal = the val episode's x, y this many steps on; cube: the subgoal interval
    max_steps: int = 50  # env steps per try (cube default 150)
    radius: float = 1.0  # reached = within this of the goal after a step (ant: its advance radius; cube default 0.4)
    advance: float = 1.0  # cube: the subgoal moves on once the cube is within this of it (obs units, the authors')
    seed: int = 0  # which rows
    expert: bool = True  # also measure the family's scripted reference (ant expert / OGBench's CubePlanOracle) ...
    zero: bool = True  # ... and zero actions (the floor)


@dataclass
class PolicyConfig:
    policy: PolicyTrainConfig = field(default_factory=PolicyTrainConfig)
    reach: ReachConfig = field(default_factory=ReachConfig)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def default_out(env_name: str) -> str:
    return f"runs/{env_name}-policy"


def policy_dir(cfg: Config, pcfg: PolicyConfig) -> Path:
    return resolve_path(pcfg.policy.out or default_out(cfg.env.name))


def load_policy_args(args: list[str] | None = None) -> tuple[Config, PolicyConfig]:
    """Split ``key=value`` words: ``policy.*`` / ``reach.*`` -> PolicyConfig, the rest -> the planner's Config."""
    pkeys = all_keys(PolicyConfig())
    cfg_words: list[str] = []
    pwords: list[tuple[str, str]] = []
    for arg in args or []:
        if "=" not in arg:
            raise ConfigError(f"override {arg!r} is not key=value; e.g. env=antmaze-medium or policy.max_steps=5000")
        key, value = (s.strip() for s in arg.split("=", 1))
        if key.startswith(PREFIXES):
            if key not in pkeys:
                raise ConfigError(f"unknown config key {key!r}{did_you_mean(key, pkeys)}")
            pwords.append((key, value))
            continue
        known = all_keys(Config()) + list(GROUPS) + list(ALIASES)
        if key not in known:
            raise ConfigError(f"unknown config key {key!r}{did_you_mean(key, known + pkeys)}")
        cfg_words.append(arg)
    cfg = load_config(cfg_words, env="antmaze-medium", method="mctd")  # cube: no planner yet
    spec = require_policy(cfg.env.name)  # a point maze: one ConfigError (it has the PD controller)
    pcfg = OmegaConf.structured(PolicyConfig)
    for key, value in [*FAMILY_DEFAULTS.get(spec.family, {}).items(), *pwords]:
        pcfg = apply_override(pcfg, key, str(value), PolicyConfig())
    obj: PolicyConfig = OmegaConf.to_object(pcfg)  # type: ignore[assignment]
    validate_policy(obj)
    return cfg, obj


def policy_config_from_dict(d: dict[str, Any]) -> PolicyConfig:
    """Rebuild from ``to_dict()`` output (manifests, train states)."""
    cfg = merge_checked(OmegaConf.structured(PolicyConfig), OmegaConf.create(d), "config dict", PolicyConfig())
    return OmegaConf.to_object(cfg)  # type: ignore[return-value]


def validate_policy(cfg: PolicyConfig) -> None:
    """Raise one ConfigError naming the field and the fix."""
    p, r = cfg.policy, cfg.reach
    for key, value in (("policy.max_steps", p.max_steps), ("policy.batch_size", p.batch_size), ("policy.lr", p.lr),
                       ("policy.geom_draws", p.geom_draws), ("policy.ckpt_every", p.ckpt_every),
                       ("policy.val_every", p.val_every), ("policy.val_rows", p.val_rows),
                       ("policy.log_every", p.log_every), ("reach.offset", r.offset),
                       ("reach.max_steps", r.max_steps), ("reach.radius", r.radius), ("reach.advance", r.advance)):
        if value <= 0:
            raise ConfigError(f"{key}={value} must be > 0")
    for key, value in (("policy.weight_decay", p.weight_decay), ("policy.seed", p.seed),
                       ("policy.threads", p.threads), ("policy.max_subgoal_dist", p.max_subgoal_dist),
                       ("policy.time_budget_s", p.time_budget_s),
                       ("reach.rows", r.rows), ("reach.seed", r.seed)):
        if value < 0:
            raise ConfigError(f"{key}={value} must be >= 0")
    if not 0 < p.geom_p <= 1:
        raise ConfigError(f"policy.geom_p={p.geom_p} must be in (0, 1]; mean offset = policy.geom_draws / geom_p")
    if not p.hidden or any(h <= 0 for h in p.hidden):
        raise ConfigError(f"policy.hidden={p.hidden} must be a non-empty list of positive widths, e.g. [256,256,256]")
