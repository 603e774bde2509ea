"""What training and evaluating the ant policy needs beyond the shared loop: its rows, noise floor and reach test."""

from __future__ import annotations

from typing import Any

import numpy as np

from fmctd_dist.config import Config, resolve_path
from fmctd_dist.families.maze.ant_policy import ANT_SPEC
from fmctd_dist.families.maze.ant_policy_rows import PolicyRows, load_policy_data
from fmctd_dist.control.policy.config import PolicyConfig
from fmctd_dist.families.maze.data import dataset_dir


class AntHooks:
    spec = ANT_SPEC
    reference = "expert"  # reach.expert runs the ant expert steered at the subgoal

    def load(self, cfg: Config, pcfg: PolicyConfig) -> tuple[PolicyRows, PolicyRows, dict[str, Any]]:
        return load_policy_data(cfg, pcfg.policy.drop_fallen)

    def dataset_fields(self, cfg: Config, manifest: dict[str, Any]) -> dict[str, Any]:
        return {"path": str(dataset_dir(cfg)), "expert": manifest.get("expert")}

    def floor(self, cfg: Config, rows: PolicyRows, i: np.ndarray) -> float | None:
        """The expert's MSE to the data's torques on rows i (its own input: the oracle direction to the data's goal)."""
        from fmctd_dist.families.maze.expert.direction_env import expert_input
        from fmctd_dist.families.maze.expert.expert import load_expert
        from fmctd_dist.families.maze.oracle import NoisyOracle
        from fmctd_dist.families.maze.geometry import maze_geometry

        expert = load_expert(resolve_path(cfg.data.expert))
        oracle = NoisyOracle(maze_geometry(cfg.env.name), 0.0)
        obs = rows.obs[i].astype(np.float64)
        dirs = np.stack([oracle.direction(o[:2], g) for o, g in zip(obs, rows.goals[i].astype(np.float64))])
        pred = expert.act(expert_input(obs, dirs))
        return float(np.mean((pred - rows.actions[i]) ** 2))

    def reach(self, cfg: Config, pcfg: PolicyConfig, policy, rows: PolicyRows,
              progress: bool = False) -> dict[str, Any]:
        """Reach rate of ``policy`` (obs, subgoal) -> torques, and of the expert / zero torques when asked, on rows."""
        from fmctd_dist.families.maze.expert.expert import load_expert
        from fmctd_dist.families.maze.ant_reach import evaluate_reach, expert_controller, zero_controller

        ctrls = {"policy": policy}
        if pcfg.reach.expert:
            ctrls["expert"] = expert_controller(load_expert(resolve_path(cfg.data.expert)))
        if pcfg.reach.zero:
            ctrls["zero"] = zero_controller
        r = pcfg.reach
        return evaluate_reach(cfg.env.name, ctrls, rows, r.rows, r.offset, r.max_steps, r.radius, r.seed)

    def format(self, name: str, result: dict[str, Any]) -> str:
        from fmctd_dist.families.maze.ant_reach import format_reach

        return format_reach(name, result)
