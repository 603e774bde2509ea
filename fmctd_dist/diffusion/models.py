"""model.kind -> network: the one place that knows which architectures exist.

Every model maps (x [B, T, D], t [B, T] long) -> x0_hat [B, T, D] and carries ``kind``,
``token_dim``, ``n_tokens`` and ``num_params()``, so the sampler, training loop, checkpoints
and denoisers never branch on the architecture.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from torch import nn

from fmctd_dist.config import MODEL_KINDS, DiffusionConfig, ModelConfig
from fmctd_dist.diffusion.model import DFTransformer
from fmctd_dist.diffusion.schedule import alphas_cumprod, make_betas
from fmctd_dist.diffusion.unet import TemporalUnet
from fmctd_dist.errors import unknown_name


def build_model(model_cfg: ModelConfig, n_tokens: int, token_dim: int | None = None,
                diffusion_cfg: DiffusionConfig | None = None) -> nn.Module:
    """An untrained model for ``cfg.model`` and a sequence of ``n_tokens`` tokens.

    token_dim defaults to 2 * frame_stack (one maze (x, y) per stacked frame; other families pass
    ``Config.token_dim``, and a frame is token_dim / frame_stack numbers); ``diffusion_cfg``
    (default: the paper's) gives the schedule that model.param v / v_offset read alphabar from.
    """
    dim = 2 * model_cfg.frame_stack if token_dim is None else token_dim
    if dim % model_cfg.frame_stack:
        raise ValueError(f"token_dim {dim} is not a multiple of model.frame_stack={model_cfg.frame_stack}")
    if model_cfg.kind == "df":
        dc = diffusion_cfg or DiffusionConfig()
        ab = alphas_cumprod(make_betas(dc.beta_schedule, dc.timesteps, dc.beta_start, dc.beta_end))
        return DFTransformer(dim, n_tokens, model_cfg.width, model_cfg.layers, model_cfg.heads, model_cfg.ff,
                             model_cfg.kind, model_cfg.param, model_cfg.norm, ab, dim // model_cfg.frame_stack)
    if model_cfg.kind == "diffuser":
        return TemporalUnet(dim, n_tokens, list(model_cfg.unet_channels), model_cfg.unet_kernel, model_cfg.kind,
                            model_cfg.unet_padding, model_cfg.unet_edge_frames)
    raise unknown_name("model.kind", model_cfg.kind, MODEL_KINDS)


def model_config_from_dict(d: dict[str, Any]) -> ModelConfig:
    """ModelConfig from a manifest's ``config.model`` (older manifests lack the U-Net and recipe fields:
    they get the defaults, i.e. the paper's recipe)."""
    names = {f.name for f in dataclasses.fields(ModelConfig)}
    return ModelConfig(**{k: v for k, v in d.items() if k in names})


def diffusion_config_from_dict(d: dict[str, Any]) -> DiffusionConfig:
    """DiffusionConfig from a manifest's ``config.diffusion`` (missing fields: the defaults)."""
    names = {f.name for f in dataclasses.fields(DiffusionConfig)}
    return DiffusionConfig(**{k: v for k, v in d.items() if k in names})
