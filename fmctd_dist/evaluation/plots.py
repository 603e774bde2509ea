"""Pictures people would rather look at than read: plans on the maze, success vs planning time."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.ticker import FormatStrFormatter, LogLocator, MaxNLocator, NullFormatter  # noqa: E402
import numpy as np  # noqa: E402

from fmctd_dist.registry import env_names  # noqa: E402
from fmctd_dist.families.maze.geometry import MAZE_UNIT, MazeGeometry  # noqa: E402
from fmctd_dist.evaluation.results import label  # noqa: E402


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


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
    return _save(fig, path)


def plot_success_vs_time(summary: list[dict[str, Any]], path: Path) -> Path:
    """Write :func:`success_vs_time_figure` to ``path``."""
    return _save(success_vs_time_figure(summary), path)


def success_vs_time_figure(summary: list[dict[str, Any]]):
    """The paper's Figure 1 style: one point per (method, env, config), error bars over seeds.

    Planning times spanning less than 4x get a linear axis (a log axis over 4.5-4.6 s has
    only colliding minor labels); wider spans a log axis labelled at 1-2-5 steps. Each method
    has its own colour in the legend; its config variants are separate points in that colour.
    """
    fig, ax = plt.subplots(figsize=(8, 4))
    envs = sorted({s["env"] for s in summary}, key=lambda e: (env_names().index(e) if e in env_names() else 99, e))
    markers = dict(zip(envs, "osD^vP<>"))
    # one colour per method; a method's config variants (the table's "[config ...]" lines) share it
    base = lambda s: label(s).split(" [")[0]  # noqa: E731
    methods = list(dict.fromkeys(base(s) for s in summary))
    colors = {m: plt.get_cmap("tab10")(i % 10) for i, m in enumerate(methods)}
    for s in summary:
        ax.errorbar(s["plan_time_s"], s["success"], xerr=s["plan_time_std"], yerr=s["success_std"],
                    marker=markers[s["env"]], color=colors[base(s)], capsize=3, ls="none")
    for m in methods:
        ax.plot([], [], "s", color=colors[m], label=m)
    for env in envs:
        ax.plot([], [], markers[env], color="k", mfc="none", label=env.replace("pointmaze-", ""))
    times = [s["plan_time_s"] for s in summary if s["plan_time_s"] > 0]
    lo = min((s["plan_time_s"] - s["plan_time_std"] for s in summary), default=0.0)
    hi = max((s["plan_time_s"] + s["plan_time_std"] for s in summary), default=1.0)
    if times and max(times) / min(times) >= 4:
        ax.set_xscale("log")
        ax.xaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        ax.xaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("planning time per episode (s, log)")
    else:
        pad = max(0.15 * (hi - lo), 0.05 * max(hi, 1e-3))
        ax.set_xlim(max(lo - pad, 0.0), hi + pad)
        ax.xaxis.set_major_locator(MaxNLocator(nbins=6))
        ax.set_xlabel("planning time per episode (s)")
    ax.set_ylabel("success (%)")
    ax.set_ylim(-5, 105)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=1 if len(methods) + len(envs) <= 8 else 2, loc="center left",
              bbox_to_anchor=(1.01, 0.5))
    fig.tight_layout()
    return fig


def plot_ablation(summary: list[dict[str, Any]], knob: str, path: Path) -> Path:
    """Success (left axis, solid) and planning time (right axis, dashed, log) against one search knob,
    one colour per maze, error bars over seeds.

    Settings are evenly spaced and labelled with their values (K runs 1..400, H 1..10)."""
    values = sorted({s["value"] for s in summary})
    envs = list(dict.fromkeys(s["env"] for s in summary))  # ablation_summary's maze order
    fig, ax = plt.subplots(figsize=(5.5, 3.4))
    ax2 = ax.twinx()
    for i, env in enumerate(envs):
        ss = [s for s in summary if s["env"] == env]
        x = [values.index(s["value"]) for s in ss]
        color = plt.get_cmap("tab10")(i % 10)
        label = env.replace("pointmaze-", "")
        ax.errorbar(x, [s["success"] for s in ss], yerr=[s["success_std"] for s in ss], marker="o", color=color,
                    capsize=3, label=f"{label}: success")
        ax2.errorbar(x, [s["plan_time_s"] for s in ss], yerr=[s["plan_time_std"] for s in ss], marker="s", ls="--",
                     color=color, capsize=3, label=f"{label}: planning time")
    ax.set_ylabel("success (%), solid")
    ax.set_ylim(-5, 105)
    ax2.set_ylabel("planning time (s), dashed")
    ax2.set_yscale("log")
    ax2.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))  # 1, 2, 5, 10, 20, 50, ... s
    ax2.yaxis.set_major_formatter(FormatStrFormatter("%g"))
    ax2.yaxis.set_minor_formatter(NullFormatter())
    ax.set_xticks(range(len(values)), [str(v) for v in values])
    ax.set_xlabel(knob)
    ax.grid(alpha=0.3)
    handles = ax.get_legend_handles_labels()[0] + ax2.get_legend_handles_labels()[0]
    ax.legend(handles, [h.get_label() for h in handles], fontsize=7, loc="upper center",
              bbox_to_anchor=(0.5, -0.22), ncol=2)
    return _save(fig, path)
