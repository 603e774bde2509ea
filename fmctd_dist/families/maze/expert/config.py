"""Config of the ant direction expert: dataclass defaults <- ``key=value`` overrides.

A config root of its own rather than a section of :class:`fmctd_dist.config.Config`: the
planner's config digest is recorded with every result row and checkpoint, and training a
low-level expert must not change it. Loaded by the one loader (:mod:`fmctd_dist.config.loader`):
unknown keys fail with a suggestion, values are typed by the defaults, ranges are declared beside
each field, and :func:`validate_expert` adds the checks between fields.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fmctd_dist.config import build, check_ranges, from_dict, parse_overrides, resolve_path, spec
from fmctd_dist.errors import ConfigError

DEFAULT_OUT = "runs/ant-expert"


@dataclass
class AntEnvConfig:
    episode_steps: int = spec(1000, gt=0)  # time limit of one training episode (OGBench online-ant-v0: 1000)
    resample_every: int = spec(100, ge=0)  # steps between commanded directions; 0 = one per episode (OGBench: 100)
    healthy_reward: float = spec(1.0, ge=0)  # per step alive (Gymnasium/OGBench AntEnv default)
    # Weight of sum(action^2). AntEnv's 0.5 was tuned for Gymnasium's gear-150 ant; this one has gear 30, and an
    # open-loop gait measured here makes ~1 m/s for 0.5*|a|^2 ~ 2 per step, so at 0.5 standing still (reward 1)
    # beats walking (~0). 0.05 keeps actions smooth without making locomotion not worth it.
    ctrl_cost: float = spec(0.05, ge=0)
    reset_noise: float = spec(0.1, ge=0)  # uniform qpos / normal qvel noise at reset (AntEnv default)


@dataclass
class SACConfig:
    hidden: list[int] = spec(factory=lambda: [256, 256], gt=0, each=True, nonempty=True,
                             why="actor and critic MLP widths, e.g. [256,256] (OGBench)")
    lr: float = spec(3e-4, gt=0)  # Adam lr of actor, critics, temperature (OGBench 1e-4; 3e-4 learns faster per step)
    gamma: float = spec(0.99, ge=0, lt=1, why="0.99 is usual")
    tau: float = spec(0.005, gt=0, le=1, why="polyak rate of the target critics; 0.005 is usual")
    batch_size: int = spec(256, gt=0)
    init_alpha: float = spec(1.0, gt=0)  # initial entropy temperature
    target_entropy_scale: float = spec(0.5, ge=0)  # target entropy = -scale * act_dim (OGBench 0.5; SAC paper 1.0)
    buffer_size: int = spec(1_000_000, gt=0)  # replay capacity in transitions


@dataclass
class ExpertTrainConfig:
    out: str = ""  # checkpoint dir; "" -> runs/ant-expert
    max_steps: int = spec(1_000_000, gt=0)  # env steps (OGBench trained its ant expert 400k steps at 1 update/step)
    start_steps: int = spec(10_000, ge=0)  # uniform random actions, no updates, before learning (OGBench seed_steps)
    updates_per_step: int = spec(1, gt=0)  # SAC updates per env step once learning has started
    seed: int = spec(0, ge=0)
    threads: int = spec(1, ge=0)  # torch intra-op threads; 0 = torch default (one per core; slow on busy cores)
    ckpt_every: int = spec(10_000, gt=0)  # env steps between checkpoints (model.pt + manifest.json + train_state.pt)
    log_every: int = spec(200, gt=0)  # env steps between progress-bar updates
    buffer_save: int = spec(200_000, ge=0)  # newest transitions kept in train_state.pt (~54 MB); 0 = none


@dataclass
class ExpertEvalConfig:
    every: int = spec(20_000, ge=0)  # env steps between direction-following evaluations; 0 = only at the end
    episodes: int = spec(8, gt=0)  # episode k starts with direction angle 2*pi*k/episodes
    segment_steps: int = spec(200, gt=0)  # env steps per commanded direction (20 s at 10 Hz)
    segments: int = spec(2, gt=0)  # directions per episode; segment j turns the direction by j * 90 degrees
    min_speed: float = spec(0.5, ge=0)  # m/s along the commanded direction for a segment to count as followed
    seed: int = spec(10_000, ge=0)  # reset-noise seed of evaluation episode k is seed + k (independent of training)


@dataclass
class AntExpertConfig:
    expert: ExpertTrainConfig = field(default_factory=ExpertTrainConfig)
    env: AntEnvConfig = field(default_factory=AntEnvConfig)
    sac: SACConfig = field(default_factory=SACConfig)
    eval: ExpertEvalConfig = field(default_factory=ExpertEvalConfig)

    def out_dir(self) -> Path:
        return resolve_path(self.expert.out or DEFAULT_OUT)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def load_expert_config(args: list[str] | None = None) -> AntExpertConfig:
    """Defaults, then dotted ``key=value`` overrides in the order given; validated."""
    _, _, words = parse_overrides(list(args or []), AntExpertConfig(), main=False, example="expert.max_steps=300000")
    return build(AntExpertConfig, words, validate_expert)


def expert_config_from_dict(d: dict[str, Any]) -> AntExpertConfig:
    """Rebuild a config from ``to_dict()`` output (manifests, train states)."""
    return from_dict(AntExpertConfig, d)


def validate_expert(cfg: AntExpertConfig) -> None:
    """Declared ranges, then the checks between fields; raise one ConfigError naming the field and the fix."""
    check_ranges(cfg)
    if cfg.sac.batch_size > cfg.sac.buffer_size:
        raise ConfigError(f"sac.batch_size={cfg.sac.batch_size} exceeds sac.buffer_size={cfg.sac.buffer_size}")
    if cfg.expert.start_steps < cfg.sac.batch_size:
        raise ConfigError(
            f"expert.start_steps={cfg.expert.start_steps} is below sac.batch_size={cfg.sac.batch_size}: the first "
            "update needs a full batch in the buffer; raise expert.start_steps"
        )
