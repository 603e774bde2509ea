"""Diffusion Forcing training loop (docs/reference.md §5), resumable and deterministic per device.

Every token gets its own timestep, so one network learns all the partially-noised sequences the
pyramid schedule (and hence the tree search) will show it. A rerun continues from the last save with
optimiser and RNG states restored, so a killed run ends with the uninterrupted run's weights (bitwise
on CPU). The recipe levers (train.lr_schedule, precision, boundary_*, position_weight, clean_context;
see TrainConfig) default to the paper's recipe (:data:`PAPER_RECIPE`).
"""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Any, Callable, Protocol

import numpy as np
import torch

from fmctd_dist.config import Config, git_sha, resolve_path
from fmctd_dist.tokens import Normaliser
from fmctd_dist.device import resolve_device, set_threads, warn_bf16
from fmctd_dist.diffusion.checkpoint import check_compatible, lineage, load_checkpoint, save_checkpoint
from fmctd_dist.diffusion.init_from import load_init_weights
from fmctd_dist.diffusion.model import DFTransformer
from fmctd_dist.diffusion.models import build_model
from fmctd_dist.diffusion.schedule import alphas_cumprod, make_betas
from fmctd_dist.errors import ConfigError, DatasetError
from fmctd_dist.resume import SNAPSHOTS, TrainRun, check_resume, load_part_states, load_train_state, part_states, \
    save_train_state, snapshot_due, stream_rng
CONTEXT_T_MAX = 250  # with prob. 0.5 the context token's timestep is resampled in [0, 250)
MASKED_WEIGHT = 0.05  # loss weight of tokens past the random terminal (they are pure noise)
VAL_NOISE_SEED = 12345  # fixed noise for validation so losses are comparable across steps
LOG_EVERY = 10  # steps between progress-bar updates (each one syncs the device)
# The paper's training (appendix tables "Hyperparameters for the Diffusion Forcing" / "... for the Diffuser").
PAPER_TRAINING = {"df": {"layers": 12, "batch_size": 1024, "steps": 200_005},
                  "diffuser": {"batch_size": 32, "steps": 20_000, "unet_channels": [32, 128, 256]}}
PAPER_RECIPE = {"model.param": "x0", "model.norm": "post", "train.lr_schedule": "constant", "train.precision": "fp32",
                "train.boundary_weight": 0.0, "train.boundary_space": "token",
                "train.position_weight": 0.0, "train.clean_context": 0.0, "train.wall_weight": 0.0}


Readout = Callable[[torch.Tensor], torch.Tensor]  # normalised frames [..., d] -> standardised positions [..., 2]


class TrainDataLike(Protocol):
    """What the loop needs from a dataset: normalised token windows [B, T, D], token 0 = context."""

    normaliser: Normaliser
    digest: str
    seed: int

    def sample(self, rng: np.random.Generator, batch: int) -> np.ndarray: ...

    def val_batches(self, n: int, batch: int) -> list[np.ndarray]: ...


class NoisingLoss(torch.nn.Module):
    """What both losses share: the schedule's forward process, x_k = sqrt(ab_k) x0 + sqrt(1 - ab_k) noise with the
    noise clipped to +-diffusion.clip_noise, and the sampler's timestep for a clean (level-0) token."""

    def __init__(self, cfg: Config, device: torch.device):
        super().__init__()
        dc = cfg.diffusion
        self.ab = ab = alphas_cumprod(make_betas(dc.beta_schedule, dc.timesteps, dc.beta_start, dc.beta_end))
        self.register_buffer("sqrt_ab", torch.as_tensor(np.sqrt(ab), dtype=torch.float32, device=device))
        self.register_buffer("sqrt_1m_ab", torch.as_tensor(np.sqrt(1.0 - ab), dtype=torch.float32, device=device))
        self.timesteps, self.clip_noise = dc.timesteps, dc.clip_noise
        self.context_t = dc.stabilization - 1  # docs/reference.md §5

    def noised(self, x0: torch.Tensor, k: torch.Tensor, gen: torch.Generator) -> torch.Tensor:
        """x0 [B, T, D] at per-token timesteps k [B, T]; the noise drawn from ``gen``."""
        noise = torch.randn(x0.shape, generator=gen, device=x0.device).clamp(-self.clip_noise, self.clip_noise)
        return self.sqrt_ab[k][..., None] * x0 + self.sqrt_1m_ab[k][..., None] * noise


