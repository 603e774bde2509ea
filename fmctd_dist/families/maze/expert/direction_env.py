"""Direction-following ant in an open arena: the task OGBench's AntMaze expert was trained on.

OGBench made its AntMaze navigate datasets with a SAC expert that sees the ant state
without x, y plus a unit direction (to the oracle's next cell) and was trained on
``online-ant-xy-v0`` = ``ogbench.online_locomotion.ant.AntEnv`` (no walls, same bodies,
joints, actuators, 10 Hz control as the maze ant; only colours differ) under
``GymXYWrapper`` (a new random direction every 100 steps). We build on the same AntEnv,
but draw directions from a seeded generator (the wrapper uses numpy's global RNG) and use
a Gymnasium-Ant-style reward instead of the wrapper's bare displacement:

    reward = v_xy . d + healthy_reward - ctrl_cost * |a|^2,   v_xy = (xy' - xy) / dt,  dt = 0.1 s

with ``ctrl_cost`` 0.05 by default instead of AntEnv's 0.5 (see ``AntEnvConfig.ctrl_cost``).
Episodes terminate when the torso leaves z in [0.2, 1.0] (AntEnv's healthy range) and are
truncated after ``episode_steps``. Observation [29] = qpos[2:] (13) + qvel (14) + d (2),
exactly ``expert_input(maze_ob, d)`` for a 29-D OGBench maze-ant observation.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fmctd_dist.families.maze.expert.config import AntEnvConfig

ANT_OBS_DIM = 29  # OGBench maze ant observation: qpos (15) + qvel (14)
PROPRIO_DIM = 27  # the same without x, y
OBS_DIM = PROPRIO_DIM + 2  # expert input: proprioception + unit direction
ACT_DIM = 8
DIRECTION_STREAM = 1  # SeedSequence([seed, DIRECTION_STREAM]) draws the commanded directions


def unit(angle: float) -> np.ndarray:
    return np.array([np.cos(angle), np.sin(angle)])


def expert_input(ant_ob: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """[..., 29] OGBench ant observation + [..., 2] direction -> [..., 29] expert input (x, y dropped, d unit)."""
    ant_ob = np.asarray(ant_ob, dtype=np.float64)
    if ant_ob.shape[-1] != ANT_OBS_DIM:
        raise ValueError(f"ant observation has {ant_ob.shape[-1]} features; expected the {ANT_OBS_DIM}-D OGBench ant "
                         "observation (qpos 15 + qvel 14) that still includes x, y")
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-8)
    d = np.broadcast_to(d, ant_ob.shape[:-1] + (2,))
    return np.concatenate([ant_ob[..., 2:], d], axis=-1)


class AntDirectionEnv:
    """``reset() -> obs [29]``, ``step(a [8]) -> (obs, reward, terminated, truncated, info)``.

    Deterministic from ``seed``: reset noise from the MuJoCo env's generator (seeded on the
    first reset), directions from their own stream. :meth:`get_state` / :meth:`set_state`
    capture everything (MuJoCo integration state included), so a resumed run steps exactly
    as an uninterrupted one.
    """

    def __init__(self, cfg: AntEnvConfig, seed: int):
        from ogbench.online_locomotion.ant import AntEnv  # deferred: MuJoCo start-up is not free

        self.cfg = cfg
        self.seed = int(seed)
        # The class, not gymnasium.make: no TimeLimit or checker wrappers; we count steps ourselves.
        self._u = AntEnv(healthy_reward=cfg.healthy_reward, ctrl_cost_weight=cfg.ctrl_cost,
                         reset_noise_scale=cfg.reset_noise, terminate_when_unhealthy=True,
                         exclude_current_positions_from_observation=True)
        self.dt = float(self._u.dt)
        self._dir_rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([self.seed, DIRECTION_STREAM])))
        self._seeded = False
        self.direction = np.array([1.0, 0.0])
        self.t = 0  # steps in this episode
        self._proprio = np.zeros(PROPRIO_DIM)

    def _obs(self) -> np.ndarray:
        return np.concatenate([self._proprio, self.direction]).astype(np.float32)

    def _new_direction(self) -> np.ndarray:
        return unit(self._dir_rng.uniform(0.0, 2.0 * np.pi))

    def reset(self, seed: int | None = None, direction: np.ndarray | None = None) -> np.ndarray:
        """New episode; ``seed`` reseeds the reset noise (the first reset uses the env seed)."""
        if seed is None and not self._seeded:
            seed = self.seed
        self._proprio, _ = self._u.reset(seed=seed)
        self._seeded = True
        self.direction = self._new_direction() if direction is None else np.asarray(direction, dtype=np.float64)
        self.t = 0
        return self._obs()

    def set_direction(self, direction: np.ndarray) -> np.ndarray:
        """Command a new direction now (evaluation turns); returns the new observation."""
        d = np.asarray(direction, dtype=np.float64)
        self.direction = d / np.linalg.norm(d)
        return self._obs()

    def xy(self) -> np.ndarray:
        return self._u.data.qpos[:2].copy()

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        a = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        xy0 = self.xy()
        self._proprio, _, terminated, _, _ = self._u.step(a)
        xy1 = self.xy()
        speed = float((xy1 - xy0) @ self.direction) / self.dt  # m/s along the commanded direction
        healthy = not terminated
        reward = speed + self.cfg.healthy_reward * healthy - self.cfg.ctrl_cost * float(a @ a)
        info = {"xy": xy1, "direction": self.direction.copy(), "speed": speed, "healthy": healthy}
        self.t += 1
        if self.cfg.resample_every > 0 and self.t % self.cfg.resample_every == 0:
            self.direction = self._new_direction()
        truncated = self.t >= self.cfg.episode_steps and not terminated
        return self._obs(), reward, bool(terminated), truncated, info

    def get_state(self) -> dict[str, Any]:
        """Everything needed to continue this episode bit for bit (plain Python types only)."""
        import mujoco

        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        buf = np.empty(mujoco.mj_stateSize(self._u.model, spec))
        mujoco.mj_getState(self._u.model, self._u.data, buf, spec)
        return {"mj_state": buf.tolist(), "proprio": self._proprio.tolist(), "direction": self.direction.tolist(),
                "t": self.t, "seeded": self._seeded, "reset_rng": self._u.np_random.bit_generator.state,
                "dir_rng": self._dir_rng.bit_generator.state}

    def set_state(self, state: dict[str, Any]) -> np.ndarray:
        """Restore :meth:`get_state` output; returns the current observation."""
        import mujoco

        self.reset(seed=self.seed)  # makes the env's generator exist before its state is overwritten
        mujoco.mj_setState(self._u.model, self._u.data, np.asarray(state["mj_state"], dtype=np.float64),
                           mujoco.mjtState.mjSTATE_INTEGRATION)
        self._proprio = np.asarray(state["proprio"], dtype=np.float64)
        self.direction = np.asarray(state["direction"], dtype=np.float64)
        self.t, self._seeded = int(state["t"]), bool(state["seeded"])
        self._u.np_random.bit_generator.state = state["reset_rng"]
        self._dir_rng.bit_generator.state = state["dir_rng"]
        return self._obs()

    def close(self) -> None:
        self._u.close()
