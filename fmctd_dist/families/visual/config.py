"""Config of the visual maze's pre-trained parts: ``vae.*``, ``latents.*``, ``estimator.*``, ``invdyn.*``, ``reach.*``.

A config of its own, like the ant expert's (:mod:`fmctd_dist.families.maze.expert.config`): the planner's
config digest is recorded with every result row, and training a VAE must not change it. Which
frames and episodes are used is still the planner's business (``env=``, ``data.*``,
``visual.frames``, ``visual.episodes``), so a job's words are split: these prefixes go here,
everything else to the planner's config, through the one loader (:mod:`fmctd_dist.config.loader`).
Ranges are declared beside each field (``spec``) and checked in one place, as in the planner's config.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fmctd_dist.config import (SEED, THREADS, Config, build, check_ranges, parse_overrides, planner_config,
                               resolve_path, spec)
from fmctd_dist.errors import ConfigError, did_you_mean
from fmctd_dist.registry import require_family

VISUAL_FAMILY = "visual-pointmaze"

LATENT_KEY = "latents"  # the planner manifest's field holding the latent provenance (families/visual/dataset.py)
PARTS = ("vae", "episodes", "latents", "estimator", "invdyn", "reach")
OUT = "where it is written and read; '' -> checkpoints/<env>-<part>"


@dataclass
class VAETrainConfig:
    out: str = ""  # checkpoint dir; "" -> checkpoints/<env>-vae
    latent_dim: int = spec(8, gt=0, why="the paper's 8-D latent")
    # Conv widths, one stride-2 4x4 conv each (64 -> 4 px after four). The authors use 32..512; a CPU gets
    # 32..256 (4x fewer MACs in the last block, ~60 M MACs per image forward).
    channels: list[int] = spec(factory=lambda: [32, 64, 128, 256], gt=0, each=True, nonempty=True,
                               why="one width per stride-2 conv block, e.g. [32,64,128,256]")
    kl_weight: float = spec(1e-6, ge=0, why="beta of the beta-VAE (authors ~1e-6)")
    batch_size: int = spec(32, gt=0, why="images per step (32: more steps in a CPU budget than 64)")
    lr: float = spec(1e-3, gt=0, why="Adam learning rate")
    max_steps: int = spec(200_000, gt=0, why="optimiser steps (time_budget_s usually ends training first)")
    time_budget_s: float = spec(1500.0, ge=0, why="stop after this much training wall time (0 = no limit)")
    seed: int = spec(0, ge=0, why=SEED)
    threads: int = spec(1, ge=0, why=THREADS)
    ckpt_every: int = spec(250, gt=0, why="steps between checkpoints (resume point)")
    val_every: int = spec(250, gt=0, why="steps between held-out reconstruction errors")
    log_every: int = spec(10, gt=0, why="steps between progress-bar updates")


@dataclass
class LatentsConfig:
    out: str = ""  # latent store dir; "" -> data/<env>-latents-<episodes>ep-vae<digest>
    vae: str = ""  # VAE checkpoint dir to encode with; "" -> vae.out's default
    val_episodes: int = spec(5, ge=0, why="validation episodes encoded too (held-out consecutive frames)")
    batch: int = spec(256, gt=0, why="frames per encoder call")


@dataclass
class HeadTrainConfig:
    """An MLP on VAE latents: the position estimator z -> (x, y) or the inverse dynamics (z-, z, z+) -> a."""

    out: str = ""  # checkpoint dir; "" -> checkpoints/<env>-<part>
    vae: str = ""  # VAE checkpoint whose latents it reads (estimator: encodes the VAE frames); "" -> the default
    latents: str = ""  # invdyn: latent store dir; "" -> the default for latents.*
    hidden: list[int] = spec(factory=lambda: [512, 512], gt=0, each=True, nonempty=True,
                             why="MLP widths, each Linear -> ReLU")
    batch_size: int = spec(256, gt=0, why="rows per step")
    lr: float = spec(1e-3, gt=0, why="Adam learning rate")
    max_steps: int = spec(20_000, gt=0, why="optimiser steps")
    time_budget_s: float = spec(600.0, ge=0, why="stop after this much training wall time (0 = no limit)")
    seed: int = spec(0, ge=0, why=SEED)
    threads: int = spec(1, ge=0, why=THREADS)
    ckpt_every: int = spec(1000, gt=0, why="steps between checkpoints (resume point)")
    val_every: int = spec(500, gt=0, why="steps between held-out errors")
    log_every: int = spec(50, gt=0, why="steps between progress-bar updates")


@dataclass
class ReachConfig:
    """part=reach: the inverse dynamics following recorded latent paths of validation episodes, closed loop."""

    segments: int = spec(50, gt=0, why="segments tried")
    steps: int = spec(50, gt=0, why="actions per segment")
    radius: float = spec(1.0, gt=0, why="reached = ends this close to the segment's last position (OGBench: 1.0)")
    seed: int = spec(0, ge=0, why=SEED)
    threads: int = spec(1, ge=0, why=THREADS)


@dataclass
class PartsConfig:
    vae: VAETrainConfig = field(default_factory=VAETrainConfig)
    latents: LatentsConfig = field(default_factory=LatentsConfig)
    estimator: HeadTrainConfig = field(default_factory=HeadTrainConfig)
    invdyn: HeadTrainConfig = field(default_factory=lambda: HeadTrainConfig(hidden=[1024, 1024]))  # authors' 2 x 1024
    reach: ReachConfig = field(default_factory=ReachConfig)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def part_dir(cfg: Config, out: str, part: str) -> Path:
    """``out`` resolved, or the default ``checkpoints/<env>-<part>``."""
    return resolve_path(out or f"checkpoints/{cfg.env.name}-{part}")


def load_parts_args(args: list[str] | None = None) -> tuple[Config, PartsConfig, str]:
    """Split ``key=value`` words: ``part=`` names the part, ``vae.*`` ... ``reach.*`` -> PartsConfig, the rest ->
    the planner's Config."""
    groups, dotted, pwords = parse_overrides(list(args or []), PartsConfig(), special=("part",),
                                             example="part=vae or vae.time_budget_s=600")
    part = groups.pop("part", None)
    if part is None:
        raise ConfigError(f"part= is missing; choose one of: {', '.join(PARTS)} (in that order: each needs the last)")
    if part not in PARTS:
        raise ConfigError(f"part={part!r} is not known{did_you_mean(part, PARTS)}; choose one of: {', '.join(PARTS)}")
    cfg = planner_config(groups, dotted, env="visual-pointmaze-medium", method="mctd")
    require_family(cfg.env.name, (VISUAL_FAMILY,), "the visual maze's VAE, estimator and inverse dynamics")
    return cfg, build(PartsConfig, pwords, check_ranges), part