class DFLoss(NoisingLoss):
    """Diffusion Forcing loss: per-token timesteps, length randomisation, min-SNR-weighted x0 MSE."""

    def __init__(self, cfg: Config, device: torch.device, readout: Readout | None = None,
                 wall: Readout | None = None):
        super().__init__(cfg, device)
        snr = self.ab / (1.0 - self.ab)
        self.register_buffer("w_snr", torch.as_tensor(np.minimum(snr, cfg.diffusion.snr_clip), dtype=torch.float32,
                                                      device=device))
        self.frame_stack = cfg.model.frame_stack
        self.boundary_weight = cfg.train.boundary_weight
        self.readout = readout  # frames -> positions (frozen), for the position levers
        self.boundary_readout = readout if cfg.train.boundary_space == "position" else None
        self.position_weight = cfg.train.position_weight
        self.clean_context = cfg.train.clean_context
        self.wall, self.wall_weight = wall, cfg.train.wall_weight  # frames -> depth inside walls (frozen)

    def forward(self, model: DFTransformer, x0: torch.Tensor, gen: torch.Generator,
                validation: bool = False) -> torch.Tensor:
        """x0: [B, T, D] clean normalised tokens -> scalar loss; all randomness from ``gen``.

        ``validation=True`` is the paper's loss alone (no train.boundary_weight term, no
        train.clean_context feeding), so validation losses compare between recipe arms.
        """
        b, t, _ = x0.shape
        dev = x0.device
        k = torch.randint(0, self.timesteps, (b, t), generator=gen, device=dev)
        ctx = torch.randint(0, CONTEXT_T_MAX, (b,), generator=gen, device=dev)
        k[:, 0] = torch.where(torch.rand(b, generator=gen, device=dev) < 0.5, ctx, k[:, 0])
        terminal = torch.randint(2, t + 1, (b, 1), generator=gen, device=dev)  # tokens >= terminal are cut off
        cut = torch.arange(t, device=dev)[None] >= terminal  # [B, T]
        k = torch.where(cut, self.timesteps - 1, k)
        weight = torch.where(cut, MASKED_WEIGHT, 1.0) * self.w_snr[k]  # [B, T]
        xt = self.noised(x0, k, gen)
        if self.clean_context and not validation:  # drawn last: with the lever off, every other draw is as before
            clean = torch.rand(b, generator=gen, device=dev) < self.clean_context
            k[:, 0] = torch.where(clean, self.context_t, k[:, 0])
            xt[:, 0] = torch.where(clean[:, None], self.sqrt_ab[self.context_t] * x0[:, 0], xt[:, 0])
            weight[:, 0] = self.w_snr[k[:, 0]]
        pred = model(xt, k)
        loss = (weight[..., None] * (pred - x0).square()).mean()
        if not validation and self.boundary_weight:
            loss = loss + self.boundary_weight * boundary_loss(pred, x0, weight, self.frame_stack,
                                                               self.boundary_readout)
        if not validation and self.position_weight:
            loss = loss + self.position_weight * position_loss(pred, x0, weight, self.frame_stack, self.readout)
        if not validation and self.wall_weight:
            loss = loss + self.wall_weight * wall_loss(pred, ~cut, self.frame_stack, self.wall)
        return loss


def boundary_loss(pred: torch.Tensor, x0: torch.Tensor, weight: torch.Tensor, frame_stack: int,
                  readout: Readout | None = None) -> torch.Tensor:
    """Weighted MSE of the step across each token boundary (pred, x0 [B, T, D], weight [B, T]), predicted vs true:
    a per-token offset error, which the token MSE barely sees, shows here in full. Each boundary has its noisier
    token's weight; ``readout`` (train.boundary_space=position) maps frames to positions first."""
    d = x0.shape[-1] // frame_stack

    def step(x: torch.Tensor) -> torch.Tensor:
        first, last = x[:, 1:, :d], x[:, :-1, -d:]  # first frame of token k+1, last frame of token k
        if readout is not None:
            first, last = readout(first), readout(last)
        return first - last

    w = torch.minimum(weight[:, 1:], weight[:, :-1])  # [B, T-1]
    return (w[..., None] * (step(pred) - step(x0)).square()).mean()


