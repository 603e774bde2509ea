"""The maze's own figures: walls, one episode's first plan and its executed trajectory."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np

from fmctd_dist.evaluation.plots import save_figure
from fmctd_dist.families.maze.geometry import MAZE_UNIT, MazeGeometry


def draw_maze(ax, geo: MazeGeometry) -> None:
    """Walls as grey squares in world coordinates."""
    for i, j in zip(*np.nonzero(geo.walls)):
        x, y = geo.cell_to_xy((int(i), int(j)))
        ax.add_patch(plt.Rectangle((x - MAZE_UNIT / 2, y - MAZE_UNIT / 2), MAZE_UNIT, MAZE_UNIT, color="0.75", lw=0))
    rows, cols = geo.walls.shape
    ax.set_xlim(-MAZE_UNIT * 1.5, (cols - 1.5) * MAZE_UNIT)
    ax.set_ylim(-MAZE_UNIT * 1.5, (rows - 1.5) * MAZE_UNIT)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])


def plot_episode(row: dict[str, Any], geo: MazeGeometry, path: Path) -> Path:
    """The first plan (dashed) and the executed trajectory (solid) of one episode."""
    fig, ax = plt.subplots(figsize=(5, 5 * geo.walls.shape[0] / geo.walls.shape[1]))
    draw_maze(ax, geo)
    plan = np.asarray(row["plan_xy"]).reshape(-1, 2)
    traj = np.asarray(row["traj_xy"]).reshape(-1, 2)
    task = geo.task(row["task"])
    ax.plot(traj[:, 0], traj[:, 1], "-", color="tab:orange", lw=2.5, alpha=0.6, label="executed", zorder=2)
    ax.plot(plan[:, 0], plan[:, 1], "--", color="tab:blue", lw=1.0, label="plan", zorder=3)
    ax.plot(*traj[0], "o", color="tab:green", ms=8, label="start")
    ax.plot(*task.goal_xy, "*", color="tab:red", ms=14, label="goal")
    outcome = "success" if row["success"] else "failure"
    ax.set_title(f"{row['method']} {row['env']} task {row['task']} seed {row['seed']}: {outcome}, "
                 f"{row['plan_time_s']:.1f}s planning", fontsize=8)
    ax.legend(loc="best", fontsize=7, framealpha=0.8)
    return save_figure(fig, path)
