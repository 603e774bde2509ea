"""Robot-arm cube episodes over OGBench's MuJoCo ``CubeEnv`` (``cube-{single,double,triple}-v0``), offline.

We build OGBench's env class directly (as ``families/maze/geometry.py`` does for the maze), so nothing
is downloaded. ``permute_blocks=True`` and success as in ``cube-*-v0``; ``terminate_at_goal``
is off (an episode runs its ``env.max_steps``; success is reported on every step).

Seeded protocol (README "Cubes"): ``reset(task_id, seed)`` is OGBench's task reset with every
random draw taken from ``seed``:
- the arm's random start pose (effector xyz in the arm sampling box, random yaw; IK), the
  ``permute_blocks`` permutation (which obs slot holds which of the task's cubes) and the start
  cubes' +-0.01 m xy jitter and random yaw: ``env.np_random``, seeded by ``reset(seed=seed)``;
- the 2 random actions OGBench takes with the cubes at their goals before it records the goal
  observation: stock OGBench draws them from a fresh, unseeded action space on every reset; we
  draw them from the seed too (``_SeededCubeEnv``), so the whole episode is a function of the seed.
Success is OGBench's: every cube within 0.04 m (0.4 obs units) of its goal, after the step.

Observation (docs/reference.md §13): 19 + 9N numbers: arm joint positions (0-5) and velocities
(6-11), effector xyz (12-14), effector yaw cos/sin (15-16), gripper opening (17), gripper
contact (18), then per cube i: xyz (19+9i..21+9i), quaternion (4), yaw cos/sin. Positions are in
obs units, (p - [0.425, 0, 0]) x 10: a cube on the table has z = 0.2, one stack level is 0.4.
The planner state is the cubes' xyz in obs units, [3N] (:func:`cube_xyz`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from fmctd_dist.seeding import check_seed
from fmctd_dist.errors import ConfigError
from fmctd_dist.registry import env_spec, require_family

os.environ.setdefault("MUJOCO_GL", "egl")

XYZ_CENTER = np.array([0.425, 0.0, 0.0])  # OGBench's obs origin (world metres)
XYZ_SCALE = 10.0  # obs units per metre
SUCCESS_RADIUS = 0.04 * XYZ_SCALE  # OGBench: every cube within 0.04 m of its goal -> 0.4 obs units
ARM_DIM = 19  # obs numbers before the first cube
CUBE_OBS = 9  # obs numbers per cube: xyz, quaternion, yaw cos/sin
ACT_DIM = 5  # effector dx, dy, dz (x 0.05 m), dyaw (x 0.3 rad), gripper
TASK_IDS = (1, 2, 3, 4, 5)


def n_cubes(name: str) -> int:
    return env_spec(name).state_dim // 3


def obs_dim(name: str) -> int:
    return ARM_DIM + CUBE_OBS * n_cubes(name)


def cube_columns(n: int) -> np.ndarray:
    """[3n] obs columns of the cubes' xyz: 19+9i .. 21+9i for cube i."""
    return np.concatenate([np.arange(ARM_DIM + CUBE_OBS * i, ARM_DIM + CUBE_OBS * i + 3) for i in range(n)])


def cube_xyz(obs: np.ndarray, n: int) -> np.ndarray:
    """[..., 19+9n] observations -> [..., 3n] cube xyz in obs units (the planner state)."""
    obs = np.asarray(obs)
    if obs.shape[-1] != ARM_DIM + CUBE_OBS * n:
        raise ValueError(f"a {n}-cube observation has {ARM_DIM + CUBE_OBS * n} numbers, got shape {obs.shape}")
    return obs[..., cube_columns(n)]


def to_obs_units(xyz_m: np.ndarray) -> np.ndarray:
    """World metres [..., 3] -> obs units [..., 3]."""
    return (np.asarray(xyz_m, dtype=np.float64) - XYZ_CENTER) * XYZ_SCALE


