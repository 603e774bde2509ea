"""Why an episode failed, from its result row: the first plan against the maze, the trajectory against the goal.

Used by ``jobs/probes/why_failed.py``. The authors' value function checks warps and reaching only, so a
plan may cut through a wall and still win the search; and an ant that falls never gets up.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fmctd_dist.families.maze.geometry import maze_geometry
from fmctd_dist.families.maze.geometry import densify

STILL_STEPS = 200  # a robot whose last STILL_STEPS positions span less than STILL_RANGE stopped
STILL_RANGE = 1.0


def failures(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per failed row: status, first-plan length / end distance to the goal / share of its path in free
    cells, closest approach of the executed trajectory, and whether the robot stood still at the end."""
    out = []
    for r in rows:
        if r["success"]:
            continue
        geo = maze_geometry(r["env"])
        goal = np.asarray(geo.task(r["task"]).goal_xy)
        plan = np.asarray(r["plan_xy"], dtype=np.float64).reshape(-1, 2)
        traj = np.asarray(r["traj_xy"], dtype=np.float64).reshape(-1, 2)
        path = densify(plan)  # 10 points along each plan step
        statuses = str(r["plan_status"]).split(",")
        tail = traj[-STILL_STEPS:]
        out.append({"task": r["task"], "seed": r["seed"], "plan_len": len(plan),
                    "status": statuses[0] if len(statuses) == 1 else f"{len(statuses)} plans",
                    "plan_end_to_goal": float(np.linalg.norm(plan[-1] - goal)),
                    "plan_in_free": float(geo.in_free_cell(path).mean()),
                    "closest": float(np.linalg.norm(traj - goal, axis=1).min()), "steps": r["env_steps"],
                    "stopped": bool(len(traj) > STILL_STEPS and np.ptp(tail, axis=0).max() < STILL_RANGE)})
    return out
