"""AntMaze navigate data: our ant expert, steered by the BFS oracle, in OGBench's ant maze.

OGBench's recipe (``generate_locomaze.py``, docs/reference.md §9) with our own expert: the same goal
logic as PointMaze navigate (random start cell + noise, random vertex-cell goal, a new goal
on each success, the episode runs on), and

    action = clip(expert(ant state without x, y  +  unit direction to the oracle's next cell)
                  + N(0, noise^2) per torque, -1, 1)

Rows keep the full 29-D observation before each step (what a low-level policy will need);
the planner trains on its x, y. A dataset is only as reproducible as the policy behind it,
so the manifest records the expert's sha256 and loading refuses data made by another
expert. The layout and verification are :mod:`fmctd_dist.families.maze.data`'s, the start / goal draws
and per-episode seeding :mod:`fmctd_dist.families.maze.navigate`'s.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fmctd_dist.families.maze.expert.direction_env import expert_input
from fmctd_dist.config import Config, resolve_path
from fmctd_dist.families.maze.navigate import Episode, random_goal, random_start, run_episodes
from fmctd_dist.families.maze.oracle import NoisyOracle
from fmctd_dist.families.maze.antmaze import ACT_DIM, GOAL_TOLERANCE, HEALTHY_Z, OBS_DIM, AntMaze, healthy, upright
from fmctd_dist.errors import DatasetError

if TYPE_CHECKING:
    from fmctd_dist.families.maze.expert.expert import AntExpert

ANT_GENERATOR_VERSION = 1
KEYS = ["observations", "actions", "goals", "terminals"]
OBS_LAYOUT = (f"observations [E, S, {OBS_DIM}] = OGBench ant qpos (x, y, z, quaternion w x y z, 8 joints) + qvel (14), "
              "before each step; actions [E, S, 8] = the noisy clipped torques applied; goals [E, S, 2]; "
              "obs_mean/obs_std are of x, y only (what the planner models)")


def generate_episode(env: AntMaze, expert: AntExpert, oracle: NoisyOracle, steps: int, noise: float,
                     rng: np.random.Generator) -> dict[str, np.ndarray]:
    """One navigate episode; ``reached [S]`` marks the steps after which the goal was reached."""
    geo = env.geometry
    start = random_start(geo, rng)
    goal = random_goal(geo, rng)
    ob = env.reset_to(start, goal, seed=int(rng.integers(2**31)))
    obs = np.empty((steps, OBS_DIM), np.float32)
    act = np.empty((steps, ACT_DIM), np.float32)
    goals = np.empty((steps, 2), np.float32)
    reached = np.zeros(steps, dtype=bool)
    for t in range(steps):
        direction = oracle.direction(ob[:2], goal)
        a = np.clip(expert.act(expert_input(ob, direction)) + rng.normal(0.0, noise, size=ACT_DIM), -1.0, 1.0)
        obs[t], act[t], goals[t] = ob, a, goal
        ob, reached[t] = env.step(a)
        if reached[t]:
            goal = random_goal(geo, rng)
            env.set_goal(goal)
    return {"observations": obs, "actions": act, "goals": goals, "reached": reached}


def split_stats(obs: np.ndarray, reached: np.ndarray, dt: float) -> dict[str, Any]:
    """Quality of one split: how often goals are reached, how often the ant is down, how fast it walks."""
    steps = int(reached.size)
    ok, up = healthy(obs), upright(obs)
    down = ~ok | ~up
    speed = np.linalg.norm(np.diff(obs[..., :2].astype(np.float64), axis=1), axis=-1) / dt
    return {
        "env_steps": steps,
        "goals_reached": int(reached.sum()),
        "goals_per_1000_steps": round(1000.0 * float(reached.sum()) / steps, 3),
        "unhealthy_fraction": round(float((~ok).mean()), 5),  # torso z outside HEALTHY_Z
        "upside_down_fraction": round(float((~up).mean()), 5),
        "episodes_fallen": int(down.any(axis=1).sum()),  # episodes with any unhealthy or upside-down step
        "mean_speed_m_per_s": round(float(speed.mean()), 4),
    }


def ant_episodes(cfg: Config) -> tuple[Episode, Callable[[], None]]:
    """The episode function (one env, expert and oracle per process) and the env's close."""
    from fmctd_dist.families.maze.expert.expert import load_expert  # deferred: torch

    env = AntMaze(cfg.env.name)
    expert = load_expert(resolve_path(cfg.data.expert))
    oracle = NoisyOracle(env.geometry, 0.0)  # only its noiseless direction is used; the noise goes on the torques
    return (lambda rng: generate_episode(env, expert, oracle, cfg.data.episode_steps, cfg.data.noise, rng)), env.close