def position_loss(pred: torch.Tensor, x0: torch.Tensor, weight: torch.Tensor, frame_stack: int,
                  readout: Readout) -> torch.Tensor:
    """Weighted MSE of each token's first and last frame's position as ``readout`` reads it, predicted vs true
    (train.position_weight): where most of a frame's variance carries no position (a visual latent's view
    jitter), a prediction close in the frame can be far in position. Only the two end frames are read: they
    carry the token's offset, and reading all ten through the visual estimator tripled a dense step."""
    b, t, dd = x0.shape
    d = dd // frame_stack
    ends = lambda x: x.reshape(b, t, frame_stack, d)[:, :, [0, frame_stack - 1]]  # noqa: E731  [B, T, 2, d]
    err = (readout(ends(pred)) - readout(ends(x0))).square()  # [B, T, 2, 2]
    return (weight[..., None, None] * err).mean()


def wall_loss(pred: torch.Tensor, kept: torch.Tensor, frame_stack: int, depth: Readout) -> torch.Tensor:
    """Mean depth inside the walls (``depth``: frames -> maze units, 0 in free space) of every predicted frame of
    the kept tokens (kept [B, T]; the cut-off ones are pure noise), each noise level alike (train.wall_weight):
    routes are chosen at high noise, where the min-SNR weight is near zero. Zero on any data window."""
    b, t, dd = pred.shape
    frames = pred.reshape(b, t, frame_stack, dd // frame_stack)
    return (depth(frames).mean(-1) * kept).sum() / kept.sum().clamp(min=1)


class DiffuserLoss(NoisingLoss):
    """Diffuser loss (Janner et al.): one uniform timestep per sample, start token clean, plain x0 MSE.

    The start token is fed exactly as the sampler feeds a level-0 token (timestep
    stabilization-1, scaled by its sqrt(alphabar), no noise) and is left out of the loss:
    at planning time it is inpainted, never predicted. No length randomisation.
    """

    def __init__(self, cfg: Config, device: torch.device):
        super().__init__(cfg, device)
        self.discount = cfg.train.loss_discount

    def frame_weights(self, plan_frames: int, device: torch.device) -> torch.Tensor:
        """[plan_frames] Janner's loss_discount weights discount**f, mean 1 (all ones at 1.0)."""
        w = self.discount ** torch.arange(plan_frames, dtype=torch.float64, device=device)
        return (w / w.mean()).float()

    def forward(self, model: torch.nn.Module, x0: torch.Tensor, gen: torch.Generator) -> torch.Tensor:
        """x0: [B, T, D] clean normalised tokens (token 0 = start) -> scalar loss; randomness from ``gen``."""
        b, t, _ = x0.shape
        dev = x0.device
        k = torch.randint(0, self.timesteps, (b, 1), generator=gen, device=dev).expand(b, t - 1)
        k = torch.cat((torch.full((b, 1), self.context_t, dtype=k.dtype, device=dev), k), dim=1)  # [B, T]
        xt = self.noised(x0, k, gen)
        xt = torch.cat((self.sqrt_ab[self.context_t] * x0[:, :1], xt[:, 1:]), dim=1)
        err = (model(xt, k)[:, 1:] - x0[:, 1:]).square()  # [B, T-1, D]
        return (self.frame_weights(t - 1, dev)[None, :, None] * err).mean()


def make_loss(cfg: Config, device: torch.device, readout: Readout | None = None,
              wall: Readout | None = None) -> torch.nn.Module:
    """The training loss of ``cfg.model.kind`` (df: DFLoss, diffuser: DiffuserLoss)."""
    return DiffuserLoss(cfg, device) if cfg.model.kind == "diffuser" else DFLoss(cfg, device, readout, wall)


def wall_depth(cfg: Config, data: Any, device: torch.device) -> tuple[Readout | None, dict[str, Any]]:
    """The data's frozen wall depth (``data.wall_depth(cfg) -> (frames -> depth, provenance)``) when
    train.wall_weight > 0, and what the manifest records; data or a model that cannot serve it is one ConfigError."""
    if not cfg.train.wall_weight:
        return None, {}
    fix = "drop train.wall_weight (0 = off, the paper's)"
    if cfg.model.kind != "df":
        raise ConfigError(f"train.wall_weight={cfg.train.wall_weight} is a Diffusion Forcing lever, but "
                          f"model.kind={cfg.model.kind}; {fix}")
    make = getattr(data, "wall_depth", None)
    if make is None:  # a TrainData over data without walls holds None
        raise ConfigError(f"train.wall_weight={cfg.train.wall_weight}: the {cfg.env.name} data has no maze walls to "
                          f"measure; {fix}")
    depth, provenance = make(cfg)
    if isinstance(depth, torch.nn.Module):
        depth = depth.to(device).requires_grad_(False)
    return depth, {"wall_depth": provenance}


def position_readout(cfg: Config, data: Any, device: torch.device) -> tuple[Readout | None, dict[str, Any]]:
    """The data's frozen position readout (``data.position_readout(cfg) -> (readout, provenance)``) when a lever
    needs it (train.boundary_space=position, train.position_weight>0), and what the manifest records; a lever
    the data or model cannot serve, or the position space of an off boundary loss, is one ConfigError."""
    tc = cfg.train
    if tc.boundary_space == "token" and not tc.position_weight:
        return None, {}
    if cfg.model.kind != "df":
        raise ConfigError(f"train.boundary_space / train.position_weight are Diffusion Forcing levers, but "
                          f"model.kind={cfg.model.kind}; drop them")
    if tc.boundary_space == "position" and not tc.boundary_weight:
        raise ConfigError(f"train.boundary_space={tc.boundary_space} measures the token-boundary loss, which is off "
                          f"(train.boundary_weight={tc.boundary_weight}, model.kind={cfg.model.kind}); set "
                          "train.boundary_weight>0 on a model.kind=df model, or drop train.boundary_space")
    make = getattr(data, "position_readout", None)
    if make is None:
        raise ConfigError(f"train.boundary_space={tc.boundary_space}, train.position_weight={tc.position_weight}: "
                          f"the {cfg.env.name} data has no position readout; use train.boundary_space=token and "
                          "train.position_weight=0")
    readout, provenance = make(cfg)
    if isinstance(readout, torch.nn.Module):
        readout = readout.to(device).requires_grad_(False)
    return readout, {"position_readout": provenance}


def vs_paper(cfg: Config, step: int) -> str:
    """One line for the manifest: what this run traded against the paper's training."""
    paper = PAPER_TRAINING[cfg.model.kind]
    seen = step * cfg.train.batch_size
    parts = [f"{step} of the paper's {paper['steps']} steps at batch {cfg.train.batch_size} (paper "
             f"{paper['batch_size']}): {seen:,} training windows, "
             f"{100 * seen / (paper['steps'] * paper['batch_size']):.1f}%"
             " of the paper's"]
    if "unet_channels" in paper and list(cfg.model.unet_channels) != paper["unet_channels"]:
        parts.append(f"U-Net channels {list(cfg.model.unet_channels)} (paper {paper['unet_channels']})")
    if "layers" in paper:
        parts.append(f"{cfg.model.layers} of the paper's {paper['layers']} layers (width {cfg.model.width})")
    if cfg.train.init_from:
        parts.append(f"started from the weights of {cfg.train.init_from} (its steps not counted here)")
    levers = {k: getattr(getattr(cfg, k.split(".")[0]), k.split(".")[1]) for k in PAPER_RECIPE}
    changed = [f"{k}={v}" for k, v in levers.items() if v != PAPER_RECIPE[k]]
    if changed:
        parts.append("recipe " + ", ".join(changed) + " (paper " + ", ".join(
            f"{k.split('.')[-1]} {PAPER_RECIPE[k]}" for k in levers if levers[k] != PAPER_RECIPE[k]) + ")")
    return "; ".join(parts)


def lr_at(cfg: Config, step: int, wall_s: float = 0.0) -> float:
    """Linear warm-up over train.warmup steps, times the schedule's factor.

    constant (paper): 1. cosine: (1 + cos(pi p)) / 2 with p the fraction of the run done,
    max(step / train.max_steps, wall_s / train.time_budget_s): a time-budgeted run decays to
    0 when its budget ends (then the LR depends on wall time, so such a run is not bitwise
    reproducible; step-bounded runs are). wsd: 1 until the last train.decay_steps steps (0: the
    last 20%) before train.max_steps, then linear to 0 at max_steps (steps only).
    """
    tc = cfg.train
    lr = tc.lr * (min(1.0, (step + 1) / tc.warmup) if tc.warmup > 0 else 1.0)
    if tc.lr_schedule == "constant":
        return lr
    if tc.lr_schedule == "wsd":
        n = tc.decay_steps or max(1, round(0.2 * tc.max_steps))
        return lr * min(1.0, max(0.0, (tc.max_steps - step) / n))
    done = step / tc.max_steps
    if tc.time_budget_s > 0:
        done = max(done, wall_s / tc.time_budget_s)
    return lr * 0.5 * (1.0 + math.cos(math.pi * min(done, 1.0)))


@torch.no_grad()
def validation_loss(model: DFTransformer, loss_fn: DFLoss, batches: list[torch.Tensor], device: torch.device) -> float:
    """Mean loss on fixed batches with fixed noise (same generator seed every call)."""
    was_training = model.training
    model.eval()
    gen = torch.Generator(device=device).manual_seed(VAL_NOISE_SEED)
    kw = {"validation": True} if isinstance(loss_fn, DFLoss) else {}
    total = sum(float(loss_fn(model, x, gen, **kw)) for x in batches)
    model.train(was_training)
    return total / max(len(batches), 1)


def train(cfg: Config, data: TrainDataLike, out_dir: str | Path, progress: bool = True) -> dict[str, Any]:
    """Train (or resume) the cfg.model.kind model into out_dir; returns the summary written to the manifest."""
    device = resolve_device(cfg.device)
    set_threads(cfg.train.threads)
    if cfg.train.precision == "bf16":
        warn_bf16(device, "train.precision")
    out_dir = Path(out_dir)
    tc = cfg.train

    with torch.random.fork_rng(devices=[]):  # seeded init without touching the caller's global RNG
        torch.manual_seed(tc.seed)
        model = build_model(cfg.model, cfg.n_tokens, cfg.token_dim, diffusion_cfg=cfg.diffusion).to(device)
    opt = torch.optim.AdamW(model.parameters(), lr=tc.lr, betas=(0.9, 0.999), weight_decay=tc.weight_decay)
    readout, readout_provenance = position_readout(cfg, data, device)
    wall, wall_provenance = wall_depth(cfg, data, device)
    loss_fn = make_loss(cfg, device, readout, wall)
    rng = stream_rng(tc.seed, data.seed)
    gen = torch.Generator(device=device).manual_seed(tc.seed)
    saved: dict[str, Any] = {"history": {"val": [], "train": []}}  # step, clock and history to continue from
    init_from = None  # provenance of train.init_from weights, kept by every later save and resume
    ema = copy.deepcopy(model).requires_grad_(False)  # what gets shipped (ema_decay=0: a plain copy)

    state = load_train_state(out_dir)
    same_data = "regenerate the original dataset"
    if state is not None:  # the same architecture on the same data
        check_compatible({"config": state["config"], "n_tokens": state["n_tokens"]}, cfg, out_dir)
        check_resume(out_dir, "planner", "train.out", {}, {}, data=[("dataset", state["dataset_digest"], data.digest)],
                     data_fix=same_data)
        load_part_states(state, model=model, optimizer=opt, numpy_rng=rng, torch_rng=gen)
        ema.load_state_dict(state.get("ema", state["model"]))  # runs from before EMA start it here
        saved, init_from = state, state.get("init_from")
    elif (out_dir / "manifest.json").exists():
        # A shipped checkpoint (model.pt + manifest, no train_state.pt: that is not committed).
        # Continue from its weights and step with a fresh optimiser rather than overwrite it.
        shipped, manifest = load_checkpoint(out_dir, cfg)
        check_resume(out_dir, "planner", "train.out", {}, {},
                     data=[("dataset", manifest["dataset_digest"], data.digest)], data_fix=same_data)
        model.load_state_dict(shipped.state_dict())
        ema.load_state_dict(shipped.state_dict())
        step = int(manifest["train_steps"])
        saved = {"step": step, "wall_time_s": manifest["wall_time_s"], "cpu_time_s": manifest.get("cpu_time_s"),
                 "history": {"val": [list(v) for v in manifest.get("val_history", [])], "train": [],
                             "optimizer_reset_at": [step]}}
        init_from = manifest.get("init_from")
    elif tc.init_from:
        weights, init_from = load_init_weights(resolve_path(tc.init_from), cfg)
        model.load_state_dict(weights)
        ema.load_state_dict(weights)
    run = TrainRun("train", tc.max_steps, saved, tc.time_budget_s, tc.budget_clock, progress)
    resumed_from = None if "step" not in saved else run.step
    if resumed_from is not None and run.last:  # finished, by steps or by its time budget
        run.close()
        return _summary(run.step, run.clock.wall_s, run.history, out_dir, model, resumed_from)

    val = [torch.as_tensor(v, dtype=torch.float32, device=device) for v in data.val_batches(tc.val_batches,
                                                                                        tc.batch_size)]
    base = {"dataset_digest": data.digest, "data_seed": data.seed, "git_sha": git_sha(),
            "normaliser": {"mean": data.normaliser.mean.tolist(), "std": data.normaliser.std.tolist()}}
    base.update(getattr(data, "provenance", {}))  # e.g. the visual maze's VAE and latent store
    base.update(readout_provenance)  # the position levers: which readout measured their losses
    base.update(wall_provenance)  # the wall lever: which maze and grid
    if init_from is not None:
        base["init_from"] = init_from

    def save() -> None:
        step, wall, cpu = run.step, run.clock.wall_s, run.clock.cpu_s
        summary = _summary(step, wall, run.history, out_dir, model, resumed_from)
        fields = {**base, "ema_decay": tc.ema_decay, "config": cfg.to_dict(), "train_steps": step, "wall_time_s": wall,
                  "cpu_time_s": cpu, "vs_paper": vs_paper(cfg, step), "final_losses": summary["final_losses"],
                  "val_history": run.history["val"]}
        fields.update(lineage(fields))  # steps, CPU time and samples, through every init_from ancestor
        save_checkpoint(out_dir, ema, fields)
        snap = snapshot_due(out_dir, tc.snapshot_every_s, cpu if run.clock.kind == "cpu" else wall)
        if snap is not None:
            save_checkpoint(out_dir / SNAPSHOTS / f"{snap}-step{step:07d}", ema, fields)
        save_train_state(out_dir, {
            **part_states(model=model, ema=ema, optimizer=opt, numpy_rng=rng, torch_rng=gen), **run.state(),
            "config": cfg.to_dict(), "dataset_digest": data.digest, "n_tokens": cfg.n_tokens, "init_from": init_from,
        })

    model.train()
    while not run.last:
        x0 = torch.as_tensor(data.sample(rng, tc.batch_size), dtype=torch.float32, device=device)
        if x0.shape[1:] != (cfg.n_tokens, cfg.token_dim):
            raise DatasetError(
                f"training windows have shape {tuple(x0.shape[1:])} but the config needs (n_tokens, token_dim) = "
                f"({cfg.n_tokens}, {cfg.token_dim}); data.train_window, env.horizon, jump and model.frame_stack "
                "must describe the same windows"
            )
        lr = lr_at(cfg, run.step, run.clock.used())
        for group in opt.param_groups:
            group["lr"] = lr
        with torch.autocast(device.type, dtype=torch.bfloat16, enabled=tc.precision == "bf16"):
            loss = loss_fn(model, x0, gen)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        update_ema(ema, model, tc.ema_decay, run.step)
        run.tick(loss.detach().float())  # summed on the device: one sync per log
        if run.due(LOG_EVERY):
            mean = run.log()[0]
            if not np.isfinite(mean):
                raise FloatingPointError(f"training loss is {mean} at step {run.step}; lower train.lr or check the "
                                         "data")
        if tc.val_every > 0 and run.due(tc.val_every):
            run.history["val"].append([run.step, validation_loss(ema, loss_fn, val, device)])
        run.checkpoint(tc.ckpt_every, save)
    run.close()
    return _summary(run.step, run.clock.wall_s, run.history, out_dir, model, resumed_from)


@torch.no_grad()
def update_ema(ema: torch.nn.Module, model: torch.nn.Module, decay: float, step: int) -> None:
    """ema <- d * ema + (1 - d) * model, with d warmed up as min(decay, (1 + step) / (10 + step))."""
    d = min(decay, (1 + step) / (10 + step)) if decay > 0 else 0.0
    for e, p in zip(ema.parameters(), model.parameters()):
        e.lerp_(p, 1.0 - d)
    for e, b in zip(ema.buffers(), model.buffers()):
        e.copy_(b)


def _summary(step: int, wall: float, history: dict, out_dir: Path, model: DFTransformer,
             resumed_from: int | None) -> dict[str, Any]:
    last = {k: history[k][-1][1] if history[k] else None for k in ("train", "val")}
    return {"step": step, "wall_time_s": wall, "final_losses": last, "param_count": model.num_params(),
            "out_dir": str(out_dir), "resumed_from": resumed_from}
