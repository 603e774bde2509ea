"""Structured configs: dataclass defaults <- configs/<group>/<name>.yaml <- ``key=value`` overrides.

Every job builds its config with :func:`load_config`; nothing else reads YAML. Unknown keys,
unknown group names and ill-typed values raise one :class:`ConfigError` with a suggestion,
and :func:`validate` checks the fields that depend on each other (horizons, budgets, seeds)
before any dataset, model or Ray actor is touched.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from omegaconf import MISSING, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from fmctd_dist.errors import ConfigError, did_you_mean, unknown_name

REPO_ROOT = Path(__file__).resolve().parent.parent
CONFIG_DIR = REPO_ROOT / "configs"

MAZES = ("medium", "large", "giant")
POINT_ENVS = tuple(f"pointmaze-{m}" for m in MAZES)
ANT_ENVS = tuple(f"antmaze-{m}" for m in MAZES)
ENV_NAMES = POINT_ENVS + ANT_ENVS
UNET_PADDINGS = ("zeros", "replicate")
TASK_IDS = (1, 2, 3, 4, 5)
DEVICES = ("cpu", "cuda", "auto")
RUNNERS = ("local", "ray")
PLANNERS = ("mctd", "diffusion_forcing", "diffuser")
PROTOCOLS = ("fixed", "ogbench")
MODEL_KINDS = ("df", "diffuser")
BETA_SCHEDULES = ("linear", "cosine")  # same names as diffusion.schedule.BETA_SCHEDULES

# Top-level shorthands accepted on the command line (`tasks=[1] seeds=[0] runner=local`).
ALIASES = {"tasks": "eval.tasks", "seeds": "eval.seeds", "runner": "eval.runner"}
# Keys whose value names a YAML file under configs/<group>/ instead of a plain value.
GROUPS = ("env", "method")


@dataclass
class EnvConfig:
    name: str = "pointmaze-medium"  # pointmaze-{medium,large,giant} | antmaze-{medium,large,giant}
    protocol: str = "fixed"  # fixed: start/goal at cell centres (paper); ogbench: stock +-1 noise
    max_steps: int = 500  # env step budget of one evaluation episode (500/500/1000)
    horizon: int = 500  # planning horizon in env steps; plan frames = horizon / jump
    policy: str = ""  # antmaze: low-level policy dir ("" -> checkpoints/<env>-policy); unused for pointmaze


@dataclass
class DataConfig:
    root: str = "data"  # dataset cache dir (relative paths are under the repo root)
    seed: int = 0  # generator seed: same seed -> same bytes
    episodes: int = 1000  # training episodes (OGBench navigate: 1000, giant 500)
    episode_steps: int = 1001  # steps per episode (OGBench: 1001, giant 2001)
    noise: float = 0.5  # action noise std (OGBench: pointmaze oracle 0.5, antmaze expert 0.2)
    expert: str = "checkpoints/ant-expert"  # antmaze only: the ant expert dir whose actions make the data
    val_fraction: float = 0.1  # extra validation episodes as a fraction of `episodes`
    train_window: int = 500  # raw env steps in one training window (= env.horizon)


@dataclass
class ModelConfig:
    kind: str = "df"  # df: Diffusion Forcing transformer | diffuser: Janner's temporal U-Net
    frame_stack: int = 10  # frames per token
    width: int = 128  # d_model (paper 128)
    layers: int = 6  # transformer layers (paper 12; 6 trains 2x faster on CPU, see docs/results.md)
    heads: int = 4  # attention heads (paper 4)
    ff: int = 512  # feed-forward width (paper 512)
    unet_channels: list[int] = field(default_factory=lambda: [32, 128, 256])  # kind=diffuser: widths per resolution
    unet_kernel: int = 5  # kind=diffuser: temporal conv kernel size
    # kind=diffuser: how the convs pad the time axis. zeros (Janner's): the frames before the start
    # read as the normalised origin; replicate: as the start itself (see docs/results.md section 3.1)
    unet_padding: str = "zeros"
    # kind=diffuser: frames added at each end of the sequence before the U-Net (point reflections
    # 2 x_0 - x_i of the plan about its end frames, cropped after), so the plan's first and last
    # frames are computed like interior ones. 0 = Janner's U-Net (see docs/results.md section 3.1)
    unet_edge_frames: int = 0


@dataclass
class DiffusionConfig:
    timesteps: int = 1000  # training diffusion steps
    beta_schedule: str = "linear"  # linear (Diffusion Forcing) | cosine (Diffuser)
    levels: int = 50  # DDIM sampling levels
    beta_start: float = 1e-4
    beta_end: float = 0.02
    stabilization: int = 10  # clean tokens are fed as timestep stabilization-1
    snr_clip: float = 5.0  # min-SNR loss weight clip
    clip_noise: float = 20.0  # initial noise clipped to +-clip_noise


@dataclass
class TrainConfig:
    max_steps: int = 8000  # optimiser steps (paper 200k at batch 1024 on GPU; see docs/results.md)
    batch_size: int = 256
    lr: float = 5e-4
    weight_decay: float = 1e-4
    warmup: int = 1000  # linear warm-up steps
    ema_decay: float = 0.999  # shipped weights are an EMA of the trained ones; 0 = off
    ckpt_every: int = 500  # steps between resumable checkpoints
    val_every: int = 1000  # steps between validation-loss evaluations
    val_batches: int = 8  # batches per validation-loss evaluation
    seed: int = 0
    out: str = ""  # checkpoint dir; "" -> runs/<env>-h<jump> (ship with train.out=checkpoints/<env>-h<jump>)
    threads: int = 0  # torch intra-op threads; 0 = torch default
    # A checkpoint dir whose weights start a fresh run (fine-tuning, e.g. an AntMaze model from the
    # PointMaze one of the same maze): same architecture, any env / horizon. Recorded in the manifest;
    # ignored when train.out already holds a run to resume.
    init_from: str = ""
    # Diffuser only (Janner et al.'s ``loss_discount``): plan frame f is weighted discount**f in the
    # x0 loss (weights normalised to mean 1). 1.0 = uniform, the paper's and Janner's maze setting.
    loss_discount: float = 1.0
    # Training windows drawn with weight count(start's 1x1 grid cell)**-start_balance (0 = uniform,
    # the paper's). Leaves p(plan | start) unchanged; see fmctd_dist.data.windows.start_balance_cdf.
    start_balance: float = 0.0


@dataclass
class MethodConfig:
    name: str = "fast-mctd"
    planner: str = "mctd"  # mctd | diffusion_forcing | diffuser
    parallel: int = 200  # K: rollouts per iteration (1 = sequential MCTD)
    virtual_weight: float = 1.0  # w: weight of virtual visits in UCT
    redundancy_aware: bool = True  # each empty slot claimed at most once per batch
    leaf_parallel: bool = False  # a selected child gets |children| virtual visits
    guidance_scales: list[float] = field(default_factory=lambda: [0.0, 0.1, 0.5, 1.0, 2.0])
    budget: int = 500  # expansion budget (expanded nodes)
    segment_transitions: int = 20  # DDIM transitions per tree depth
    sim_skip: int = 10  # jumpy simulation: rows skipped per transition
    warp_threshold: float = 2.0  # max plan step (world units) before a plan is a warp
    goal_radius: float = 2.0  # value: plan reaches goal within this radius
    bad_plan_tries: int = 10  # re-sample plans that barely move
    bad_plan_step: float = 0.1  # a plan "barely moves" if every step is below this
    uct_c: float = 1.4142135623730951
    early_stop: bool = True  # stop when a new node's own plan reaches the goal
    replan_every: int = 0  # env steps between replans; 0 = plan once (open loop)
    guidance_scale: float = 2.0  # fixed scale for planners without search
    # Diffuser only: RePaint resampling U (each level re-visited U times; 1 = plain DDIM, the paper's)
    resample: int = 1


@dataclass
class EvalConfig:
    runner: str = "ray"  # ray (local cluster, or the running one) | local (no Ray, one process)
    tasks: list[int] = field(default_factory=lambda: [1, 2, 3, 4, 5])
    seeds: list[int] = field(default_factory=lambda: list(range(10)))
    out: str = "results"  # results root; rows go to <out>/<run>/<method>/<env>/...
    run: str = "default"
    episode_time_limit: float = 0.0  # seconds of planning per episode; 0 = none
    threads: int = 0  # torch threads of an in-process denoiser (runner=local, bench_speed); 0 = torch default.
    # Set 1 when other jobs share the cores: 2 spinning threads on a busy 2-core machine run 10x slower.


@dataclass
class RayConfig:
    address: str = ""  # "" -> join a running cluster if there is one, else start local
    denoiser_actors: int = 1
    env_actors: int = 2
    micro_batch: int = 8  # M: jobs per denoiser call (fixed shapes -> determinism); raise on GPUs
    num_gpus: float = 0.0  # per denoiser actor
    num_cpus: float = 1.0  # per denoiser actor
    call_timeout_s: float = 300.0  # a micro-batch slower than this is re-routed
    max_restarts: int = 3  # per denoiser actor; 0 = a dead actor stays dead (its work is re-routed)


@dataclass
class Config:
    env: EnvConfig = field(default_factory=EnvConfig)
    data: DataConfig = field(default_factory=DataConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    diffusion: DiffusionConfig = field(default_factory=DiffusionConfig)
    train: TrainConfig = field(default_factory=TrainConfig)
    method: MethodConfig = field(default_factory=MethodConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)
    ray: RayConfig = field(default_factory=RayConfig)
    jump: int = 1  # H: plan on trajectories subsampled every H env steps (S-MCTD)
    device: str = "cpu"  # cpu | cuda | auto
    checkpoint: str = ""  # checkpoint dir; "" -> checkpoints/<env>-h<jump> (model.kind=diffuser: <env>-diffuser)
    seed: int = 0  # planning seed offset (episode seeds come from eval.seeds)

    # ---- derived quantities (read-only helpers) ----
    @property
    def plan_frames(self) -> int:
        """Frames in one plan (excluding the start frame)."""
        return self.env.horizon // self.jump

    @property
    def plan_tokens(self) -> int:
        """P: plan tokens, excluding the context token."""
        return self.plan_frames // self.model.frame_stack

    @property
    def n_tokens(self) -> int:
        """Tokens the model sees: context + P plan tokens."""
        return self.plan_tokens + 1

    @property
    def token_dim(self) -> int:
        return 2 * self.model.frame_stack

    @property
    def run_name(self) -> str:
        """<env>-h<jump> (Diffusion Forcing models) or <env>-diffuser: default checkpoint/run dir name."""
        return f"{self.env.name}-diffuser" if self.model.kind == "diffuser" else f"{self.env.name}-h{self.jump}"

    def checkpoint_dir(self) -> Path:
        return resolve_path(self.checkpoint or f"checkpoints/{self.run_name}")

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def digest(self) -> str:
        """Short hash of the whole config (recorded with every result row)."""
        blob = json.dumps(self.to_dict(), sort_keys=True).encode()
        return hashlib.sha256(blob).hexdigest()[:16]


def is_ant(env_name: str) -> bool:
    """AntMaze (29-D ant state, 8-D torque actions) rather than PointMaze (2-D position and action)."""
    return env_name in ANT_ENVS


def git_sha() -> str:
    """The repository's HEAD commit, recorded in manifests and result rows ("unknown" outside git)."""
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO_ROOT, capture_output=True, text=True, timeout=10)
        return out.stdout.strip() if out.returncode == 0 else "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def resolve_path(p: str | Path) -> Path:
    p = Path(p).expanduser()
    return p if p.is_absolute() else REPO_ROOT / p