class AntSource:
    """AntMaze data source for :func:`fmctd_dist.families.maze.data.make_dataset` (checks the expert first)."""

    version = ANT_GENERATOR_VERSION

    def __init__(self, cfg: Config):
        from fmctd_dist.families.maze.expert.expert import load_expert  # deferred: torch

        self.cfg = cfg
        self.expert = load_expert(resolve_path(cfg.data.expert))  # CheckpointError: missing, other kind, corrupt
        self.stats: dict[str, dict[str, Any]] = {}
        self.wall_s: dict[str, float] = {}
        env = AntMaze(cfg.env.name)
        self.dt = env.dt  # the stats' speed; the episodes build their own envs (one per worker process)
        env.close()

    def generate(self, split: str, episodes: int, progress: bool) -> dict[str, np.ndarray]:
        from fmctd_dist.device import torch_threads

        t0 = time.perf_counter()
        with torch_threads(1):
            arrays = run_episodes(self.cfg, split, episodes, ant_episodes, progress)
        self.wall_s[split] = time.perf_counter() - t0
        reached = arrays.pop("reached")
        self.stats[split] = split_stats(arrays["observations"], reached, self.dt)
        return arrays

    def manifest_fields(self) -> dict[str, Any]:
        m = self.expert.manifest
        steps = sum(s["env_steps"] for s in self.stats.values())
        wall = sum(self.wall_s.values())
        return {
            "generator": "ant-expert-navigate",
            "policy": "expert(ant state without x, y + unit direction to the BFS next-cell subgoal) + N(0, noise^2) "
                      f"per torque, clipped to [-1, 1]; new vertex-cell goal on success (within {GOAL_TOLERANCE}); "
                      "a fallen ant is not reset (as in OGBench)",
            "expert": {"path": self.cfg.data.expert, "kind": m.get("kind"), "digest": m.get("digest"),
                       "model_sha256": m.get("model_sha256"), "env_steps": m.get("env_steps")},
            "obs_dim": OBS_DIM,
            "act_dim": ACT_DIM,
            "obs_layout": OBS_LAYOUT,
            "keys": KEYS,
            "stats": self.stats,
            "healthy_z": list(HEALTHY_Z),  # stats: "unhealthy" = torso z outside this range
            # the only field that differs between two runs of the same config (the .npz bytes do not)
            "generation": {"wall_s": round(wall, 1), "env_steps_per_s": round(steps / max(wall, 1e-9), 1),
                           "torch_threads": 1, "workers": self.cfg.data.workers},
        }


def check_expert_matches(manifest: dict[str, Any], cfg: Config, path: Path) -> None:
    """Data made by one expert must not pass as another's: compare the recorded sha256 with data.expert's."""
    from fmctd_dist.families.maze.expert.expert import read_expert_manifest  # deferred: torch

    recorded = manifest.get("expert") or {}
    current = read_expert_manifest(resolve_path(cfg.data.expert))
    if recorded.get("model_sha256") != current.get("model_sha256"):
        raise DatasetError(
            f"{path} was made by ant expert {recorded.get('digest')!r} but data.expert={cfg.data.expert} is expert "
            f"{current.get('digest')!r}; point data.expert to the expert that made it, or use another data.root "
            "(or delete the directory) to generate data with this one"
        )
