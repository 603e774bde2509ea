"""Cross-field checks of the planner's config: the declared ranges first, then the fields that depend on
each other (horizons, budgets, model kinds), before any dataset, model or Ray actor is touched."""

from __future__ import annotations

from fmctd_dist.config.ranges import check_ranges
from fmctd_dist.config.schema import Config, EnvConfig
from fmctd_dist.errors import ConfigError
from fmctd_dist.registry import env_field_readers, family


def is_ant(env_name: str) -> bool:
    """AntMaze (29-D ant state, 8-D torque actions) rather than PointMaze (2-D position and action)."""
    return family(env_name) == "antmaze"

def check_env_fields(env: EnvConfig) -> None:
    """One ConfigError for an env field set on a family that never reads it (``registry.env_field_readers``)."""
    fam, default = family(env.name), EnvConfig()
    for key, readers in env_field_readers().items():
        value = getattr(env, key)
        if fam not in readers and value != getattr(default, key):
            raise ConfigError(f"env.{key}={value!r} is read by {' / '.join(readers)} envs only; env.name={env.name} "
                              f"({fam}) would ignore it. Drop env.{key} (or leave it at "
                              f"{getattr(default, key)!r}) for this env")


def validate(cfg: Config) -> None:
    """Declared ranges, then cross-field checks; raise one ConfigError naming the field and the fix."""
    check_ranges(cfg)
    check_env_fields(cfg.env)
    if cfg.visual.plan_xy and family(cfg.env.name) != "visual-pointmaze":
        raise ConfigError(f"visual.plan_xy=true adds the position estimator's (x, y) to a visual maze's latent "
                          f"frames; env.name={cfg.env.name} ({family(cfg.env.name)}) has no latents. "
                          "Drop visual.plan_xy")
    for name, value in (("method.wall_test", cfg.method.wall_test), ("method.wall_guidance", cfg.method.wall_guidance),
                        ("env.wall_clearance", cfg.env.wall_clearance)):
        if value and family(cfg.env.name) not in ("pointmaze", "antmaze"):
            raise ConfigError(f"{name}={value} needs a point or ant maze (the walls come from its cells); "
                              f"env.name={cfg.env.name} ({family(cfg.env.name)}) has none. Drop {name}")
    if cfg.model.kind == "diffuser" and cfg.method.planner != "diffuser":
        raise ConfigError(
            f"model.kind=diffuser with method.planner={cfg.method.planner}: the U-Net gives all plan tokens one "
            "noise level, but this planner needs per-token levels; use method=diffuser (or diffuser-replan), "
            "or model.kind=df"
        )
    if cfg.model.kind == "diffuser":
        k = cfg.model.unet_kernel
        if k % 2 == 0:
            raise ConfigError(f"model.unet_kernel={k} must be a positive odd number (same-length convs), e.g. 5")
        if not 0 <= cfg.model.unet_edge_frames < cfg.plan_tokens:
            raise ConfigError(f"model.unet_edge_frames={cfg.model.unet_edge_frames} must be in [0, {cfg.plan_tokens}) "
                              "(fewer than the plan's frames); 0 is Janner's U-Net, 8 reflects 8 frames at each end")
    if cfg.model.kind == "diffuser" and (cfg.model.param, cfg.model.norm) != ("x0", "post"):
        raise ConfigError(f"model.param={cfg.model.param} / model.norm={cfg.model.norm} apply to model.kind=df only; "
                          "the Diffuser U-Net predicts x0 (set model.param=x0 model.norm=post)")
    if cfg.model.kind == "diffuser" and cfg.diffusion.guidance_path != "input":
        raise ConfigError("diffusion.guidance_path=network applies to model.kind=df only (the U-Net has no skip "
                          "path); set diffusion.guidance_path=input")
    if cfg.diffusion.boundary_guidance > 0 and cfg.model.frame_stack < 2:
        raise ConfigError(f"diffusion.boundary_guidance={cfg.diffusion.boundary_guidance:g} compares each token "
                          f"boundary's step with the step before it inside the token, but model.frame_stack="
                          f"{cfg.model.frame_stack} leaves no such step; use a model with frame_stack >= 2 "
                          "(every MCTD-family method) or set diffusion.boundary_guidance=0")
    if cfg.model.width % cfg.model.heads:
        raise ConfigError(f"model.width={cfg.model.width} is not divisible by model.heads={cfg.model.heads}; "
                          "pick a width that is a multiple of heads (paper 128 / 4)")
    if cfg.diffusion.beta_start >= cfg.diffusion.beta_end:
        raise ConfigError(f"diffusion.beta_start={cfg.diffusion.beta_start} must be below diffusion.beta_end="
                          f"{cfg.diffusion.beta_end} (paper 1e-4 and 0.02)")
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
    if cfg.method.sim_skip > cfg.method.segment_transitions:
        raise ConfigError(
            f"method.sim_skip={cfg.method.sim_skip} exceeds method.segment_transitions={cfg.method.segment_transitions}"
        )
    if is_ant(cfg.env.name) and not cfg.data.expert.strip():
        raise ConfigError(f"data.expert is empty but env.name={cfg.env.name} makes its data with the ant expert; "
                          "set data.expert=checkpoints/ant-expert (or the dir written by jobs/train_expert.py)")
    if cfg.ray.num_gpus > 0 and cfg.device == "cpu":
        raise ConfigError("ray.num_gpus > 0 but device=cpu; set device=cuda (or auto) to plan on GPUs")

