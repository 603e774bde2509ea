"""The figure of one cube episode: cube paths and the arm's effector from above, and heights over time.

Reads a cube episode row (:func:`evaluation.cube_episode.run_cube_episode`): ``traj_cubes``,
``plan_cubes`` (the first plan), ``traj_effector`` and ``goal_cubes``, all in obs units.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from fmctd_dist.evaluation.plots import save_figure  # noqa: E402

COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:purple")


def plot_cube_episode(row: dict[str, Any], path: Path) -> Path:
    """Left: x, y from above (executed cube paths solid, first plan dashed, goals as stars, effector grey);
    right: each cube's z and the effector's z per env step (table 0.2, one stack level 0.4)."""
    n = int(row["n_cubes"])
    traj = np.asarray(row["traj_cubes"], np.float64).reshape(-1, n, 3)
    plan = np.asarray(row["plan_cubes"], np.float64).reshape(-1, n, 3)
    eff = np.asarray(row["traj_effector"], np.float64).reshape(-1, 3)
    goal = np.asarray(row["goal_cubes"], np.float64).reshape(n, 3)
    fig, (top, side) = plt.subplots(1, 2, figsize=(10, 4.5))
    top.plot(eff[:, 0], eff[:, 1], "-", color="0.6", lw=1.0, label="effector")
    for i in range(n):
        c = COLOURS[i % len(COLOURS)]
        top.plot(traj[:, i, 0], traj[:, i, 1], "-", color=c, lw=2.5, alpha=0.7, label=f"cube {i}")
        top.plot(plan[:, i, 0], plan[:, i, 1], "--", color=c, lw=1.0)
        top.plot(*traj[0, i, :2], "o", color=c, ms=7)
        top.plot(*goal[i, :2], "*", color=c, ms=14, markeredgecolor="k")
        side.plot(traj[:, i, 2], "-", color=c, lw=2.0, label=f"cube {i} z")
    side.plot(eff[:, 2], "-", color="0.6", lw=1.0, label="effector z")
    top.set_aspect("equal")
    top.set_xlabel("x (obs units, 0.1 m)")
    top.set_ylabel("y")
    top.legend(loc="best", fontsize=7, framealpha=0.8)
    side.set_xlabel("env step")
    side.set_ylabel("z (obs units)")
    side.legend(loc="best", fontsize=7, framealpha=0.8)
    outcome = "success" if row["success"] else f"failure ({row.get('why_failed', '')})"
    fig.suptitle(f"{row['method']} {row['env']} task {row['task']} seed {row['seed']}: {outcome}, "
                 f"{row['plan_time_s']:.1f}s planning, targets {row.get('targets', '')}", fontsize=9)
    return save_figure(fig, path)
