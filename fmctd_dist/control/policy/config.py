"""Config of the goal-conditioned policy (ant, cube): ``policy.*`` (network, data, training), ``reach.*`` (its test).

A config of its own, like the expert's (:mod:`fmctd_dist.families.maze.expert.config`): the planner's config
digest is recorded with every result row, and training a low-level policy must not change
it. The dataset is still named by the planner's keys (``env=``, ``data.root``,
``data.episodes``, ...), so a job's words are split: ``policy.*`` / ``reach.*`` go here,
everything else to the planner's config, through the one loader (:mod:`fmctd_dist.config.loader`). A
field's default is the ant's unless ``FAMILY_DEFAULTS`` gives the cube another (words on the command line
win over both).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fmctd_dist.config import (Config, build, check_ranges, from_dict, parse_overrides, planner_config, resolve_path,
                               spec)
from fmctd_dist.control.policy.spec import require_policy

# Per-family defaults that differ from the ant's (the dataclass defaults). The cube's reach test follows a
# whole pick-and-place (up to ~100 steps) to OGBench's 0.04 m success radius (0.4 obs units).
FAMILY_DEFAULTS: dict[str, dict[str, Any]] = {
    "cube": {"reach.rows": 100, "reach.max_steps": 150, "reach.radius": 0.4},
}


@dataclass
class PolicyTrainConfig:
    out: str = ""  # policy dir (training writes it, evaluation reads it); "" -> runs/<env>-policy
    hidden: list[int] = spec(factory=lambda: [256, 256, 256], gt=0, each=True, nonempty=True,
                             why="MLP widths, each Linear -> LayerNorm -> ReLU, e.g. [256,256,256]")
    # Hindsight subgoal of row t = the ant's x, y at t + k, k = the sum of geom_draws Geometric(geom_p) draws
    # (each >= 1), cut at the episode's (or the upright run's) end. 2 x Geometric(0.2): mean 10 steps, mode 5-6,
    # 90% within 2..19 steps (see fmctd_dist.families.maze.ant_policy_rows.sample_offsets).
    geom_p: float = spec(0.2, gt=0, le=1, why="mean offset = policy.geom_draws / geom_p")
    geom_draws: int = spec(2, gt=0)
    # the relative subgoal's norm is clipped here (input and training); 0 = no clip
    max_subgoal_dist: float = spec(4.0, ge=0)
    drop_fallen: bool = True  # ant: train only on rows where it is healthy and upright (a fallen ant never recovers)
    # Optimiser steps. 100k x 256 ~ 29 passes over full medium data (~0.88M upright rows), ~9 min on one busy
    # core. Small data overfits: 20 episodes peak at ~2k steps (manifest metrics best_val_step tells).
    max_steps: int = spec(100_000, gt=0)
    batch_size: int = spec(256, gt=0)
    lr: float = spec(3e-4, gt=0)  # Adam
    weight_decay: float = spec(0.0, ge=0)  # AdamW decoupled weight decay
    seed: int = spec(0, ge=0)  # init, batches and the fixed validation set
    threads: int = spec(1, ge=0)  # torch intra-op threads; 0 = torch default (one per core; slow on busy cores)
    # stop at the first checkpoint after this many seconds of this call (0 = none)
    time_budget_s: float = spec(0.0, ge=0)
    ckpt_every: int = spec(1000, gt=0)  # steps between checkpoints (model.pt + manifest.json + train_state.pt)
    val_every: int = spec(1000, gt=0)  # steps between validation losses
    val_rows: int = spec(4096, gt=0)  # fixed (row, subgoal) pairs drawn once from the val split
    log_every: int = spec(50, gt=0)  # steps between progress-bar updates


@dataclass
class ReachConfig:
    rows: int = spec(200, ge=0)  # val rows tried (0 = no reach evaluation at the end of training)
    offset: int = spec(10, gt=0)  # ant: subgoal = the val episode's x, y this many steps on; cube: the subgoal interval
    max_steps: int = spec(50, gt=0)  # env steps per try (cube default 150)
    # reached = within this of the goal after a step (ant: its advance radius; cube default 0.4)
    radius: float = spec(1.0, gt=0)
    # cube: the subgoal moves on once the cube is within this of it (obs units, the authors')
    advance: float = spec(1.0, gt=0)
    seed: int = spec(0, ge=0)  # which rows
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
    groups, dotted, pwords = parse_overrides(list(args or []), PolicyConfig(),
                                             example="env=antmaze-medium or policy.max_steps=5000")
    cfg = planner_config(groups, dotted, env="antmaze-medium", method="mctd")  # cube: no planner yet
    family = require_policy(cfg.env.name).family  # a point maze: one ConfigError (it has the PD controller)
    defaults = [(key, str(value)) for key, value in FAMILY_DEFAULTS.get(family, {}).items()]
    return cfg, build(PolicyConfig, [*defaults, *pwords], check_ranges)  # every check is a declared range


def policy_config_from_dict(d: dict[str, Any]) -> PolicyConfig:
    """Rebuild from ``to_dict()`` output (manifests, train states)."""
    return from_dict(PolicyConfig, d)
