"""Direction-following success: does the expert go where it is told, and turn when told?

Evaluation episode k (k = 0..E-1, E = ``eval.episodes``) resets the ant with seed
``eval.seed + k`` and commands ``eval.segments`` directions in a row, each for
``eval.segment_steps`` env steps: segment j points at angle 2*pi*k/E + j*pi/2 (so the
first segments cover the circle evenly and every later one is a 90-degree left turn, as
in a maze corridor). Actions are deterministic (tanh of the mean).

A segment's speed is its displacement along its direction divided by its duration
(m/s; dt = 0.1 s). An episode **succeeds** when the ant stays healthy (torso z in
[0.2, 1.0], i.e. it never falls over) for the whole episode and every segment's speed is
at least ``eval.min_speed``. Success rate = successful episodes / E. The first segment
starts from a standing ant, so it includes getting going.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from fmctd_dist.families.maze.expert.config import AntEnvConfig, ExpertEvalConfig
from fmctd_dist.families.maze.expert.direction_env import AntDirectionEnv, unit

Policy = Callable[[np.ndarray], np.ndarray]  # obs [29] -> action [8]


def make_eval_env(env_cfg: AntEnvConfig, cfg: ExpertEvalConfig) -> AntDirectionEnv:
    """The training env's dynamics and reward, with directions only from the evaluation schedule."""
    return AntDirectionEnv(dataclasses.replace(env_cfg, resample_every=0,
                                               episode_steps=cfg.segments * cfg.segment_steps), seed=cfg.seed)


def evaluate_directions(policy: Policy, env_cfg: AntEnvConfig, cfg: ExpertEvalConfig,
                        env: AntDirectionEnv | None = None) -> dict[str, float]:
    """Run the evaluation episodes; returns success rate, fall rate, mean/min segment speed, return."""
    env = env or make_eval_env(env_cfg, cfg)
    speeds, successes, falls, returns = [], [], [], []
    for k in range(cfg.episodes):
        angle0 = 2.0 * np.pi * k / cfg.episodes
        obs = env.reset(seed=cfg.seed + k, direction=unit(angle0))
        seg_speed, fell, ret = [], False, 0.0
        for j in range(cfg.segments):
            obs = env.set_direction(unit(angle0 + j * np.pi / 2))
            xy0 = env.xy()
            for _ in range(cfg.segment_steps):
                obs, r, terminated, _, _ = env.step(policy(obs))
                ret += r
                if terminated:
                    fell = True
                    break
            seg_speed.append(float((env.xy() - xy0) @ env.direction) / (cfg.segment_steps * env.dt))
            if fell:
                break
        seg_speed += [0.0] * (cfg.segments - len(seg_speed))  # segments never reached count as not followed
        speeds.append(seg_speed)
        falls.append(fell)
        successes.append(not fell and min(seg_speed) >= cfg.min_speed)
        returns.append(ret)
    sp = np.asarray(speeds)
    return {"success": float(np.mean(successes)), "fall_rate": float(np.mean(falls)),
            "speed_mean": float(sp.mean()), "speed_min": float(sp.min()), "return_mean": float(np.mean(returns)),
            "episodes": cfg.episodes, "min_speed": cfg.min_speed}
