"""The Diffusion Forcing transformer: a non-causal denoiser with one noise level per token.

Every token carries its own diffusion timestep, which is what lets the pyramid schedule keep
later tokens noisier than earlier ones (and lets MCTD cut that schedule into tree segments).
Architecture as in the authors' release (docs/reference.md §5): token ++ sinusoidal timestep
embedding -> MLP -> + sinusoidal position embedding -> post-LN transformer encoder -> x0.

Two recipe levers (issue 17) change the network, never its interface ``(x_t, t) -> x0_hat``,
so the loss, the sampler and the denoisers need no branch: ``norm`` (post-LN blocks, the
paper's, or pre-LN with a final LayerNorm) and ``param``, what the output F means:

- ``x0`` (paper): x0_hat = F. Smooth frames, but each token's offset is the network's guess.
- ``v``: x0_hat = sqrt(ab_t) x_t - sqrt(1 - ab_t) F (v-prediction written as x0). The skip path
  carries each number of the noisy input, so offsets are as good as the input, frames jitter.
- ``v_offset``: each token's frame mean (per coordinate) as in ``v``, its shape (frames minus
  their mean) as in ``x0``: the offset through the skip path, the shape from the network.

The encoder blocks are written out (same math and parameter count as
``nn.TransformerEncoderLayer(norm_first=False, activation=relu, dropout=0)``) instead of
using ``nn.TransformerEncoder``: PyTorch's inference fast path runs a fused kernel under
``no_grad`` whose bits differ (~1e-6) from the autograd path, and the sampler needs an
unguided job to give the same bits whether or not its micro-batch computes guidance.
"""

from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from fmctd_dist.config import DiffusionConfig, ModelConfig
from fmctd_dist.diffusion.schedule import alphas_cumprod, make_betas
from fmctd_dist.errors import unknown_name

