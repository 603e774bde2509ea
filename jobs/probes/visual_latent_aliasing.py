"""Probe: does the VAE's latent space keep distant places apart, at the scale of one frame's step?

    python jobs/probes/visual_latent_aliasing.py visual.episodes=100             # medium, the shipped H=5 model
    python jobs/probes/visual_latent_aliasing.py env=visual-pointmaze-large visual.episodes=100
    python jobs/probes/visual_latent_aliasing.py visual.episodes=100 jump=1 checkpoint=runs/visual/s29-h1-e100-bw3-cos

The latent planner learns the step statistics of real latent paths in normalised latent units
(the units of its loss). If two real frames far apart in the maze lie closer in latent space than
a real frame-to-frame step often is, a plan can cross between them in one ordinary-looking step:
the estimator then reads a teleport. This reads only data (no planner): the normalised step between
consecutive train latents, and for a seeded sample of train latents the nearest train latent at
least ``far`` world units away (positions read by the position estimator), and prints how often
that far neighbour is closer than the data's own p99 step. Then, for the planner of ``checkpoint=``,
it samples unguided Diffusion Forcing plans from seeded validation starts and looks at each plan's
largest estimated step: how far its two frames are from the nearest train latents (beside that
distance for held-out real latents), and how far apart those two nearest real latents are, in latent
units and in world units. Near-real frames whose nearest reals are close in latent space but far in
the maze are a crossing between aliased places, not a sample off the manifold.
"""

from __future__ import annotations

import numpy as np

from fmctd_dist.cli import run
from fmctd_dist.device import set_threads
from visual_plan_quality import probe_config

QUERIES = 500  # seeded train latents whose far neighbour is searched
POOL = 20_000  # train latents searched (every k-th frame)
PLANS = 6  # unguided plans whose largest step is looked at


def pool_index(n: int) -> np.ndarray:
    """Indices of the searched train latents among ``n`` flattened ones: every k-th, at most POOL."""
    return np.arange(0, n, max(1, n // POOL))[:POOL]


def aliasing(z: np.ndarray, xy: np.ndarray, zn_of, far: float, seed: int = 0) -> dict[str, float]:
    """z [E, S, D] train latents, xy [E, S, 2] their positions, zn_of: latents -> normalised latents."""
    steps = np.linalg.norm(np.diff(zn_of(z), axis=1), axis=-1).ravel()
    flat_z, flat_xy = z.reshape(-1, z.shape[-1]), xy.reshape(-1, 2)
    pick = pool_index(len(flat_z))
    zn, pxy = zn_of(flat_z[pick]), flat_xy[pick]
    queries = np.random.default_rng(seed).choice(len(zn), min(QUERIES, len(zn)), replace=False)
    nearest = []
    for i in queries:
        away = np.linalg.norm(pxy - pxy[i], axis=-1) >= far
        if away.any():
            nearest.append(float(np.linalg.norm(zn[away] - zn[i], axis=-1).min()))
    nearest_a = np.asarray(nearest)
    p99 = float(np.percentile(steps, 99))
    return {"step_median": float(np.median(steps)), "step_p99": p99, "far": far, "queries": len(nearest_a),
            "far_neighbour_median": float(np.median(nearest_a)),
            "far_neighbour_p10": float(np.percentile(nearest_a, 10)),
            "share_closer_than_p99_step": float(np.mean(nearest_a < p99))}


def nearest(zn: np.ndarray, pool: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normalised latents [N, D] -> (distance to, index of) the nearest of ``pool`` [M, D]."""
    d = np.linalg.norm(pool[None] - zn[:, None], axis=-1)
    i = d.argmin(1)
    return d[np.arange(len(zn)), i], i


def largest_steps(cfg, ds, train_xy: np.ndarray) -> list[str]:
    """Table rows: each unguided plan's largest step and what lies on either side of it.

    ``train_xy`` [E, S, 2] are the train latents' estimated positions (main's). Plans are read as the
    planner's value reads them (estimated positions; with visual.plan_xy, the plan's own x, y).
    """
    from visual_plan_quality import visual_planner

    planner, episodes, manifest, norm = visual_planner(cfg)
    positions = episodes.frames
    flat = ds.train.reshape(-1, ds.train.shape[-1])
    pick = pool_index(len(flat))
    pool, pool_xy = norm.normalise(flat[pick]), train_xy.reshape(-1, 2)[pick]
    real, _ = nearest(norm.normalise(ds.val.reshape(-1, ds.val.shape[-1])[::97][:300]), pool)
    rows = [f"{cfg.checkpoint_dir()} ({manifest['digest']}); held-out real latents' distance to the nearest train "
            f"latent: median {np.median(real):.2f}, p90 {np.percentile(real, 90):.2f}",
            "| plan | largest step (world units) at plan frame | its frames' distance to the nearest train latent | "
            "those two train latents apart: latent / world units |", "|---|---|---|---|"]
    span = cfg.env.horizon - cfg.jump
    rng = np.random.default_rng(0)
    for i in range(PLANS):
        e, t = int(rng.integers(len(ds.val))), int(rng.integers(ds.val.shape[1] - span))
        z = ds.val[e, t]
        plan = np.concatenate([z[None], planner.plan(z, ds.val[e, t + span], i).waypoints[:: cfg.jump]])
        xy = positions(plan)
        k = int(np.linalg.norm(np.diff(xy, axis=0), axis=-1).argmax())
        d, idx = nearest(norm.normalise(plan[[k, k + 1]]), pool)
        rows.append(f"| {i} | {np.linalg.norm(xy[k + 1] - xy[k]):.2f} at {k} | {d[0]:.2f} / {d[1]:.2f} | "
                    f"{np.linalg.norm(pool[idx[0]] - pool[idx[1]]):.2f} / "
                    f"{np.linalg.norm(pool_xy[idx[0]] - pool_xy[idx[1]]):.2f} |")
    return rows


def main(argv: list[str]) -> int:
    from fmctd_dist.families.visual.dataset import load_visual_dataset
    from fmctd_dist.families.visual.guide import load_positions

    cfg = probe_config(argv)
    set_threads(cfg.eval.threads or 1)
    ds = load_visual_dataset(cfg)
    dim = int(ds.manifest["latent_dim"])
    latents = ds.train[..., :dim]  # visual.plan_xy frames: the latent part
    if ds.plan_xy:  # the frames carry the estimator's (x, y) already
        xy = ds.train[..., dim:dim + 2].astype(np.float64)
    else:
        xy = load_positions(cfg, str(ds.manifest["vae"]["digest"]), dim)[0](latents)
    norm = ds.normaliser
    r = aliasing(latents, xy, lambda z: (z - norm.mean[:dim]) / norm.std[:dim], far=5.0)
    print(f"{ds.path}: {ds.train.shape[0]} train episodes; latent distances in normalised units (the planner's)")
    print("| consecutive step: median / p99 | nearest latent >= 5 units away: median / p10 | "
          "far neighbours closer than the p99 step |\n|---|---|---|")
    print(f"| {r['step_median']:.2f} / {r['step_p99']:.2f} | {r['far_neighbour_median']:.2f} / "
          f"{r['far_neighbour_p10']:.2f} | {r['share_closer_than_p99_step']:.0%} of {r['queries']} |")
    print("\n".join(largest_steps(cfg, ds, xy)))
    return 0


if __name__ == "__main__":
    run(main)
