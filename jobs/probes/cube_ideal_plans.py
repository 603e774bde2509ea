"""Cube episodes with hand-made ideal plans: how far the arm's scripts + the cube policy get without a model.

    python jobs/probes/cube_ideal_plans.py env=cube-single
    python jobs/probes/cube_ideal_plans.py env=cube-double tasks=[1,2,3,4,5] seeds=[0,1]

The planner is replaced by an arc: the first cube the value's rules call unsolved goes from
where it is to its goal in 60 env steps after a 20-step hold (for the grasp), lifted by
min(1.0, xy distance) at mid-way; every other cube stays. Everything else is the evaluation's
cube episode (``families/cube/episode.py``: target choice, pre-position, subgoals, release,
``env.replan_every``) with the policy of ``env.policy``. A failure here is the policy's or the
episode loop's, not the diffusion model's, which is what the robot table's failure analysis
needs to tell apart. The arc knows no stacking order and no free spot, so tasks that need
them (swap, cycle, stacks) can fail on the arc alone. Prints one line per episode and a
success count; writes nothing.
"""

from __future__ import annotations

import time

import numpy as np

from fmctd_dist.cli import run
from fmctd_dist.config import load_config
from fmctd_dist.control.policy.checkpoint import load_policy
from fmctd_dist.families.cube.env import CubeEpisodes
from fmctd_dist.families.cube.episode import run_cube_episode
from fmctd_dist.registry import require_family
from fmctd_dist.families.cube.policy import CUBE_SPEC
from fmctd_dist.families.cube.hooks import policy_dir
from fmctd_dist.planners.base import PlanOutput
from fmctd_dist.families.cube.value import CubeValue

HOLD, MOVE, FRAMES = 20, 60, 100  # env steps: wait for the grasp, carry, plan length


class ArcPlanner:
    """The ideal plan described in the module docstring (no model, no search)."""

    def plan(self, start: np.ndarray, goal: np.ndarray, seed: int) -> PlanOutput:
        s, g = start.reshape(-1, 3), goal.reshape(-1, 3)
        i = (CubeValue().unsolved(start, goal) or [0])[0]
        u = np.clip((np.arange(FRAMES) - HOLD) / MOVE, 0.0, 1.0)  # [F] progress
        p = np.repeat(s[None], FRAMES, 0)
        p[:, i] = s[i] + u[:, None] * (g[i] - s[i])
        p[:, i, 2] += min(1.0, float(np.linalg.norm(g[i, :2] - s[i, :2]))) * np.sin(np.pi * u)
        return PlanOutput(p.reshape(FRAMES, -1).astype(np.float32), "plan", 0.0, 0.0)


def main(argv: list[str]) -> int:
    cfg = load_config(argv, env="cube-single", method="fast-mctd-replan")
    require_family(cfg.env.name, ("cube",), "jobs/probes/cube_ideal_plans.py")
    policy = load_policy(policy_dir(cfg), CUBE_SPEC, cfg.env.name)
    env = CubeEpisodes(cfg.env.name)
    print(f"{cfg.env.name}: policy {policy_dir(cfg)} (digest {policy.manifest.get('digest')}), "
          f"replan every {cfg.env.replan_every or cfg.method.replan_every} policy steps, {cfg.env.max_steps} steps")
    wins = total = 0
    for task in cfg.eval.tasks:
        for seed in cfg.eval.seeds:
            t0 = time.perf_counter()
            r = run_cube_episode(cfg, env, ArcPlanner(), policy.act, task, seed)
            wins, total = wins + r["success"], total + 1
            print(f"task {task} seed {seed}: {'success' if r['success'] else 'failure (' + r['why_failed'] + ')'} "
                  f"after {r['env_steps']} steps, {r['plans']} plans, {r['releases']} releases "
                  f"({time.perf_counter() - t0:.1f}s)")
    print(f"{wins} of {total} episodes solved with ideal arc plans")
    env.close()
    return 0


if __name__ == "__main__":
    run(main)
