"""What training and evaluating the cube policy needs beyond the shared loop: its rows and reach test.

No noise floor is reported: the data's oracle adds smoothed noise to its whole plan, so there
is no clean action to compare with (the ant's expert gives one).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fmctd_dist.config import Config
from fmctd_dist.control.policy.config import PolicyConfig
from fmctd_dist.families.cube.policy import CUBE_SPEC
from fmctd_dist.families.cube.policy_rows import CubeRows, load_cube_policy_data
from fmctd_dist.families.cube.data import dataset_dir


class CubeHooks:
    spec = CUBE_SPEC
    reference = "oracle"  # reach.expert runs OGBench's CubePlanOracle

    def load(self, cfg: Config, pcfg: PolicyConfig) -> tuple[CubeRows, CubeRows, dict[str, Any]]:
        return load_cube_policy_data(cfg)

    def dataset_fields(self, cfg: Config, manifest: dict[str, Any]) -> dict[str, Any]:
        return {"path": str(dataset_dir(cfg)), "oracle": manifest.get("oracle")}

    def floor(self, cfg: Config, rows: CubeRows, i: np.ndarray) -> float | None:
        return None

    def reach(self, cfg: Config, pcfg: PolicyConfig, policy, rows: CubeRows, progress: bool = False) -> dict[str, Any]:
        """Reach rate of ``policy`` (view, subgoal) -> action, and of OGBench's oracle / zero actions when asked."""
        from fmctd_dist.families.cube.reach import evaluate_reach, zero_controller

        ctrls: dict[str, Any] = {"policy": policy}
        if pcfg.reach.expert:
            ctrls["oracle"] = None
        if pcfg.reach.zero:
            ctrls["zero"] = zero_controller
        r = pcfg.reach
        return evaluate_reach(cfg.env.name, ctrls, rows, r.rows, r.offset, r.advance, r.radius, r.max_steps, r.seed,
                              progress)

    def format(self, name: str, result: dict[str, Any]) -> str:
        from fmctd_dist.families.cube.reach import format_reach

        return format_reach(name, result)
