"""Figure: chase-camera frames along a path through the visual maze, next to the maze.

    python jobs/figures/plot_visual_frames.py                      # -> docs/figures/visual_frames.png

For task 1 of medium and large, the BFS cell path from start to goal (cell centres joined by
straight lines), six frames at evenly spaced points of it, rendered as the env renders them
(chase camera, config's visual.shadowsize). The camera looks along +y, up in the maze plot.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from fmctd_dist.cli import run  # noqa: E402
from fmctd_dist.config import REPO_ROOT, load_config  # noqa: E402
from fmctd_dist.families.maze.geometry import maze_geometry  # noqa: E402
from fmctd_dist.families.visual.env import point_env_name, render_states  # noqa: E402
from fmctd_dist.families.maze.plots import draw_maze  # noqa: E402

MAZES = ("visual-pointmaze-medium", "visual-pointmaze-large")
FRAMES = 6


def bfs_path(geo, task_id: int) -> np.ndarray:
    """[P, 2] world points along the BFS cell path of a task, 0.2 apart (the point's speed per step)."""
    task = geo.task(task_id)
    cells = [task.init_ij]
    while cells[-1] != task.goal_ij:
        cells.append(geo.next_cell(cells[-1], task.goal_ij))
    centres = np.array([geo.cell_to_xy(c) for c in cells])
    pts = [np.linspace(a, b, 20, endpoint=False) for a, b in zip(centres[:-1], centres[1:])]
    return np.concatenate(pts + [centres[-1:]])


def main(argv: list[str]) -> int:
    cfg = load_config(argv, env=MAZES[0], method="mctd")
    fig, axes = plt.subplots(len(MAZES), FRAMES + 1, figsize=(2.0 * (FRAMES + 1) + 1.2, 2.6 * len(MAZES)),
                             gridspec_kw={"width_ratios": [2.2] + [1] * FRAMES})
    for row, name in zip(axes, MAZES):
        geo = maze_geometry(point_env_name(name))
        path = bfs_path(geo, 1)
        picks = np.linspace(0, len(path) - 1, FRAMES).round().astype(int)
        frames = render_states(name, path[picks], shadowsize=cfg.visual.shadowsize)
        ax = row[0]
        draw_maze(ax, geo)
        ax.plot(path[:, 0], path[:, 1], "-", color="tab:orange", lw=2)
        ax.plot(*path[0], "o", color="tab:green", ms=8)
        ax.plot(*path[-1], "*", color="tab:red", ms=13)
        for k, p in enumerate(path[picks]):
            ax.annotate(str(k + 1), p, fontsize=8, ha="center", va="center", color="white",
                        bbox=dict(boxstyle="circle,pad=0.2", fc="tab:blue", lw=0))
        ax.set_title(f"{name} task 1 (BFS path)", fontsize=8)
        for k, (a, img, p) in enumerate(zip(row[1:], frames, path[picks])):
            a.imshow(img, interpolation="nearest")
            a.set_xticks([])
            a.set_yticks([])
            a.set_title(f"{k + 1}: ({p[0]:.1f}, {p[1]:.1f})", fontsize=8)
    fig.suptitle(f"Chase-camera frames (64x64, camera 'back' on the point, looking along +y = up in the maze; "
                 f"shadow map {cfg.visual.shadowsize})", fontsize=9)
    fig.tight_layout()
    out = REPO_ROOT / "docs" / "figures" / "visual_frames.png"
    fig.savefig(out, dpi=110)
    print(out)
    return 0


if __name__ == "__main__":
    run(main)
