"""Figure: a visual planner's first plan as images (decoded latents) beside the path the robot took.

    python jobs/figures/plot_visual_plan.py env=visual-pointmaze-medium env.warp_sparse=8.0 tasks=[2] seeds=[0]

Runs one episode (task and seed: the first of ``eval.tasks`` / ``eval.seeds``) with the configured
method, in this process. Left: the maze with the first plan as the estimator reads it (numbered
where the shown frames sit) and the executed path. Right, top row: the start frame, decoded frames
of the first plan (the VAE's decoder on the planned latents), the goal frame; bottom row: what the
chase camera really showed at those steps of the episode. Written to
``docs/figures/visual_plan_<env>_task<k>.png``.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from fmctd_dist.cli import run  # noqa: E402
from fmctd_dist.config import REPO_ROOT, load_config  # noqa: E402
from fmctd_dist.denoiser.local import LocalDenoiser  # noqa: E402
from fmctd_dist.device import set_threads  # noqa: E402
from fmctd_dist.diffusion.checkpoint import normaliser_from_manifest, read_manifest  # noqa: E402
from fmctd_dist.families.maze.geometry import maze_geometry  # noqa: E402
from fmctd_dist.families.visual.env import point_env_name, render_states  # noqa: E402
from fmctd_dist.families.maze.plots import draw_maze  # noqa: E402
from fmctd_dist.families import guide_map, hooks_for, plan_rules  # noqa: E402
from fmctd_dist.planners import make_planner  # noqa: E402

SHOWN = 5  # plan frames shown between the start and the goal


class Recording:
    """Wraps a planner to keep its first plan's latents (the episode keeps only their estimated positions)."""

    def __init__(self, planner):
        self.planner, self.first = planner, None

    def plan(self, start, goal, seed):
        out = self.planner.plan(start, goal, seed)
        self.first = out.waypoints if self.first is None else self.first
        return out


def main(argv: list[str]) -> int:
    cfg = load_config(argv, env="visual-pointmaze-medium", method="fast-mctd")
    set_threads(cfg.eval.threads or 1)
    task, seed = int(cfg.eval.tasks[0]), int(cfg.eval.seeds[0])
    manifest = read_manifest(cfg.checkpoint_dir(), cfg)
    denoiser = LocalDenoiser.from_checkpoint(cfg.checkpoint_dir(), cfg, guide_map=guide_map(cfg.env.name))
    planner = Recording(make_planner(cfg, denoiser, normaliser_from_manifest(manifest), plan_rules(cfg)))
    episodes = hooks_for(cfg.env.name).episodes(cfg)
    row = episodes.run(planner, task, seed)
    plan_z = np.asarray(planner.first)  # [F_env, D], one planner frame per env step
    traj = np.asarray(row["traj_xy"]).reshape(-1, 2)
    est = episodes.frames(plan_z)
    steps = np.linspace(0, len(plan_z) - 1, SHOWN + 2).round().astype(int)[1:-1]
    decoded = episodes.vae.decode(episodes.frames.latents(plan_z[steps]))
    real_at = np.minimum(steps + 1, len(traj) - 1)  # the robot's position after that many steps
    seen = render_states(cfg.env.name, traj[real_at], shadowsize=cfg.visual.shadowsize)
    ends = render_states(cfg.env.name, np.stack([traj[0], episodes.env.goal]), shadowsize=cfg.visual.shadowsize)

    fig = plt.figure(figsize=(15, 5.2))
    grid = fig.add_gridspec(2, SHOWN + 4, width_ratios=[4.2, 0.2] + [1] * (SHOWN + 2))
    ax = fig.add_subplot(grid[:, 0])
    draw_maze(ax, maze_geometry(point_env_name(cfg.env.name)))
    ax.plot(est[:, 0], est[:, 1], "--", color="tab:blue", lw=1.2, label="first plan (estimated x, y)")
    ax.plot(traj[:, 0], traj[:, 1], "-", color="tab:orange", lw=2.5, alpha=0.8, label="executed")
    ax.plot(*traj[0], "o", color="tab:green", ms=9, label="start")
    ax.plot(*episodes.env.goal, "*", color="tab:red", ms=15, label="goal")
    for k, s in enumerate(steps):
        ax.annotate(str(k + 1), est[s], fontsize=8, ha="center", va="center", color="white",
                    bbox=dict(boxstyle="circle,pad=0.2", fc="tab:blue", lw=0))
    ax.legend(loc="upper right", fontsize=7)
    outcome = f"success in {row['env_steps']} steps" if row["success"] else "failure"
    ax.set_title(f"{cfg.method.name} {cfg.env.name} task {task} seed {seed}: {outcome}", fontsize=9)
    top = [(ends[0], "start")] + [(d, f"plan {k + 1} (step {s + 1})") for k, (d, s) in enumerate(zip(decoded, steps))]
    top += [(ends[1], "goal")]
    bottom = [(None, "")] + [(f, f"seen at step {s + 1}") for f, s in zip(seen, steps)] + [(None, "")]
    for r, images in enumerate((top, bottom)):
        for c, (img, title) in enumerate(images):
            a = fig.add_subplot(grid[r, c + 2])
            a.axis("off")
            if img is not None:
                a.imshow(img, interpolation="nearest")
                a.set_title(title, fontsize=7)
    fig.text(0.62, 0.02, "top: decoded latents of the first plan; bottom: the chase camera at the same steps",
             ha="center", fontsize=8)
    out = REPO_ROOT / "docs" / "figures" / f"visual_plan_{cfg.env.name}_task{task}.png"
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110, bbox_inches="tight")
    print(f"{out}: {outcome}")
    return 0


if __name__ == "__main__":
    run(main)