def all_keys(node: Any, prefix: str = "") -> list[str]:
    """Every dotted leaf key of a dataclass config instance (what an override may name)."""
    keys = []
    for f in dataclasses.fields(node):
        value = getattr(node, f.name)
        name = f"{prefix}{f.name}"
        if dataclasses.is_dataclass(value):
            keys.extend(all_keys(value, name + "."))
        else:
            keys.append(name)
    return keys


def group_names(group: str) -> list[str]:
    return sorted(p.stem for p in (CONFIG_DIR / group).glob("*.yaml"))


def _group_file(group: str, name: str) -> Any:
    path = CONFIG_DIR / group / f"{name}.yaml"
    if not path.is_file():
        raise unknown_name(group, name, group_names(group))
    return OmegaConf.load(path)


def merge_checked(base: Any, update: Any, where: str, schema: Any = None) -> Any:
    """OmegaConf.merge; a bad key or type becomes one ConfigError naming the key (and its type).

    ``schema`` is the dataclass instance the keys come from (default: ``Config()``).
    """
    try:
        return OmegaConf.merge(base, update)
    except OmegaConfBaseException as e:
        schema = Config() if schema is None else schema
        key = getattr(e, "full_key", "") or ""
        msg = str(getattr(e, "msg", e)).splitlines()[0]
        valid = all_keys(schema)
        if key in valid:
            raise ConfigError(f"{where}: {key}: {msg}; expected {_type_name(schema, key)}") from None
        raise ConfigError(f"{where}: unknown config key {key!r}{did_you_mean(key, valid)}") from None