MODEL_KINDS = ("df",)
MODEL_PARAMS = ("x0", "v", "v_offset")
MODEL_NORMS = ("post", "pre")
FRAME_DIM = 2  # the mazes' numbers per frame (x, y); a token is frame_stack frames of frame_dim numbers


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
    """Self-attention block, h: [B, T, width].

    Post-LN (paper): h = LN(h + MHA(h)); h = LN(h + FF(h)). Pre-LN: h = h + MHA(LN(h));
    h = h + FF(LN(h)) (same parameters; the residual stream is never normalised).
    """

    def __init__(self, width: int, heads: int, ff: int, norm_first: bool = False):
        super().__init__()
        assert width % heads == 0, f"width {width} is not divisible by heads {heads}"
        self.heads = heads
        self.norm_first = norm_first
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

    def attend(self, h: torch.Tensor) -> torch.Tensor:
        b, t, w = h.shape
        q, k, v = self.qkv(h).view(b, t, 3, self.heads, w // self.heads).permute(2, 0, 3, 1, 4)
        a = F.scaled_dot_product_attention(q, k, v)  # [B, heads, T, w/heads], bidirectional
        return self.proj(a.transpose(1, 2).reshape(b, t, w))

    def forward(self, h: torch.Tensor) -> torch.Tensor:
        if self.norm_first:
            h = h + self.attend(self.norm1(h))
            return h + self.ff2(F.relu(self.ff1(self.norm2(h))))
        h = self.norm1(h + self.attend(h))
        return self.norm2(h + self.ff2(F.relu(self.ff1(h))))


class DFTransformer(nn.Module):
    """x0-predictor f(x_t, t) -> x0_hat for token sequences with per-token timesteps.

    x: [B, T, D] float (D = frame_dim * frame_stack: the env family's planner state per frame, 2 for
    a maze's x, y, 3 per cube), t: [B, T] long in [0, timesteps) -> [B, T, D].
    ``alphas_cumprod`` [timesteps] (the training schedule) is needed by param v / v_offset only;
    it is a non-persistent buffer, so state_dicts are the same for every ``param``.
    """

    def __init__(self, token_dim: int, n_tokens: int, width: int = 128, layers: int = 12,
                 heads: int = 4, ff: int = 512, kind: str = "df", param: str = "x0", norm: str = "post",
                 alphas_cumprod: np.ndarray | None = None, frame_dim: int = FRAME_DIM):
        super().__init__()
        if param not in MODEL_PARAMS:
            raise unknown_name("model.param", param, MODEL_PARAMS)
        if norm not in MODEL_NORMS:
            raise unknown_name("model.norm", norm, MODEL_NORMS)
        assert token_dim % frame_dim == 0, f"token_dim {token_dim} is not a multiple of frame_dim {frame_dim}"
        self.kind = kind
        self.frame_dim = frame_dim  # numbers per frame: v_offset's token mean is taken per frame coordinate
        self.param, self.norm = param, norm
        self.token_dim = token_dim
        self.n_tokens = n_tokens  # the sequence length it is trained for (recorded in manifests)
        if param != "x0":
            assert alphas_cumprod is not None, f"model.param={param} needs the diffusion schedule's alphas_cumprod"
            ab = torch.as_tensor(np.asarray(alphas_cumprod, dtype=np.float64))
            self.register_buffer("sqrt_ab", ab.sqrt().float(), persistent=False)
            self.register_buffer("sqrt_1m_ab", (1.0 - ab).sqrt().float(), persistent=False)
        self.t_embed = SinusoidalEmbedding(width // 2)
        self.pos_embed = SinusoidalEmbedding(width)
        self.init_mlp = nn.Sequential(
            nn.Linear(token_dim + width // 2, width), nn.ReLU(), nn.Linear(width, width)
        )
        self.blocks = nn.ModuleList(EncoderBlock(width, heads, ff, norm == "pre") for _ in range(layers))
        self.final_norm = nn.LayerNorm(width) if norm == "pre" else nn.Identity()  # pre-LN's residual stream
        self.out = nn.Linear(width, token_dim)

    @classmethod
    def from_config(cls, model_cfg: ModelConfig, n_tokens: int,
                    diffusion_cfg: DiffusionConfig | None = None, frame_dim: int = FRAME_DIM) -> "DFTransformer":
        """Build from ``cfg.model`` (and ``cfg.diffusion``'s schedule for param v / v_offset);
        ``frame_dim`` is the env family's state size per frame (``Config.frame_dim``)."""
        if model_cfg.kind not in MODEL_KINDS:
            raise unknown_name("model.kind", model_cfg.kind, MODEL_KINDS)
        dc = diffusion_cfg or DiffusionConfig()
        ab = alphas_cumprod(make_betas(dc.beta_schedule, dc.timesteps, dc.beta_start, dc.beta_end))
        return cls(frame_dim * model_cfg.frame_stack, n_tokens, model_cfg.width, model_cfg.layers,
                   model_cfg.heads, model_cfg.ff, model_cfg.kind, model_cfg.param, model_cfg.norm, ab, frame_dim)

    def forward(self, x: torch.Tensor, t: torch.Tensor, skip_grad: bool = True) -> torch.Tensor:
        """x0_hat [B, T, D]. ``skip_grad=False`` detaches v's skip path (guidance through the network only)."""
        assert x.ndim == 3 and x.shape[-1] == self.token_dim and t.shape == x.shape[:2], (
            f"x {tuple(x.shape)} / t {tuple(t.shape)}: expected [B, T, {self.token_dim}] / [B, T]"
        )
        h = self.init_mlp(torch.cat((x, self.t_embed(t)), dim=-1))
        h = h + self.pos_embed(torch.arange(x.shape[1], device=x.device))
        for block in self.blocks:
            h = block(h)
        out = self.out(self.final_norm(h))
        if self.param == "x0":
            return out
        return self.skip(x if skip_grad else x.detach(), t) + self.branch(out, t)

    def skip(self, x: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        """The part of x0_hat that is linear in the noisy input x [B, T, D] (0 for param x0)."""
        if self.param == "x0":
            return torch.zeros_like(x)
        sx = self.sqrt_ab[t][..., None] * x
        return sx if self.param == "v" else token_offset(sx, self.frame_dim)

    def branch(self, out: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        """The network's part of x0_hat, from its raw output [B, T, D]: v's -sqrt(1-ab) F; for
        v_offset that on each token's mean frame, plus F's frames minus their mean (the shape)."""
        if self.param == "x0":
            return out
        v = -self.sqrt_1m_ab[t][..., None] * out
        return v if self.param == "v" else token_offset(v, self.frame_dim) + out - token_offset(out, self.frame_dim)

    def num_params(self) -> int:
        return sum(p.numel() for p in self.parameters())


def token_offset(z: torch.Tensor, frame_dim: int = FRAME_DIM) -> torch.Tensor:
    """[B, T, D] -> [B, T, D]: every frame of a token replaced by the token's mean frame (its offset)."""
    b, t, d = z.shape
    frames = z.reshape(b, t, d // frame_dim, frame_dim)
    return frames.mean(dim=2, keepdim=True).expand_as(frames).reshape(b, t, d)
