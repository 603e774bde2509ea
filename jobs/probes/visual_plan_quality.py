"""Latent plan quality of a visual planner: warps on estimated positions and distance to the latent manifold.

    python jobs/probes/visual_plan_quality.py env=visual-pointmaze-medium                 # Fast-MCTD, tasks 1-5, seed 0
    python jobs/probes/visual_plan_quality.py env=visual-pointmaze-medium \
        checkpoint=runs/visual/visual-pointmaze-medium-h5

One search per task from the start frame to the goal frame (no control). Prints a table and the JSON.
The other latent-plan probes of this folder import its functions.

A latent plan is only as usable as its latents are images the VAE could have made: the value,
the guidance and the inverse dynamics all read latents, and the position estimator was trained on
real ones only. So for the plans of every node of one Fast-MCTD tree per task (start and goal
frames encoded as in an episode) this reports:

- warps: the fraction of plans with a step (estimated positions, world units) over the value's
  warp threshold, the median of each plan's largest step and of its first step (from the start);
- reach: the median over plans of the closest estimated approach to the estimated goal;
- manifold: the median distance (normalised latent units) from each plan latent to its nearest
  latent of the store's train episodes, beside the same for held-out real latents (what a model
  that samples real trajectories would score), and the estimator's largest 5-step move along real
  held-out episodes (its own noise, the floor of the warp test).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from fmctd_dist.cli import run
from fmctd_dist.config import Config, load_config
from fmctd_dist.device import set_threads
from fmctd_dist.family import warp_threshold
from fmctd_dist.hints import shown

NN_STRIDE = 5  # every 5th train latent is a nearest-neighbour candidate (~4k of 20k)


def nearest_distance(q: np.ndarray, ref: np.ndarray, chunk: int = 2048) -> np.ndarray:
    """[N] Euclidean distance of each row of q [N, D] to its nearest row of ref [M, D]."""
    out = np.empty(len(q))
    for i in range(0, len(q), chunk):
        d2 = ((q[i:i + chunk, None, :] - ref[None]) ** 2).sum(-1)
        out[i:i + chunk] = np.sqrt(d2.min(1))
    return out


@dataclass(frozen=True)
class TaskSearch:
    """One search from a task's start frame: every expanded node's simulated plan and the latents it planned between."""

    task: int
    plans: np.ndarray  # [N, F, D] every expanded node's simulated plan, model latents
    z: np.ndarray  # [D] start frame (the VAE's mu of the start image; visual.plan_xy: with its estimated x, y)
    zg: np.ndarray  # [D] goal frame
    status: str
    stop_reason: str
    expansions: int
    plan_time_s: float


def probe_config(argv: list[str]) -> Config:
    """The latent-plan probes' config: unguided Diffusion Forcing at jump 5 on visual medium unless ``argv``
    says otherwise."""
    given = {w.split("=", 1)[0] for w in argv}
    defaults = [w for w in ("jump=5", "method.guidance_scale=0.0") if w.split("=", 1)[0] not in given]
    return load_config(defaults + argv, env="visual-pointmaze-medium", method="diffusion-forcing")


def visual_planner(cfg: Config) -> tuple[Any, Any, dict[str, Any], Any]:
    """(planner, the family's episode parts, the planner's manifest, its normaliser) for ``cfg``'s checkpoint."""
    from fmctd_dist.denoiser.local import LocalDenoiser
    from fmctd_dist.diffusion.checkpoint import normaliser_from_manifest, read_manifest
    from fmctd_dist.families import guide_map, hooks_for, plan_rules
    from fmctd_dist.planners import make_planner

    manifest = read_manifest(cfg.checkpoint_dir(), cfg)
    norm = normaliser_from_manifest(manifest)
    denoiser = LocalDenoiser.from_checkpoint(cfg.checkpoint_dir(), cfg, guide_map=guide_map(cfg.env.name))
    planner = make_planner(cfg, denoiser, norm, plan_rules(cfg))
    return planner, hooks_for(cfg.env.name).episodes(cfg), manifest, norm