def apply_override(cfg: Any, key: str, value: str, schema: Any = None) -> Any:
    """Merge one dotted ``key=value`` into ``cfg``, the value typed as YAML (``1`` int, ``[1,2]`` list)."""
    try:
        parsed = OmegaConf.create({"v": OmegaConf.from_dotlist([f"v={value}"]).v}).v
    except OmegaConfBaseException as e:
        raise ConfigError(f"{key}={value!r} could not be parsed: {e}") from None
    upd = OmegaConf.create()
    OmegaConf.update(upd, key, parsed, force_add=True)
    return merge_checked(cfg, upd, f"override {key}={value}", schema)


def _type_name(schema: Any, dotted: str) -> str:
    node: Any = schema
    *parents, leaf = dotted.split(".")
    for part in parents:
        node = getattr(node, part)
    ftype = {f.name: f.type for f in dataclasses.fields(node)}[leaf]
    return str(ftype).replace("typing.", "")


def parse_overrides(args: list[str]) -> tuple[dict[str, str], list[tuple[str, str]]]:
    """Split CLI words into group selections (env=..., method=...) and dotted overrides."""
    groups: dict[str, str] = {}
    dotted: list[tuple[str, str]] = []
    valid = all_keys(Config())
    for arg in args:
        if "=" not in arg:
            raise ConfigError(f"override {arg!r} is not key=value; e.g. env=pointmaze-giant or train.max_steps=200")
        key, value = arg.split("=", 1)
        key = ALIASES.get(key.strip(), key.strip())
        if key in GROUPS:
            groups[key] = value.strip()
        elif key in valid:
            dotted.append((key, value))
        else:
            raise ConfigError(f"unknown config key {key!r}{did_you_mean(key, valid + list(GROUPS) + list(ALIASES))}")
    return groups, dotted


