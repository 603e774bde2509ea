"""Env families: which env names exist, which family each belongs to, and what its planner models.

A family (docs/design.md §13) is one package under ``fmctd_dist/families/``: ``maze`` (the point and
ant robots), ``cube`` (the robot arm) and ``visual`` (the point maze seen through a camera), each with
its env, data, episode, value rules, controller and configs.
This registry sits below all of them and imports nothing of ours but the errors, so config,
envs and data can ask it without import cycles; ``search/``, ``denoiser/`` and ``evaluation/``
never branch on a family.

Code written for some families only guards its entry with :func:`require_family`, so a name
from another family stops there with one ConfigError instead of a crash deeper down.
"""

from __future__ import annotations

from dataclasses import dataclass

from fmctd_dist.errors import ConfigError, unknown_name

MAZES = ("medium", "large", "giant")
POINT_ENVS = tuple(f"pointmaze-{m}" for m in MAZES)
ANT_ENVS = tuple(f"antmaze-{m}" for m in MAZES)
CUBE_TYPES = ("single", "double", "triple")  # OGBench CubeEnv env_type
CUBE_ENVS = tuple(f"cube-{c}" for c in CUBE_TYPES)
MAZE_ENVS = POINT_ENVS + ANT_ENVS
VISUAL_ENVS = ("visual-pointmaze-medium", "visual-pointmaze-large")  # 64x64 chase-camera images (issue 21)
ENV_NAMES = MAZE_ENVS + CUBE_ENVS + VISUAL_ENVS

MAZE_FAMILIES = ("pointmaze", "antmaze")
VISUAL_PLANNER_ISSUE = "issue 21"  # where the visual planner (VAE, inverse dynamics, latent DF) is built
# Families whose planner is not built yet: load_config refuses them unless the job names them,
# so train / eval stop with one ConfigError before any work. (None now: the visual maze's is built.)
PENDING_FAMILIES: tuple[str, ...] = ()
# Each family's hook module (fmctd_dist.family.FamilyHooks): its plan rules (the tree's actions and
# value) and its episodes. Named, not imported, so this registry stays below everything.
HOOKS = {"pointmaze": "fmctd_dist.families.maze.hooks", "antmaze": "fmctd_dist.families.maze.hooks",
         "cube": "fmctd_dist.families.cube.hooks",
         "visual-pointmaze": "fmctd_dist.families.visual.hooks"}

# The env fields only some families read (the rest, name / protocol / max_steps / horizon, every family
# reads). Set away from its default on another family, such a field would be silently unused, so
# config.validate refuses it: one ConfigError naming the field and who reads it.
ENV_FIELD_READERS: dict[str, tuple[str, ...]] = {
    "policy": ("antmaze", "cube"),  # the low-level policy dir
    "replan_every": ("cube",),  # the maze families replan on method.replan_every
    "warp_dense": ("cube", "visual-pointmaze"),  # the point / ant mazes use method.warp_threshold
    "warp_sparse": ("cube", "visual-pointmaze"),
    "object_scales": ("cube",),
    "preposition_yaw": ("cube",),
    "start_tolerance": ("cube",),
}


@dataclass(frozen=True)
class EnvSpec:
    """One env name: its family and the planner state the diffusion model works on."""

    name: str  # e.g. pointmaze-medium, cube-double
    family: str  # pointmaze | antmaze | cube
    state_dim: int  # planner state per frame: maze x, y (2) | cube xyz in obs units (3 per cube)
    state: str  # what the planner state is, in words (for messages and manifests)


ENVS: dict[str, EnvSpec] = {
    **{n: EnvSpec(n, "pointmaze", 2, "x, y") for n in POINT_ENVS},
    **{n: EnvSpec(n, "antmaze", 2, "torso x, y") for n in ANT_ENVS},
    **{f"cube-{c}": EnvSpec(f"cube-{c}", "cube", 3 * (i + 1), f"xyz of {i + 1} cube(s) in obs units")
       for i, c in enumerate(CUBE_TYPES)},
    **{n: EnvSpec(n, "visual-pointmaze", 8, "8-D VAE latent of a 64x64 chase-camera image") for n in VISUAL_ENVS},
}


def env_spec(name: str, field: str = "env.name") -> EnvSpec:
    """The spec of ``name``; an unknown name is one ConfigError with the closest valid one."""
    if name not in ENVS:
        raise unknown_name(field, name, ENV_NAMES)
    return ENVS[name]


def family(name: str) -> str:
    return env_spec(name).family


def state_dim(name: str) -> int:
    return env_spec(name).state_dim


def require_family(name: str, families: tuple[str, ...], what: str) -> str:
    """``name`` if its family is one of ``families``; else one ConfigError saying what is not built for it."""
    spec = env_spec(name)
    if spec.family in families:
        return name
    if spec.family == "visual-pointmaze":
        raise ConfigError(f"env.name={name} is a visual maze env (64x64 images, {VISUAL_PLANNER_ISSUE}), but {what} "
                          f"is not built for it. The visual maze's code: python jobs/train_visual.py part=... "
                          f"env={name} (VAE, latents, estimator, inverse dynamics); python jobs/train.py env={name} "
                          f"jump=5; python jobs/eval.py env={name}")
    if spec.family == "cube":
        raise ConfigError(f"env.name={name} is a cube env, but {what} is built for mazes only. The cube code: "
                          f"python jobs/make_dataset.py env={name}; python jobs/train.py env={name} jump=5; "
                          f"python jobs/train_policy.py env=cube-single; python jobs/eval.py env={name}")
    raise ConfigError(f"env.name={name} is a {spec.family} env, but {what} is built for "
                      f"{' / '.join(families)} envs only")