def cubes_at_goal(state: np.ndarray, goal: np.ndarray) -> bool:
    """OGBench's success on planner states: every cube within 0.4 obs units (0.04 m) of its goal. [3N], [3N]."""
    d = np.asarray(state, dtype=np.float64).reshape(-1, 3) - np.asarray(goal, dtype=np.float64).reshape(-1, 3)
    return bool(np.all(np.linalg.norm(d, axis=1) <= SUCCESS_RADIUS))


def _seeded_env_class():
    """OGBench's CubeEnv with one action space whose ``sample()`` is seeded (stock: a fresh Box per call)."""
    from gymnasium.spaces import Box
    from ogbench.manipspace.envs.cube_env import CubeEnv

    class _SeededCubeEnv(CubeEnv):
        _space: Box | None = None

        @property
        def action_space(self) -> Box:
            if self._space is None:
                self._space = Box(low=-1.0, high=1.0, shape=(ACT_DIM,), dtype=np.float32)
            return self._space

    return _SeededCubeEnv


def make_cube_env(name: str, mode: str = "task"):
    """The raw OGBench env for ``cube-*`` (``mode='data_collection'`` for play data), not yet reset."""
    name = require_family(name, ("cube",), "the cube env")
    return _seeded_env_class()(env_type=name.split("-", 1)[1], permute_blocks=True, terminate_at_goal=False,
                               mode=mode, visualize_info=False)


@dataclass
class CubeReset:
    obs: np.ndarray  # [19+9N] start observation
    goal: np.ndarray  # [3N] goal cube xyz in obs units, in the obs slot order of this episode
    goal_obs: np.ndarray  # [19+9N] OGBench's goal observation (cubes settled at their goals)


class CubeEpisodes:
    """One ``cube-*`` env in OGBench's task mode: ``reset(task_id, seed)``, then
    ``step(action [5]) -> (obs, success)``."""

    def __init__(self, name: str):
        self._env = make_cube_env(name)
        self.name = name
        self.n_cubes = n_cubes(name)
        self.goal = np.zeros(3 * self.n_cubes)

    def task_start_goal(self, task_id: int) -> tuple[np.ndarray, np.ndarray]:
        """OGBench's task ``task_id`` (1..5) before permutation and jitter: start, goal cube xyz [N, 3] in obs units."""
        if task_id not in TASK_IDS:
            raise ConfigError(f"task={task_id!r} is not a task id; choose one of {list(TASK_IDS)}")
        if not getattr(self._env, "task_infos", None):
            self._env.set_tasks()
        info = self._env.task_infos[task_id - 1]
        return to_obs_units(info["init_xyzs"]), to_obs_units(info["goal_xyzs"])

    def reset(self, task_id: int, seed: int) -> CubeReset:
        self.task_start_goal(task_id)  # checks task_id
        seed = check_seed(seed)
        self._env.action_space.seed(seed)  # OGBench's 2 settling actions at the goal
        ob, info = self._env.reset(seed=seed, options=dict(task_id=task_id))
        u = self._env
        self.goal = to_obs_units(u._data.mocap_pos[u._cube_target_mocap_ids]).reshape(-1)
        return CubeReset(ob.astype(np.float64), self.goal.copy(), np.asarray(info["goal"], dtype=np.float64))

    def state(self, obs: np.ndarray) -> np.ndarray:
        """[..., 19+9N] -> [..., 3N] cube xyz in obs units."""
        return cube_xyz(obs, self.n_cubes)

    def step(self, action: np.ndarray) -> tuple[np.ndarray, bool]:
        """Apply one 5-D action in [-1, 1]; return the new obs and OGBench's success (every cube at its goal)."""
        action = np.asarray(action, dtype=np.float64)
        if action.shape != (ACT_DIM,):
            raise ValueError(f"{self.name}: an action has shape {action.shape}, the arm takes ({ACT_DIM},)")
        ob, _, _, _, info = self._env.step(np.clip(action, -1.0, 1.0))
        return ob.astype(np.float64), bool(info["success"])

    def close(self) -> None:
        self._env.close()
