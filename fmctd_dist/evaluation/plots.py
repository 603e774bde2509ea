"""Pictures people would rather look at than read: plans on the maze, success vs planning time."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.ticker import FormatStrFormatter, LogLocator, MaxNLocator, NullFormatter  # noqa: E402

from fmctd_dist.registry import env_names  # noqa: E402
from fmctd_dist.evaluation.results import label  # noqa: E402


def save_figure(fig, path: Path) -> Path:
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_success_vs_time(summary: list[dict[str, Any]], path: Path) -> Path:
    """Write :func:`success_vs_time_figure` to ``path``."""
    return save_figure(success_vs_time_figure(summary), path)


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
    return save_figure(fig, path)