def task_frames(episodes: Any, task: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(start, goal) planner frames of ``task``: the env reset, its start and goal images encoded as an episode
    encodes them (latents, or with visual.plan_xy latents and their estimated x, y)."""
    env, f = episodes.env, episodes.frames
    env.reset(task, seed)
    return (f.of_latents(episodes.vae.encode(env.image()[None])[0]),
            f.of_latents(episodes.vae.encode(env.goal_image()[None])[0]))


def search_task(cfg: Config, planner: Any, episodes: Any, task: int, seed: int = 0) -> TaskSearch:
    """One plan call from ``task``'s start frame to its goal frame, encoded as an episode encodes them."""
    from fmctd_dist.planners.base import plan_seed

    z, zg = task_frames(episodes, task, seed)
    out = planner.plan(z, zg, plan_seed(cfg.seed, task, seed, 0))
    r = planner.last_result
    return TaskSearch(task, r.tree.sim_plan[1:r.expansions + 1], z, zg, out.status, r.stop_reason,
                      r.expansions, out.plan_time_s)


def estimated_steps(pos: Callable[[np.ndarray], np.ndarray], plans: np.ndarray, z: np.ndarray) -> np.ndarray:
    """[N, F] estimated world-unit step into each plan frame, the first from the start latent ``z``."""
    xy = pos(plans)
    prev = np.concatenate([np.broadcast_to(pos(z), (len(xy), 1, 2)), xy[:, :-1]], axis=1)
    return np.linalg.norm(xy - prev, axis=-1)


def plan_quality(cfg: Config, tasks: list[int], seed: int = 0) -> dict[str, Any]:
    """One search per task from its start frame to its goal frame; the statistics of the module docstring."""
    from fmctd_dist.families.visual.dataset import load_visual_dataset

    planner, episodes, manifest, norm = visual_planner(cfg)
    env, pos = episodes.env, episodes.frames
    ds = load_visual_dataset(cfg)
    ref = norm.normalise(ds.train.reshape(-1, ds.train.shape[-1])[::NN_STRIDE])
    real = ds.val[:, ::NN_STRIDE]  # [E, S/5, D], 5 env steps apart like a jump-5 plan
    real_moves = np.linalg.norm(np.diff(pos(real), axis=1), axis=-1)
    rows = []
    for task in tasks:
        s = search_task(cfg, planner, episodes, task, seed)
        steps = estimated_steps(pos, s.plans, s.z)  # [N, F]
        to_goal = np.linalg.norm(pos(s.plans) - pos(s.zg), axis=-1).min(1)
        nn = nearest_distance(norm.normalise(s.plans.reshape(-1, s.plans.shape[-1])), ref)
        rows.append({"task": task, "status": s.status, "stop_reason": s.stop_reason, "expansions": s.expansions,
                     "plan_time_s": round(s.plan_time_s, 2), "plans": len(s.plans),
                     "warp_fraction": float((steps[:, :-1].max(1) > warp_threshold(cfg)).mean()),
                     "median_max_step": float(np.median(steps[:, :-1].max(1))),
                     "median_first_step": float(np.median(steps[:, 0])),
                     "median_closest_to_goal": float(np.median(to_goal)),
                     "median_nn_distance": float(np.median(nn)),
                     "start_estimate_error": float(np.linalg.norm(pos(s.z) - env.position())),
                     "goal_estimate_error": float(np.linalg.norm(pos(s.zg) - env.goal))})
    real_nn = nearest_distance(norm.normalise(real.reshape(-1, real.shape[-1])), ref)
    return {"checkpoint": shown(cfg.checkpoint_dir()), "digest": manifest["digest"],
            "train_steps": manifest.get("train_steps"), "val_loss": manifest.get("final_losses", {}).get("val"),
            "warp_threshold": warp_threshold(cfg), "tasks": rows,
            "real_val_median_nn_distance": float(np.median(real_nn)),
            "real_val_max_5step_move": float(real_moves.max()),
            "real_val_p99_5step_move": float(np.percentile(real_moves, 99))}


def main(argv: list[str]) -> int:
    cfg = load_config(argv, env="visual-pointmaze-medium", method="fast-mctd")
    set_threads(cfg.eval.threads or 1)
    q = plan_quality(cfg, list(cfg.eval.tasks), int(cfg.eval.seeds[0]))
    print(f"{q['checkpoint']} ({q['digest']}, {q['train_steps']} steps, val loss {q['val_loss']:.4f}); "
          f"warp threshold {q['warp_threshold']}")
    print("| task | status | plans | warping | median largest step | median first step | median closest to goal "
          "| median NN distance |")
    print("|---|---|---|---|---|---|---|---|")
    for r in q["tasks"]:
        print(f"| {r['task']} | {r['status']} ({r['stop_reason']}) | {r['plans']} | {100 * r['warp_fraction']:.0f}% | "
              f"{r['median_max_step']:.2f} | {r['median_first_step']:.2f} | {r['median_closest_to_goal']:.2f} | "
              f"{r['median_nn_distance']:.3f} |")
    print(f"real held-out latents: median NN distance {q['real_val_median_nn_distance']:.3f}; estimator's 5-step "
          f"moves along real episodes: p99 {q['real_val_p99_5step_move']:.2f}, max {q['real_val_max_5step_move']:.2f}")
    print(json.dumps(q))
    return 0


if __name__ == "__main__":
    run(main)
