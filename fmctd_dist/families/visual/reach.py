"""Reach rate of the inverse dynamics following a recorded latent path, closed loop through the renderer.

A segment is ``reach.steps`` consecutive frames of a held-out (validation) episode of the latent
store: the point starts at the segment's first position, and at every step the controller sees
only the chase camera's new frame, encoded by the VAE (mu):

    a_k = invdyn(z_{k-1}, z_k, z*_{k+1})     z = the encoded observations, z* = the recorded path

(z_{-1} = z_0). Reached = the point ends within ``reach.radius`` of the segment's last recorded
position. This is the controller's job inside the planner (a planned latent path in place of the
recorded one), without the planner's errors. Reference on the same segments: the same loop with
perfect perception, a_k = clip((x*_{k+1} - x_k) / 0.2) from true positions.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from fmctd_dist.config import Config
from fmctd_dist.families.visual.env import VisualPointMaze
from fmctd_dist.families.visual.config import PartsConfig
from fmctd_dist.families.visual.latents import LatentStore
from fmctd_dist.families.visual.load import LoadedHead, LoadedVAE
from fmctd_dist.families.visual.train_head import POINT_STEP

REACH_STREAM = 43


def segments(store: LatentStore, n: int, steps: int, seed: int) -> list[tuple[int, int]]:
    """n seeded (val episode row, start step) pairs whose segment of ``steps`` actions fits the episode."""
    s = store.split("val")
    e, total = s["mu"].shape[:2]
    if e == 0 or total <= steps:
        raise ValueError(f"the latent store has {e} validation episodes of {total} steps: too few for reach.steps="
                         f"{steps}; raise latents.val_episodes or lower reach.steps")
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, REACH_STREAM])))
    return [(int(rng.integers(e)), int(rng.integers(total - steps))) for _ in range(n)]


def evaluate_reach(cfg: Config, pcfg: PartsConfig, vae: LoadedVAE, invdyn: LoadedHead, store: LatentStore,
                   progress: bool = True) -> dict[str, Any]:
    """Reach rate (and final distances) of the inverse dynamics and of the true-position reference."""
    r = pcfg.reach
    s = store.split("val")
    segs = segments(store, r.segments, r.steps, r.seed)
    env = VisualPointMaze(cfg.env.name, shadowsize=cfg.visual.shadowsize)
    env.reset(1, 0)  # OGBench needs one reset; every segment then places the point itself
    out: dict[str, Any] = {}
    t0 = time.perf_counter()
    try:
        for name in ("invdyn", "true_positions"):
            final = []
            bar = tqdm(segs, desc=f"reach {name}", disable=not progress or name != "invdyn", unit="segment")
            for e, t in bar:
                path_xy = s["xy"][e, t:t + r.steps + 1].astype(np.float64)
                path_z = s["mu"][e, t:t + r.steps + 1]
                env.set_position(path_xy[0])
                pos = env.position()
                z_prev = z = vae.encode(env.image()[None])[0] if name == "invdyn" else None
                for k in range(r.steps):
                    if name == "invdyn":
                        a = invdyn(np.concatenate([z_prev, z, path_z[k + 1]]))
                    else:
                        a = np.clip((path_xy[k + 1] - pos) / POINT_STEP, -1.0, 1.0)
                    pos, _ = env.step(a)
                    if name == "invdyn":
                        z_prev, z = z, vae.encode(env.image()[None])[0]
                final.append(float(np.linalg.norm(pos - path_xy[-1])))
            d = np.asarray(final)
            out[name] = {"reach_rate": float(np.mean(d <= r.radius)), "reach_rate_half_radius":
                         float(np.mean(d <= r.radius / 2)), "mean_final_dist": float(d.mean()),
                         "median_final_dist": float(np.median(d))}
    finally:
        env.close()
    path_len = [float(np.linalg.norm(np.diff(s["xy"][e, t:t + r.steps + 1], axis=0), axis=-1).sum()) for e, t in segs]
    out.update({"segments": len(segs), "steps": r.steps, "radius": r.radius, "seed": r.seed,
                "mean_path_length": float(np.mean(path_len)), "wall_s": round(time.perf_counter() - t0, 1)})
    return out


def run_reach(cfg: Config, pcfg: PartsConfig, progress: bool = True) -> dict[str, Any]:
    """Load the VAE, inverse dynamics and latent store of ``cfg``; measure; record under the invdyn's metrics.reach."""
    from fmctd_dist.device import set_threads
    from fmctd_dist.artifacts import MANIFEST_FILE, write_manifest
    from fmctd_dist.families.visual.config import part_dir
    from fmctd_dist.families.visual.latents import load_latents, vae_dir
    from fmctd_dist.families.visual.load import load_invdyn, load_vae

    set_threads(pcfg.reach.threads)
    vae = load_vae(vae_dir(cfg, pcfg), cfg.env.name)
    inv_dir = part_dir(cfg, pcfg.invdyn.out, "invdyn")
    invdyn = load_invdyn(inv_dir, cfg.env.name, vae)
    store = load_latents(cfg, pcfg, vae)
    result = evaluate_reach(cfg, pcfg, vae, invdyn, store, progress)
    m = invdyn.manifest
    m["metrics"]["reach"] = result  # the weights are unchanged: model_sha256 still holds
    write_manifest(m, inv_dir / MANIFEST_FILE)
    return {"out_dir": str(inv_dir), "reach": result}
