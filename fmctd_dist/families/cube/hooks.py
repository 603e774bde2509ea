"""Cube hooks (docs/reference.md §13): object-wise actions + the cube value; episodes driven by the cube policy.

Tree children are (unsolved cube, scale) pairs over ``env.object_scales``; the value is
:class:`CubeValue` with the warp threshold of the model's density (``env.warp_dense`` at jump 1,
``env.warp_sparse`` above) in replanning mode when the method replans. Planners without search
guide every unsolved cube at ``method.guidance_scale`` and pin the solved ones.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fmctd_dist.config import Config, resolve_path
from fmctd_dist.errors import CheckpointError, ConfigError
from fmctd_dist.family import warp_threshold
from fmctd_dist.planners.base import Planner
from fmctd_dist.search.actions import ALL, Actions, object_actions
from fmctd_dist.families.cube.value import CubeValue

DEFAULT_POLICY = "checkpoints/cube-single-policy"  # the authors drive every cube env with the single-cube policy


@dataclass(frozen=True)
class CubeRules:
    n_cubes: int
    scales: tuple[float, ...]  # per unsolved cube (env.object_scales)
    fixed_scale: float  # method.guidance_scale of planners without search
    value: CubeValue

    def objects(self, start: np.ndarray, goal: np.ndarray) -> list[int]:
        """The cubes still to place (every cube if none is left: the plan is then only a fallback)."""
        return self.value.unsolved(start, goal) or list(range(self.n_cubes))

    def tree(self, start: np.ndarray, goal: np.ndarray) -> tuple[Actions, CubeValue]:
        return object_actions(self.objects(start, goal), self.n_cubes, 3, self.scales), self.value

    def fixed(self, start: np.ndarray, goal: np.ndarray) -> tuple[Actions, CubeValue]:
        mask = np.zeros((1, 3 * self.n_cubes), np.float32)
        for i in self.objects(start, goal):
            mask[0, 3 * i:3 * i + 3] = 1.0
        return Actions(np.array([self.fixed_scale], np.float32), np.array([ALL], np.int32), mask), self.value


def plan_rules(cfg: Config) -> CubeRules:
    if not cfg.env.object_scales:
        raise ConfigError(f"env.object_scales is empty for {cfg.env.name}: give the per-cube guidance scales, "
                          "e.g. env.object_scales=[1,2,4] (configs/env/cube-*.yaml set them)")
    n = cfg.frame_dim // 3
    value = CubeValue(warp_threshold=warp_threshold(cfg), replanning=cfg.method.replan_every > 0,
                      start_tol=float(cfg.env.start_tolerance))
    return CubeRules(n, tuple(float(s) for s in cfg.env.object_scales), float(cfg.method.guidance_scale), value)


def policy_dir(cfg: Config) -> Path:
    return resolve_path(cfg.env.policy or DEFAULT_POLICY)


def check_episodes(cfg: Config) -> str:
    """The cube policy exists and is a cube policy: else one CheckpointError naming the training command."""
    from fmctd_dist.control.policy.checkpoint import read_policy_manifest  # deferred: torch
    from fmctd_dist.families.cube.policy import CUBE_SPEC

    try:
        return str(read_policy_manifest(policy_dir(cfg), CUBE_SPEC, cfg.env.name).get("digest", ""))
    except CheckpointError as e:
        raise CheckpointError(f"env.policy={cfg.env.policy or DEFAULT_POLICY} (the cube low-level policy; "
                              f"env.policy=DIR for another): {e}") from None


class CubeEpisodeRunner:
    """The cube env + the loaded policy, built once; :func:`run_cube_episode` per episode."""

    def __init__(self, cfg: Config):
        from fmctd_dist.control.policy.checkpoint import load_policy
        from fmctd_dist.families.cube.env import CubeEpisodes
        from fmctd_dist.families.cube.policy import CUBE_SPEC

        self.cfg = cfg
        self.env = CubeEpisodes(cfg.env.name)
        policy = load_policy(policy_dir(cfg), CUBE_SPEC, cfg.env.name)
        self.policy = policy.act
        self.policy_digest = str(policy.manifest.get("digest", ""))  # rows say which policy drove the arm

    def run(self, planner: Planner, task: int, seed: int) -> dict[str, Any]:
        from fmctd_dist.families.cube.episode import run_cube_episode

        return run_cube_episode(self.cfg, self.env, planner, self.policy, task, seed)


def episodes(cfg: Config) -> CubeEpisodeRunner:
    return CubeEpisodeRunner(cfg)


def plot_episode(row: dict[str, Any], path: Path) -> Path:
    """Cube paths and the effector from above, heights over time."""
    from fmctd_dist.families.cube.plots import plot_cube_episode

    return plot_cube_episode(row, path)
