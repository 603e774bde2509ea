"""AntMaze episodes over OGBench's MuJoCo ant maze, with the same start/goal protocols as PointMaze.

Same surface as :class:`~fmctd_dist.families.maze.pointmaze.PointMaze` (both subclass
:class:`~fmctd_dist.families.maze.tasks.OGBenchMaze`: ``reset(task_id, seed)``, ``step``,
``position``, ``geometry``), but the observation is the full 29-D ant state
(qpos 15 + qvel 14, x and y first) and an action is 8 joint torques in [-1, 1].

Success is OGBench's ant rule (``compute_success``, ``success_timing='post'``): the torso's
x, y within 0.5 of the goal after the step. OGBench's maze ant has no health check: an ant
that falls over is never reset and its episode runs on, so :meth:`AntMaze.healthy` and
:meth:`AntMaze.upright` let a dataset report how often that happens.
"""

from __future__ import annotations

import numpy as np

from fmctd_dist.families.maze.tasks import OGBenchMaze, Reset
from fmctd_dist.seeding import check_seed

GOAL_TOLERANCE = 0.5  # OGBench ant/humanoid success radius (point: 1.0)
OBS_DIM = 29  # qpos (x, y, z, quaternion 4, 8 joints) + qvel (14)
ACT_DIM = 8
HEALTHY_Z = (0.2, 1.0)  # AntEnv's healthy torso height (our expert was trained to terminate outside it)


def healthy(obs: np.ndarray) -> np.ndarray:
    """[..., 29] ant observations -> [...] bool: torso height inside AntEnv's healthy range."""
    z = np.asarray(obs)[..., 2]
    return (z >= HEALTHY_Z[0]) & (z <= HEALTHY_Z[1])


def upright(obs: np.ndarray) -> np.ndarray:
    """[..., 29] -> [...] bool: the torso's up axis points above the horizon.

    An ant on its back can still be "healthy" by height, so a fall is judged by both.
    The up axis' z component of quaternion (w, x, y, z) = qpos[3:7] is 1 - 2 (x^2 + y^2).
    """
    q = np.asarray(obs)[..., 3:7]
    return 1.0 - 2.0 * (q[..., 1] ** 2 + q[..., 2] ** 2) > 0.0


class AntMaze(OGBenchMaze):
    """One AntMaze env. ``reset(task_id, seed)`` then ``step(action [8]) -> (obs [29], success)``."""

    def reset(self, task_id: int, seed: int) -> Reset:
        """Task ``task_id`` (1..5): start/goal at its cell centres (``fixed``) or with seeded +-1 noise."""
        start, goal = self.task_start_goal(task_id, seed)
        return Reset(self.reset_to(start, goal, seed), goal.copy())

    def reset_to(self, start_xy: np.ndarray, goal_xy: np.ndarray, seed: int) -> np.ndarray:
        """A fresh ant (OGBench's reset: joint noise from ``seed``) standing at ``start_xy``; returns obs [29].

        OGBench's reset also perturbs the start with numpy's global RNG; we overwrite x, y
        right after, so the episode depends on ``seed`` and the given positions only.
        """
        seed = check_seed(seed)
        self._u.action_space.seed(seed)  # OGBench's 5 stabilising random actions
        self._u.reset(seed=seed, options=dict(task_id=1))
        self.set_goal(goal_xy)
        self._u.set_xy(np.asarray(start_xy, dtype=np.float64))
        return self.observation()

    def set_goal(self, goal_xy: np.ndarray) -> None:
        """Move the goal (the env's success check and its marker) without touching the ant."""
        self.goal = np.asarray(goal_xy, dtype=np.float64).copy()
        self._u.set_goal(goal_xy=self.goal)

    def restore(self, obs: np.ndarray) -> np.ndarray:
        """Put the ant in the state of a 29-D observation (qpos 15 + qvel 14, e.g. a dataset row); returns obs.

        MuJoCo's data is reset first (solver warm start, time, controls), so what follows
        depends on ``obs`` alone, not on what ran before. The env must have been reset once.
        """
        import mujoco

        obs = np.asarray(obs, dtype=np.float64)
        if obs.shape != (OBS_DIM,):
            raise ValueError(f"{self.name}: restore takes a ({OBS_DIM},) ant observation (qpos 15 + qvel 14), "
                             f"got {obs.shape}")
        mujoco.mj_resetData(self._u.model, self._u.data)
        self._u.set_state(obs[:15], obs[15:])
        return self.observation()

    def observation(self) -> np.ndarray:
        return self._u.get_ob().astype(np.float64)

    def position(self) -> np.ndarray:
        return self._u.get_xy().astype(np.float64)

    def healthy(self) -> bool:
        """Torso height inside AntEnv's healthy range (OGBench's maze never checks it)."""
        return bool(healthy(self.observation()))

    def upright(self) -> bool:
        return bool(upright(self.observation()))

    @property
    def dt(self) -> float:
        """Seconds per env step (MuJoCo timestep x frame skip)."""
        return float(self._u.dt)

    def step(self, action: np.ndarray) -> tuple[np.ndarray, bool]:
        """Apply 8 torques in [-1, 1]; return the new obs [29] and OGBench's success (within 0.5, after the step)."""
        action = np.asarray(action, dtype=np.float64)
        if action.shape != (ACT_DIM,):
            raise ValueError(f"{self.name}: an action has shape {action.shape}, the ant takes ({ACT_DIM},) torques")
        ob, _, _, _, info = self._u.step(np.clip(action, -1.0, 1.0))
        return ob.astype(np.float64), bool(info["success"])
