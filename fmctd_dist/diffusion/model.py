"""The Diffusion Forcing transformer: a non-causal denoiser with one noise level per token.

Every token carries its own diffusion timestep, which is what lets the pyramid schedule keep
later tokens noisier than earlier ones (and lets MCTD cut that schedule into tree segments).
Architecture as in the authors' release (reference.md §5): token ++ sinusoidal timestep
embedding -> MLP -> + sinusoidal position embedding -> post-LN transformer encoder -> x0.

The encoder blocks are written out (same math and parameter count as
``nn.TransformerEncoderLayer(norm_first=False, activation=relu, dropout=0)``) instead of
using ``nn.TransformerEncoder``: PyTorch's inference fast path runs a fused kernel under
``no_grad`` whose bits differ (~1e-6) from the autograd path, and the sampler needs an
unguided job to give the same bits whether or not its micro-batch computes guidance.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from fmctd_dist.config import ModelConfig
from fmctd_dist.errors import unknown_name

MODEL_KINDS = ("df",)


class SinusoidalEmbedding(nn.Module):
    """[...] numbers -> [..., dim]: sin of dim/2 geometric frequencies, then cos.

    Takes raw integers (timesteps 0..999, token indices) without rescaling, as the
    authors' ``SinusoidalPosEmb`` does.
    """

    def __init__(self, dim: int, theta: float = 10000.0):
        super().__init__()
        assert dim % 2 == 0 and dim >= 4, f"embedding dim {dim} must be even and >= 4"
        half = dim // 2
        freqs = torch.exp(torch.arange(half, dtype=torch.float32) * (-math.log(theta) / (half - 1)))
        self.register_buffer("freqs", freqs, persistent=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        arg = x.to(torch.float32)[..., None] * self.freqs
        return torch.cat((arg.sin(), arg.cos()), dim=-1)


class EncoderBlock(nn.Module):
    """Post-LN self-attention block: h = LN(h + MHA(h)); h = LN(h + FF(h)). h: [B, T, width]."""

    def __init__(self, width: int, heads: int, ff: int):
        super().__init__()
        assert width % heads == 0, f"width {width} is not divisible by heads {heads}"
        self.heads = heads
        self.qkv = nn.Linear(width, 3 * width)
        self.proj = nn.Linear(width, width)
        self.norm1 = nn.LayerNorm(width)
        self.ff1 = nn.Linear(width, ff)
        self.ff2 = nn.Linear(ff, width)
        self.norm2 = nn.LayerNorm(width)
        # nn.MultiheadAttention's initialisation.
        nn.init.xavier_uniform_(self.qkv.weight)
        nn.init.zeros_(self.qkv.bias)
        nn.init.zeros_(self.proj.bias)

    def forward(self, h: torch.Tensor) -> torch.Tensor:
        b, t, w = h.shape
        q, k, v = self.qkv(h).view(b, t, 3, self.heads, w // self.heads).permute(2, 0, 3, 1, 4)
        a = F.scaled_dot_product_attention(q, k, v)  # [B, heads, T, w/heads], bidirectional
        h = self.norm1(h + self.proj(a.transpose(1, 2).reshape(b, t, w)))
        return self.norm2(h + self.ff2(F.relu(self.ff1(h))))


class DFTransformer(nn.Module):
    """x0-predictor f(x_t, t) -> x0_hat for token sequences with per-token timesteps.

    x: [B, T, D] float (D = 2 * frame_stack), t: [B, T] long in [0, timesteps) -> [B, T, D].
    """

    def __init__(self, token_dim: int, n_tokens: int, width: int = 128, layers: int = 12,
                 heads: int = 4, ff: int = 512, kind: str = "df"):
        super().__init__()
        self.kind = kind
        self.token_dim = token_dim
        self.n_tokens = n_tokens  # the sequence length it is trained for (recorded in manifests)
        self.t_embed = SinusoidalEmbedding(width // 2)
        self.pos_embed = SinusoidalEmbedding(width)
        self.init_mlp = nn.Sequential(
            nn.Linear(token_dim + width // 2, width), nn.ReLU(), nn.Linear(width, width)
        )
        self.blocks = nn.ModuleList(EncoderBlock(width, heads, ff) for _ in range(layers))
        self.out = nn.Linear(width, token_dim)

    @classmethod
    def from_config(cls, model_cfg: ModelConfig, n_tokens: int) -> "DFTransformer":
        """Build from ``cfg.model``; the paper size is the ModelConfig default (12 x 128, 4 heads, FF 512)."""
        if model_cfg.kind not in MODEL_KINDS:
            raise unknown_name("model.kind", model_cfg.kind, MODEL_KINDS)
        return cls(2 * model_cfg.frame_stack, n_tokens, model_cfg.width, model_cfg.layers,
                   model_cfg.heads, model_cfg.ff, model_cfg.kind)

    def forward(self, x: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        assert x.ndim == 3 and x.shape[-1] == self.token_dim and t.shape == x.shape[:2], (
            f"x {tuple(x.shape)} / t {tuple(t.shape)}: expected [B, T, {self.token_dim}] / [B, T]"
        )
        h = self.init_mlp(torch.cat((x, self.t_embed(t)), dim=-1))
        h = h + self.pos_embed(torch.arange(x.shape[1], device=x.device))
        for block in self.blocks:
            h = block(h)
        return self.out(h)

    def num_params(self) -> int:
        return sum(p.numel() for p in self.parameters())
