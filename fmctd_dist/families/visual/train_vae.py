"""Training loop of the visual maze's VAE: time-budgeted, resumable, deterministic from a seed.

Trains on the seeded frame subset of ``jobs/render_frames.py`` (``visual.frames`` train frames)
and measures on its validation frames (other episodes): per-pixel MSE / PSNR of decode(mu), and
how much of the position a *linear* read-out of mu keeps (least squares on the train frames,
RMSE on the validation frames; the MLP estimator does better). Every ``ckpt_every`` steps it
writes model.pt + manifest.json and train_state.pt (network, optimiser, RNGs, history);
rerunning continues from there. ``vae.time_budget_s`` bounds the training wall time over all
runs together, so a CPU budget is a config value, not a killed process.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from fmctd_dist.artifacts import MANIFEST_FILE
from fmctd_dist.config import Config, git_sha
from fmctd_dist.device import set_threads
from fmctd_dist.families.visual.checkpoint import read_part_manifest, save_part
from fmctd_dist.families.visual.config import PartsConfig, part_dir
from fmctd_dist.families.visual.frames import FrameSet, load_frame_set
from fmctd_dist.families.visual.vae import ConvVAE, encode_frames, psnr, recon_mse, vae_loss
from fmctd_dist.resume import Clock, TrainRun, check_resume, load_part_states, load_train_state, part_states, \
    save_train_state, stream_rng
BATCH_STREAM, NOISE_SEED_OFFSET = 31, 1_000_003
RESUME_FIELDS = ("latent_dim", "channels", "kl_weight", "batch_size", "seed")


def build_vae(latent_dim: int, channels: list[int], seed: int) -> ConvVAE:
    """Seeded init without touching the caller's global torch RNG."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        return ConvVAE(latent_dim, channels)


def linear_probe(z_train: np.ndarray, xy_train: np.ndarray, z_val: np.ndarray, xy_val: np.ndarray) -> float:
    """RMSE (world units, over x and y) of a least-squares affine map mu -> (x, y), fit on train, read on val."""
    a = np.c_[z_train, np.ones(len(z_train))].astype(np.float64)
    w, *_ = np.linalg.lstsq(a, xy_train.astype(np.float64), rcond=None)
    pred = np.c_[z_val, np.ones(len(z_val))] @ w
    return float(np.sqrt(np.mean(np.sum((pred - xy_val) ** 2, axis=-1))))


def train_vae(cfg: Config, pcfg: PartsConfig, progress: bool = True, frames: FrameSet | None = None
              ) -> dict[str, Any]:
    """Train (or resume) the VAE into vae.out; returns the manifest's summary."""
    v = pcfg.vae
    set_threads(v.threads)
    out = part_dir(cfg, v.out, "vae")
    fs = frames or load_frame_set(cfg)
    state = load_train_state(out)
    if state is not None:
        check_resume(out, "VAE", "vae.out", {"vae": state["config"], "env": state["env"]},
                     {"vae": pcfg.to_dict()["vae"], "env": cfg.env.name}, [f"vae.{k}" for k in RESUME_FIELDS] + ["env"],
                     [("frames", state["frames_sha256"], fs.sha256)],
                     "set visual.frames / visual.frames_seed as they were")
    if (out / MANIFEST_FILE).exists() and (state is None or int(state["step"]) >= v.max_steps
                                           or Clock(state["wall_time_s"]).over(v.time_budget_s)):
        m = read_part_manifest(out, "vae", cfg.env.name)  # finished earlier (budget or steps): nothing to do
        return {"out_dir": str(out), "step": m["steps"], "wall_time_s": m["wall_time_s"], **m["metrics"]}

    net = build_vae(v.latent_dim, v.channels, v.seed)
    opt = torch.optim.Adam(net.parameters(), lr=v.lr)
    rng = stream_rng(v.seed, BATCH_STREAM)
    gen = torch.Generator().manual_seed(v.seed + NOISE_SEED_OFFSET)
    if state is not None:
        load_part_states(state, net=net, opt=opt, rng=rng, gen=gen)
        for group in opt.param_groups:
            group["lr"] = v.lr
    run = TrainRun(f"vae {cfg.env.name}", v.max_steps, state or {"history": {"train": [], "val": []}},
                   v.time_budget_s, progress=progress, names=("mse", "kl"))  # [step, per-pixel mse] (train: + kl)
    hist = run.history
    probe: dict[str, float] = {}

    def metrics() -> dict[str, Any]:
        val = hist["val"][-1][1] if hist["val"] else None
        return {"train_mse": hist["train"][-1][1] if hist["train"] else None,
                "train_kl": hist["train"][-1][2] if hist["train"] else None,
                "val_mse": val, "val_psnr_db": psnr(val) if val is not None else None, **probe}

    def save() -> None:
        save_part(out, "vae", net, {
            "env": cfg.env.name, "latent_dim": v.latent_dim, "channels": list(v.channels), "config": {"vae": {
                **pcfg.to_dict()["vae"]}}, "frames": fs.record(), "steps": run.step,
            "wall_time_s": round(run.clock.wall_s, 2),
            "metrics": metrics(), "val_history": hist["val"], "git_sha": git_sha(),
            "input_layout": "encode(uint8 [B, 64, 64, 3] chase-camera frames) -> mu, logvar [B, latent_dim]; "
                            "decode(z) -> [B, 3, 64, 64] in (0, 1)"})
        save_train_state(out, {**part_states(net=net, opt=opt, rng=rng, gen=gen), **run.state(),
                               "config": pcfg.to_dict()["vae"], "env": cfg.env.name, "frames_sha256": fs.sha256})

    images = torch.from_numpy(fs.train_images)
    net.train()
    while not run.last:
        idx = rng.integers(0, len(images), size=v.batch_size)
        loss, mse, kl = vae_loss(net, images[idx], v.kl_weight, gen)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        run.tick(float(mse.detach()), float(kl.detach()))
        if run.due(v.log_every):
            run.log()
        if run.due(v.val_every):
            hist["val"].append([run.step, recon_mse(net, fs.val_images)])
            net.train()
        if run.last:
            z_tr, _ = encode_frames(net, fs.train_images)
            z_va, _ = encode_frames(net, fs.val_images)
            probe["val_linear_xy_rmse"] = linear_probe(z_tr, fs.train_xy, z_va, fs.val_xy)
            net.train()
        run.checkpoint(v.ckpt_every, save)
    run.close()
    return {"out_dir": str(out), "step": run.step, "wall_time_s": run.clock.wall_s, **metrics()}