def load_config(args: list[str] | None = None, *, env: str = "pointmaze-medium", method: str = "fast-mctd") -> Config:
    """Build and validate a Config from group defaults and ``key=value`` words.

    Order: dataclass defaults, configs/env/<env>.yaml, configs/method/<method>.yaml, then
    dotted overrides in the order given. ``env``/``method`` give the default group names.
    """
    groups, dotted = parse_overrides(list(args or []))
    cfg = OmegaConf.structured(Config)
    cfg = merge_checked(cfg, _group_file("env", groups.get("env", env)), "configs/env")
    cfg = merge_checked(cfg, _group_file("method", groups.get("method", method)), "configs/method")
    for key, value in dotted:
        cfg = apply_override(cfg, key, value)
    obj: Config = OmegaConf.to_object(cfg)  # type: ignore[assignment]
    validate(obj)
    return obj


def config_from_dict(d: dict[str, Any]) -> Config:
    """Rebuild a Config from ``Config.to_dict()`` output (checkpoint manifests, Ray payloads)."""
    cfg = merge_checked(OmegaConf.structured(Config), OmegaConf.create(d), "config dict")
    return OmegaConf.to_object(cfg)  # type: ignore[return-value]


def validate(cfg: Config) -> None:
    """Cross-field checks; raise one ConfigError naming the field and the fix."""
    if cfg.env.name not in ENV_NAMES:
        raise unknown_name("env.name", cfg.env.name, ENV_NAMES)
    if cfg.env.protocol not in PROTOCOLS:
        raise unknown_name("env.protocol", cfg.env.protocol, PROTOCOLS)
    if cfg.device not in DEVICES:
        raise unknown_name("device", cfg.device, DEVICES)
    if cfg.eval.runner not in RUNNERS:
        raise unknown_name("eval.runner", cfg.eval.runner, RUNNERS)
    if cfg.method.planner not in PLANNERS:
        raise unknown_name("method.planner", cfg.method.planner, PLANNERS)
    if cfg.model.kind not in MODEL_KINDS:
        raise unknown_name("model.kind", cfg.model.kind, MODEL_KINDS)
    if cfg.diffusion.beta_schedule not in BETA_SCHEDULES:
        raise unknown_name("diffusion.beta_schedule", cfg.diffusion.beta_schedule, BETA_SCHEDULES)
    if cfg.model.kind == "diffuser" and cfg.method.planner != "diffuser":
        raise ConfigError(
            f"model.kind=diffuser with method.planner={cfg.method.planner}: the U-Net gives all plan tokens one "
            "noise level, but this planner needs per-token levels; use method=diffuser (or diffuser-replan), "
            "or model.kind=df"
        )
    if cfg.model.kind == "diffuser":
        ch, k = cfg.model.unet_channels, cfg.model.unet_kernel
        if not ch or any(c <= 0 or c % 8 for c in ch):
            raise ConfigError(f"model.unet_channels={ch} must be a non-empty list of positive multiples of 8 "
                              "(GroupNorm with 8 groups), e.g. [32, 128, 256]")
        if k < 1 or k % 2 == 0:
            raise ConfigError(f"model.unet_kernel={k} must be a positive odd number (same-length convs), e.g. 5")
        if cfg.model.unet_padding not in UNET_PADDINGS:
            raise ConfigError(f"model.unet_padding={cfg.model.unet_padding!r} is not one of {list(UNET_PADDINGS)}; "
                              "zeros is Janner's U-Net, replicate pads with the edge frames")
        if not 0 <= cfg.model.unet_edge_frames < cfg.plan_tokens:
            raise ConfigError(f"model.unet_edge_frames={cfg.model.unet_edge_frames} must be in [0, {cfg.plan_tokens}) "
                              "(fewer than the plan's frames); 0 is Janner's U-Net, 8 reflects 8 frames at each end")
    if not 0.0 < cfg.train.loss_discount <= 1.0:
        raise ConfigError(f"train.loss_discount={cfg.train.loss_discount} must be in (0, 1]: plan frame f is "
                          "weighted discount**f (1.0 = uniform, the paper's setting)")
    if not 0.0 <= cfg.train.start_balance <= 1.0:
        raise ConfigError(f"train.start_balance={cfg.train.start_balance} must be in [0, 1]: windows are drawn with "
                          "weight count(start cell)**-start_balance (0 = uniform, the paper's; 1 = every start cell alike)")
    _positive(cfg, "jump", "env.max_steps", "env.horizon", "model.frame_stack", "data.episodes",
              "data.episode_steps", "data.train_window", "train.max_steps", "train.batch_size",
              "train.ckpt_every", "method.parallel", "method.budget", "method.segment_transitions",
              "method.sim_skip", "method.resample", "ray.denoiser_actors", "ray.env_actors", "ray.micro_batch",
              "ray.call_timeout_s", "diffusion.levels", "diffusion.timesteps")
    _non_negative(cfg, "data.seed", "train.seed", "seed", "method.virtual_weight", "data.noise",
                  "method.replan_every", "eval.episode_time_limit", "ray.num_gpus",
                  "ray.max_restarts", "eval.threads", "train.threads")
    step = cfg.jump * cfg.model.frame_stack
    if cfg.env.horizon % step:
        raise ConfigError(
            f"env.horizon={cfg.env.horizon} is not divisible by jump x model.frame_stack = "
            f"{cfg.jump} x {cfg.model.frame_stack} = {step}; pick a horizon that is a multiple of {step}"
        )
    if cfg.data.train_window % step:
        raise ConfigError(
            f"data.train_window={cfg.data.train_window} is not divisible by jump x model.frame_stack = {step}; "
            f"use a multiple of {step} (normally data.train_window = env.horizon)"
        )
    if cfg.data.train_window != cfg.env.horizon:
        raise ConfigError(
            f"data.train_window={cfg.data.train_window} differs from env.horizon={cfg.env.horizon}: the model is "
            "trained on windows of the planning horizon; set both to the same number of env steps"
        )
    if cfg.data.train_window + 1 > cfg.data.episode_steps:
        raise ConfigError(
            f"data.train_window={cfg.data.train_window} needs episodes of at least {cfg.data.train_window + 1} "
            f"steps but data.episode_steps={cfg.data.episode_steps}; raise data.episode_steps"
        )
    if cfg.env.horizon > cfg.env.max_steps:
        raise ConfigError(
            f"env.horizon={cfg.env.horizon} exceeds env.max_steps={cfg.env.max_steps}; a plan cannot be longer "
            "than the episode budget"
        )
    if not 0 <= cfg.data.val_fraction <= 1:
        raise ConfigError(f"data.val_fraction={cfg.data.val_fraction} must be in [0, 1]")
    if not cfg.method.guidance_scales:
        raise ConfigError("method.guidance_scales is empty; give at least one scale, e.g. [0, 0.1, 0.5, 1, 2]")
    if cfg.method.sim_skip > cfg.method.segment_transitions:
        raise ConfigError(
            f"method.sim_skip={cfg.method.sim_skip} exceeds method.segment_transitions={cfg.method.segment_transitions}"
        )
    bad_tasks = [t for t in cfg.eval.tasks if t not in TASK_IDS]
    if bad_tasks or not cfg.eval.tasks:
        raise ConfigError(f"eval.tasks={cfg.eval.tasks} must be a non-empty list drawn from {list(TASK_IDS)}")
    bad_seeds = [s for s in cfg.eval.seeds if not isinstance(s, int) or s < 0]
    if bad_seeds or not cfg.eval.seeds:
        raise ConfigError(f"eval.seeds={cfg.eval.seeds} must be a non-empty list of non-negative integers")
    if is_ant(cfg.env.name) and not cfg.data.expert.strip():
        raise ConfigError(f"data.expert is empty but env.name={cfg.env.name} makes its data with the ant expert; "
                          "set data.expert=checkpoints/ant-expert (or the dir written by jobs/train_expert.py)")
    if cfg.ray.num_gpus > 0 and cfg.device == "cpu":
        raise ConfigError("ray.num_gpus > 0 but device=cpu; set device=cuda (or auto) to plan on GPUs")


def _get(cfg: Config, dotted: str) -> Any:
    node: Any = cfg
    for part in dotted.split("."):
        node = getattr(node, part)
    return node


def _positive(cfg: Config, *keys: str) -> None:
    for key in keys:
        if _get(cfg, key) <= 0:
            raise ConfigError(f"{key}={_get(cfg, key)} must be > 0")


def _non_negative(cfg: Config, *keys: str) -> None:
    for key in keys:
        if _get(cfg, key) < 0:
            raise ConfigError(f"{key}={_get(cfg, key)} must be >= 0")


__all__ = ["Config", "load_config", "validate", "config_from_dict", "resolve_path", "MISSING"]
