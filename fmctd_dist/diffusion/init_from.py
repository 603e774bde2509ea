"""Starting a planner's training from another checkpoint's weights (``train.init_from``).

The env, jump and horizon may differ from the source's (positions are sinusoidal, so a transformer
runs at any token count); the architecture may not, except that a DF model's frames may be widened
(:func:`widen_frames`). The provenance returned goes into the new manifest, with the lineage of
training behind the weights (:func:`~fmctd_dist.diffusion.checkpoint.lineage`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from fmctd_dist.artifacts import MODEL_FILE, torch_load_weights, verify_weights
from fmctd_dist.config import REPO_ROOT, Config
from fmctd_dist.diffusion.checkpoint import SHAPE_FREE_FIELDS, model_fields, saved_model, lineage, read_manifest
from fmctd_dist.errors import CheckpointError


def load_init_weights(ckpt_dir: str | Path, cfg: Config) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
    """Weights to start a run from (``train.init_from``) -> (state_dict, provenance for the manifest)."""
    ckpt_dir = Path(ckpt_dir)
    manifest = read_manifest(ckpt_dir)
    where, fix = f"train.init_from={ckpt_dir}", "point train.init_from at an intact checkpoint"
    verify_weights(ckpt_dir, manifest, where, fix)
    saved = saved_model(manifest)
    for f in model_fields(cfg):
        if f not in SHAPE_FREE_FIELDS and saved.get(f) != getattr(cfg.model, f):
            raise CheckpointError(f"train.init_from={ckpt_dir} has model.{f}={saved.get(f)!r} but the config has "
                                  f"model.{f}={getattr(cfg.model, f)!r}; set model.{f}={saved.get(f)!r} or start "
                                  "from scratch (train.init_from=)")
    state = torch_load_weights(ckpt_dir / MODEL_FILE, where, fix)
    widened = {}
    saved_td, fs = int(manifest.get("token_dim", cfg.token_dim)), cfg.model.frame_stack
    if saved_td != cfg.token_dim:
        old = saved_td // fs
        if cfg.model.kind != "df" or saved_td % fs or old >= cfg.frame_dim:
            raise CheckpointError(f"train.init_from={ckpt_dir} models {saved_td} numbers per token but this config "
                                  f"has {cfg.token_dim} ({cfg.frame_dim} per frame x model.frame_stack={fs}); a DF "
                                  "model can only be widened to frames that add numbers after its own (e.g. "
                                  "positions appended to a latent model's frames): start from such a checkpoint, "
                                  "or from scratch (train.init_from=)")
        state = widen_frames(state, old, cfg.frame_dim, fs)
        widened = {"widened_frames": {"from": old, "to": cfg.frame_dim}}
    provenance = {"path": str(ckpt_dir.relative_to(REPO_ROOT) if ckpt_dir.is_relative_to(REPO_ROOT) else ckpt_dir),
                  "digest": manifest["digest"], "env": manifest.get("config", {}).get("env", {}).get("name"),
                  "jump": manifest.get("config", {}).get("jump"), "train_steps": manifest.get("train_steps"),
                  **lineage(manifest), **widened}
    return state, provenance


def widen_frames(state: dict[str, torch.Tensor], old: int, new: int, frame_stack: int) -> dict[str, torch.Tensor]:
    """A DF model's weights on frames of ``old`` numbers, for frames of ``new`` > ``old`` whose first ``old``
    numbers are the old ones (e.g. a visual latent model -> [z, x, y] frames).

    Why: a widened model starts as the trained one instead of from scratch. The added numbers enter
    with zero input weights and leave with zero output weights (x0_hat = 0, their normalised mean),
    so at step 0 the old numbers' predictions are exactly the old model's; training then learns the rest.
    """
    cols = torch.as_tensor([f * new + j for f in range(frame_stack) for j in range(old)])  # old token -> new token
    out = dict(state)
    w_in = state["init_mlp.0.weight"]  # [width, token_dim + t_embed]: the token's numbers first
    extra = w_in.shape[1] - old * frame_stack
    wide = torch.zeros(w_in.shape[0], new * frame_stack + extra, dtype=w_in.dtype)
    wide[:, cols] = w_in[:, :old * frame_stack]
    wide[:, new * frame_stack:] = w_in[:, old * frame_stack:]
    out["init_mlp.0.weight"] = wide
    for key in ("out.weight", "out.bias"):
        w = state[key]
        o = torch.zeros((new * frame_stack, *w.shape[1:]), dtype=w.dtype)
        o[cols] = w
        out[key] = o
    return out
