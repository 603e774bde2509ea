"""The maze family's robots, plan -> actions: PD on waypoints (PointMaze) or subgoals + a learned policy
(AntMaze). The choice lives here, with the family's controllers, so evaluation/ never branches on the robot.

An episode only needs ``make_controller(plan) -> controller`` with ``controller.act(obs)``;
this module picks the kind from ``env.name`` and, for the ant, loads and checks the
low-level policy (``env.policy``, default ``checkpoints/<env>-policy``). The check runs in
:func:`check_controller` before any actor starts, so a missing or mismatched policy is one
error in the job process, not a failure inside an actor.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from fmctd_dist.config import Config, is_ant, resolve_path


class Controller(Protocol):
    def act(self, obs: np.ndarray) -> np.ndarray: ...


ControllerFactory = Callable[[np.ndarray], Controller]


def policy_dir(cfg: Config) -> Path:
    """The ant's low-level policy dir: ``env.policy``, or ``checkpoints/<env>-policy`` when empty."""
    return resolve_path(cfg.env.policy or f"checkpoints/{cfg.env.name}-policy")


def check_controller(cfg: Config) -> dict[str, Any] | None:
    """AntMaze: the policy manifest (exists, right kind, trained for this maze), else CheckpointError. Point: None."""
    if not is_ant(cfg.env.name):
        return None
    from fmctd_dist.control.policy.checkpoint import read_policy_manifest  # deferred: torch
    from fmctd_dist.errors import CheckpointError
    from fmctd_dist.families.maze.ant_policy import ANT_SPEC

    try:
        return read_policy_manifest(policy_dir(cfg), ANT_SPEC, cfg.env.name)
    except CheckpointError as e:
        raise CheckpointError(f"env.policy={cfg.env.policy or policy_dir(cfg)} (the ant's low-level policy, set "
                              f"env.policy=DIR to use another): {e}") from None


def controller_factory(cfg: Config) -> ControllerFactory:
    """``plan [F, 2] (one x, y per env step) -> controller``; loads the ant policy once. With
    ``env.wall_clearance`` the controller follows the plan pushed off the walls (:mod:`.clearance`)."""
    if not is_ant(cfg.env.name):
        from fmctd_dist.families.maze.pd import PDController

        make: ControllerFactory = PDController
    else:
        from fmctd_dist.control.policy.checkpoint import load_policy
        from fmctd_dist.families.maze.ant_controller import AntPlanController
        from fmctd_dist.families.maze.ant_policy import ANT_SPEC

        policy = load_policy(policy_dir(cfg), ANT_SPEC, cfg.env.name)
        make = lambda plan: AntPlanController(plan, policy.act)  # noqa: E731
    if not cfg.env.wall_clearance:
        return make
    from fmctd_dist.families.maze.clearance import keep_clear
    from fmctd_dist.families.maze.geometry import maze_geometry

    geo, clearance = maze_geometry(cfg.env.name), cfg.env.wall_clearance
    return lambda plan: make(keep_clear(plan, geo, clearance))
