"""Config of the ant direction expert: dataclass defaults <- ``key=value`` overrides.

A config of its own rather than a section of :class:`fmctd_dist.config.Config`: the
planner's config digest is recorded with every result row and checkpoint, and training a
low-level expert must not change it. Same rules as the planner's config: unknown keys fail
with a suggestion, values are typed by the defaults, and :func:`validate_expert` checks
every field before any env or network is built.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from omegaconf import OmegaConf

from fmctd_dist.config import all_keys, apply_override, merge_checked, resolve_path
from fmctd_dist.errors import ConfigError, did_you_mean

DEFAULT_OUT = "runs/ant-expert"


@dataclass
class AntEnvConfig:
    episode_steps: int = 1000  # time limit of one training episode (OGBench online-ant-v0: 1000)
    resample_every: int = 100  # steps between commanded directions; 0 = one per episode (OGBench: 100)
    healthy_reward: float = 1.0  # per step alive (Gymnasium/OGBench AntEnv default)
    # Weight of sum(action^2). AntEnv's 0.5 was tuned for Gymnasium's gear-150 ant; this one has gear 30, and an
    # open-loop gait measured here makes ~1 m/s for 0.5*|a|^2 ~ 2 per step, so at 0.5 standing still (reward 1)
    # beats walking (~0). 0.05 keeps actions smooth without making locomotion not worth it.
    ctrl_cost: float = 0.05
    reset_noise: float = 0.1  # uniform qpos / normal qvel noise at reset (AntEnv default)


@dataclass
class SACConfig:
    hidden: list[int] = field(default_factory=lambda: [256, 256])  # actor and critic MLP widths (OGBench: 256x256)
    lr: float = 3e-4  # Adam lr of actor, critics and temperature (OGBench 1e-4; 3e-4 learns faster per step)
    gamma: float = 0.99
    tau: float = 0.005  # polyak rate of the target critics
    batch_size: int = 256
    init_alpha: float = 1.0  # initial entropy temperature
    target_entropy_scale: float = 0.5  # target entropy = -scale * act_dim (OGBench 0.5; SAC paper 1.0)
    buffer_size: int = 1_000_000  # replay capacity in transitions


@dataclass
class ExpertTrainConfig:
    out: str = ""  # checkpoint dir; "" -> runs/ant-expert
    max_steps: int = 1_000_000  # env steps (OGBench trained its ant expert 400k steps at 1 update/step)
    start_steps: int = 10_000  # uniform random actions, no updates, before learning (OGBench seed_steps: 10k)
    updates_per_step: int = 1  # SAC updates per env step once learning has started
    seed: int = 0
    threads: int = 1  # torch intra-op threads; 0 = torch default (one per core; slow on busy cores)
    ckpt_every: int = 10_000  # env steps between checkpoints (model.pt + manifest.json + train_state.pt)
    log_every: int = 200  # env steps between progress-bar updates
    buffer_save: int = 200_000  # newest transitions kept in train_state.pt (~54 MB); 0 = none


@dataclass
class ExpertEvalConfig:
    every: int = 20_000  # env steps between direction-following evaluations; 0 = only at the end
    episodes: int = 8  # episode k starts with direction angle 2*pi*k/episodes
    segment_steps: int = 200  # env steps per commanded direction (20 s at 10 Hz)
    segments: int = 2  # directions per episode; segment j turns the direction by j * 90 degrees
    min_speed: float = 0.5  # m/s along the commanded direction for a segment to count as followed
    seed: int = 10_000  # reset-noise seed of evaluation episode k is seed + k (independent of training)


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
    valid = all_keys(AntExpertConfig())
    cfg = OmegaConf.structured(AntExpertConfig)
    for arg in args or []:
        if "=" not in arg:
            raise ConfigError(f"override {arg!r} is not key=value; e.g. expert.max_steps=300000")
        key, value = (s.strip() for s in arg.split("=", 1))
        if key not in valid:
            raise ConfigError(f"unknown config key {key!r}{did_you_mean(key, valid)}")
        cfg = apply_override(cfg, key, value, AntExpertConfig())
    obj: AntExpertConfig = OmegaConf.to_object(cfg)  # type: ignore[assignment]
    validate_expert(obj)
    return obj


def expert_config_from_dict(d: dict[str, Any]) -> AntExpertConfig:
    """Rebuild a config from ``to_dict()`` output (manifests, train states)."""
    cfg = merge_checked(OmegaConf.structured(AntExpertConfig), OmegaConf.create(d), "config dict", AntExpertConfig())
    return OmegaConf.to_object(cfg)  # type: ignore[return-value]


def validate_expert(cfg: AntExpertConfig) -> None:
    """Raise one ConfigError naming the field and the fix."""
    for key in ("expert.max_steps", "expert.updates_per_step", "expert.ckpt_every", "expert.log_every",
                "env.episode_steps", "sac.batch_size", "sac.buffer_size", "sac.lr", "sac.init_alpha",
                "eval.episodes", "eval.segment_steps", "eval.segments"):
        if _get(cfg, key) <= 0:
            raise ConfigError(f"{key}={_get(cfg, key)} must be > 0")
    for key in ("expert.start_steps", "expert.seed", "expert.threads", "expert.buffer_save", "env.resample_every",
                "env.healthy_reward", "env.ctrl_cost", "env.reset_noise", "eval.every", "eval.min_speed",
                "eval.seed", "sac.target_entropy_scale"):
        if _get(cfg, key) < 0:
            raise ConfigError(f"{key}={_get(cfg, key)} must be >= 0")
    if not cfg.sac.hidden or any(h <= 0 for h in cfg.sac.hidden):
        raise ConfigError(f"sac.hidden={cfg.sac.hidden} must be a non-empty list of positive widths, e.g. [256,256]")
    if not 0 < cfg.sac.tau <= 1:
        raise ConfigError(f"sac.tau={cfg.sac.tau} must be in (0, 1]; 0.005 is usual")
    if not 0 <= cfg.sac.gamma < 1:
        raise ConfigError(f"sac.gamma={cfg.sac.gamma} must be in [0, 1); 0.99 is usual")
    if cfg.sac.batch_size > cfg.sac.buffer_size:
        raise ConfigError(f"sac.batch_size={cfg.sac.batch_size} exceeds sac.buffer_size={cfg.sac.buffer_size}")
    if cfg.expert.start_steps < cfg.sac.batch_size:
        raise ConfigError(
            f"expert.start_steps={cfg.expert.start_steps} is below sac.batch_size={cfg.sac.batch_size}: the first "
            "update needs a full batch in the buffer; raise expert.start_steps"
        )


def _get(cfg: AntExpertConfig, dotted: str) -> Any:
    node: Any = cfg
    for part in dotted.split("."):
        node = getattr(node, part)
    return node
