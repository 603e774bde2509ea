"""Training loop of the two latent MLPs: the position estimator and the inverse dynamics (resumable, time-budgeted).

    estimator: sampled z of the VAE's frames (visual.frames, scattered over the maze) -> (x, y);
               held out: the frames of validation episodes. RMSE in world units (Euclidean).
    invdyn:    sampled (z_{t-1}, z_t, z_{t+1}) of the latent store's train episodes -> a_t;
               held out: the store's validation episodes. Action MSE, beside two references on the
               same rows: predicting 0, and reading a_t off the true positions (clip((x_{t+1} - x_t) / 0.2),
               exact except against walls), the floor any perception could reach.

A fresh z is drawn from (mu, logvar) for every row of every batch, as the planner's latents are
sampled; the held-out numbers use mu (what the controller sees) and a sampled z.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from fmctd_dist.artifacts import MANIFEST_FILE
from fmctd_dist.config import Config, git_sha, resolve_path
from fmctd_dist.device import set_threads
from fmctd_dist.families.visual.checkpoint import read_part_manifest, save_part
from fmctd_dist.families.visual.config import PartsConfig, part_dir
from fmctd_dist.families.visual.frames import load_frame_set
from fmctd_dist.families.visual.latents import load_latents, vae_dir
from fmctd_dist.families.visual.load import LoadedVAE, load_vae
from fmctd_dist.families.visual.mlp import LatentMLP, build_mlp, triples
from fmctd_dist.families.visual.vae import encode_frames
from fmctd_dist.resume import TrainRun, check_resume, load_part_states, load_train_state, part_states, \
    save_train_state, stream_rng
BATCH_STREAM, VAL_STREAM = 41, 42
POINT_STEP = 0.2  # the point maze moves 0.2 * action per step in open floor (its data: x_{t+1} - x_t = 0.2 a_t)
RESUME_FIELDS = ("hidden", "batch_size", "seed")


def _sample(mu: np.ndarray, std: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return (mu + std * rng.standard_normal(mu.shape)).astype(np.float32)


def head_data(cfg: Config, pcfg: PartsConfig, part: str, vae: LoadedVAE) -> dict[str, Any]:
    """Train / val inputs as (mu, std) and targets, plus what the manifest records about them."""
    if part == "estimator":
        fs = load_frame_set(cfg)
        mu, logvar = encode_frames(vae.net, fs.train_images)
        vmu, vlogvar = encode_frames(vae.net, fs.val_images)
        return {"mu": mu, "std": np.exp(0.5 * logvar), "y": fs.train_xy, "val_mu": vmu,
                "val_std": np.exp(0.5 * vlogvar), "val_y": fs.val_xy, "record": {"frames": fs.record()}}
    h = pcfg.invdyn
    store = load_latents(cfg, pcfg, vae, resolve_path(h.latents) if h.latents else None)
    out: dict[str, Any] = {"record": {"latents": {k: store.manifest[k] for k in ("sha256", "frames_digest",
                                                                                  "episodes", "val_episodes")},
                                      "latents_path": str(store.path)}}
    for split, pre in (("train", ""), ("val", "val_")):
        s = store.split(split)
        out[pre + "mu"] = triples(s["mu"]).reshape(-1, 3 * vae.latent_dim)
        out[pre + "std"] = triples(np.exp(0.5 * s["logvar"])).reshape(-1, 3 * vae.latent_dim)
        out[pre + "y"] = s["actions"][:, 1:-1].reshape(-1, 2)
        if split == "val":
            xy = s["xy"].astype(np.float64)
            out["val_true_xy_action"] = np.clip((xy[:, 2:] - xy[:, 1:-1]) / POINT_STEP, -1, 1).reshape(-1, 2)
    return out


def _errors(part: str, pred: np.ndarray, y: np.ndarray) -> dict[str, float]:
    err = pred.astype(np.float64) - y
    if part == "estimator":
        return {"rmse": float(np.sqrt(np.mean(np.sum(err ** 2, -1)))), "mae_x": float(np.abs(err[:, 0]).mean()),
                "mae_y": float(np.abs(err[:, 1]).mean())}
    return {"mse": float(np.mean(err ** 2)), "rmse": float(np.sqrt(np.mean(err ** 2))),
            "mae": float(np.abs(err).mean())}


@torch.no_grad()
def _predict(net: LatentMLP, x: np.ndarray, chunk: int = 8192) -> np.ndarray:
    net.eval()
    out = np.concatenate([net(torch.from_numpy(x[a:a + chunk])).numpy() for a in range(0, len(x), chunk)])
    net.train()
    return out


def train_head(cfg: Config, pcfg: PartsConfig, part: str, progress: bool = True) -> dict[str, Any]:
    """Train (or resume) the estimator or the inverse dynamics into <part>.out; returns the manifest's summary."""
    h = getattr(pcfg, part)
    set_threads(h.threads)
    out = part_dir(cfg, h.out, part)
    vae = load_vae(part_dir(cfg, h.vae, "vae") if h.vae else vae_dir(cfg, pcfg), cfg.env.name)
    state = load_train_state(out)
    if state is None and (out / MANIFEST_FILE).exists():
        m = read_part_manifest(out, part, cfg.env.name, vae.latent_dim, vae.digest)
        return {"out_dir": str(out), "step": m["steps"], "wall_time_s": m["wall_time_s"], **m["metrics"]}
    if state is not None:
        check_resume(out, part, f"{part}.out", {part: state["config"]}, {part: pcfg.to_dict()[part]},
                     [f"{part}.{k}" for k in RESUME_FIELDS], [("VAE", state["vae_digest"], vae.digest)],
                     f"set {part}.vae to the VAE it started on")
    d = head_data(cfg, pcfg, part, vae)
    window = 1 if part == "estimator" else 3
    net = build_mlp(window * vae.latent_dim, 2, h.hidden, h.seed)
    net.set_normaliser(d["mu"], d["y"])
    opt = torch.optim.Adam(net.parameters(), lr=h.lr)
    rng = stream_rng(h.seed, BATCH_STREAM)
    val_z = _sample(d["val_mu"], d["val_std"], stream_rng(h.seed, VAL_STREAM))
    if state is not None:
        load_part_states(state, net=net, opt=opt, rng=rng)
    run = TrainRun(f"{part} {cfg.env.name}", h.max_steps, state or {"history": {"train": [], "val": []}},
                   h.time_budget_s, progress=progress)
    hist = run.history
    refs: dict[str, Any] = {}
    if part == "invdyn":
        y = d["val_y"].astype(np.float64)
        refs = {"val_mse_zero": float(np.mean(y ** 2)), "val_mse_true_positions":
                float(np.mean((d["val_true_xy_action"] - y) ** 2)), "val_rows": len(y), "train_rows": len(d["y"])}
    else:
        refs = {"val_rmse_mean_position": float(np.sqrt(np.mean(np.sum((d["val_y"] - d["y"].mean(0)) ** 2, -1)))),
                "val_rows": len(d["val_y"]), "train_rows": len(d["y"])}
    yt = torch.from_numpy(d["y"].astype(np.float32))

    def metrics() -> dict[str, Any]:
        got = {f"val_{k}": v for k, v in _errors(part, _predict(net, d["val_mu"]), d["val_y"]).items()}
        got.update({f"val_sampled_{k}": v for k, v in _errors(part, _predict(net, val_z), d["val_y"]).items()})
        return {**got, "train_loss": hist["train"][-1][1] if hist["train"] else None, **refs}

    def save(final: dict[str, Any]) -> None:
        save_part(out, part, net, {
            "env": cfg.env.name, "latent_dim": vae.latent_dim, "window": window, "hidden": list(h.hidden),
            "vae": {"path": str(vae.path), "digest": vae.digest}, "config": {part: pcfg.to_dict()[part]},
            "data": d["record"], "steps": run.step, "wall_time_s": round(run.clock.wall_s, 2), "metrics": final,
            "val_history": hist["val"], "git_sha": git_sha(),
            "input_layout": "z [..., latent_dim] (mu or a sample) -> world (x, y)" if part == "estimator" else
            "(z_{t-1}, z_t, z_{t+1}) concatenated [..., 3 latent_dim] -> a_t [..., 2] (point maze action, [-1, 1])"})
        save_train_state(out, {**part_states(net=net, opt=opt, rng=rng), **run.state(), "config": pcfg.to_dict()[part],
                               "vae_digest": vae.digest})

    final = metrics()
    while not run.last:
        i = rng.integers(0, len(d["y"]), size=h.batch_size)
        x = torch.from_numpy(_sample(d["mu"][i], d["std"][i], rng))
        loss = (net.normalised(x) - (yt[i] - net.out_mean) / net.out_std).square().mean()
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        run.tick(float(loss.detach()))
        if run.due(h.log_every):
            run.log()
        if run.due(h.val_every):
            final = metrics()
            hist["val"].append([run.step, final["val_rmse"] if part == "estimator" else final["val_mse"]])
        run.checkpoint(h.ckpt_every, lambda: save(final))
    run.close()
    return {"out_dir": str(out), "step": run.step, "wall_time_s": run.clock.wall_s, **final}
