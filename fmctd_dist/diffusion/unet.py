"""Diffuser's temporal U-Net (Janner et al. 2022): one noise level for a whole trajectory.

Architecture of the authors' ``TemporalUnet`` (diffuser/models/temporal.py, no attention):
residual blocks of two Conv1d(kernel 5) -> GroupNorm(8) -> Mish layers with the time
embedding added after the first, a sinusoidal -> Linear -> Mish -> Linear time MLP, two
blocks per resolution, stride-2 conv down-sampling and transposed-conv up-sampling with
skip connections, and a final conv block + 1x1 conv to the state dimension.

Channel widths are ``model.unet_channels`` (paper table: (32, 128, 256), i.e. Janner's
dim=32, dim_mults=(1, 4, 8)). The table's "depth 4" is the length of Janner's ``dims``
list [state_dim, 32, 128, 256]: 3 resolution levels, so the time axis is halved twice
(factor 4). The time axis is replicate-padded at the end to a multiple of that factor and
the output cropped, so any trajectory length (501, 1001 tokens) works.

``edge_frames`` > 0 (not in Janner's net) first extends the sequence at both ends by point
reflections about its end frames, x_{-i} = 2 x_0 - x_i, a straight continuation of the path, and
crops them again: the sequence edges, where this U-Net's convs and strided resampling are least
accurate, then fall on frames that are thrown away (docs/results.md section 3.1).

It has DFTransformer's call signature, ``forward(x [B, T, D], t [B, T]) -> x0_hat``, so the
per-token sampler runs it unchanged. Plan tokens share one level per row in the Diffuser
planner, so the network reads the timestep of the last token, ``t[:, -1]``; token 0 (the
start, level 0) is inpainted by the sampler, never overwritten.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from fmctd_dist.diffusion.model import SinusoidalEmbedding

GROUPS = 8  # GroupNorm groups (Janner's n_groups)


class ConvBlock(nn.Module):
    """Conv1d (same length) -> GroupNorm -> Mish. [B, C_in, T] -> [B, C_out, T]."""

    def __init__(self, c_in: int, c_out: int, kernel: int, padding: str = "zeros"):
        super().__init__()
        self.conv = nn.Conv1d(c_in, c_out, kernel, padding=kernel // 2, padding_mode=padding)
        self.norm = nn.GroupNorm(GROUPS, c_out)

    def forward(self, h: torch.Tensor) -> torch.Tensor:
        return F.mish(self.norm(self.conv(h)))


class ResidualTemporalBlock(nn.Module):
    """Two conv blocks, time embedding added after the first, 1x1-conv residual. h: [B, C, T], e: [B, E]."""

    def __init__(self, c_in: int, c_out: int, embed_dim: int, kernel: int, padding: str = "zeros"):
        super().__init__()
        self.block1 = ConvBlock(c_in, c_out, kernel, padding)
        self.block2 = ConvBlock(c_out, c_out, kernel, padding)
        self.time = nn.Sequential(nn.Mish(), nn.Linear(embed_dim, c_out))
        self.residual = nn.Conv1d(c_in, c_out, 1) if c_in != c_out else nn.Identity()

    def forward(self, h: torch.Tensor, e: torch.Tensor) -> torch.Tensor:
        out = self.block1(h) + self.time(e)[..., None]
        return self.block2(out) + self.residual(h)


class TemporalUnet(nn.Module):
    """x0-predictor f(x_t, t) -> x0_hat with one timestep per sequence.

    x: [B, T, D] float, t: [B, T] long (only t[:, -1] is read) -> [B, T, D].
    """

    def __init__(self, token_dim: int, n_tokens: int, channels: tuple[int, ...] | list[int] = (32, 128, 256),
                 kernel: int = 5, kind: str = "diffuser", padding: str = "zeros", edge_frames: int = 0):
        super().__init__()
        self.edge_frames = int(edge_frames)
        channels = [int(c) for c in channels]
        assert channels and all(c % GROUPS == 0 for c in channels), f"channels {channels}: multiples of {GROUPS}"
        self.kind = kind
        self.token_dim = token_dim
        self.n_tokens = n_tokens  # the sequence length it is trained for (recorded in manifests)
        self.channels = channels
        self.factor = 2 ** (len(channels) - 1)  # time-axis down-sampling factor
        dim = channels[0]
        self.time_mlp = nn.Sequential(SinusoidalEmbedding(dim), nn.Linear(dim, 4 * dim), nn.Mish(),
                                      nn.Linear(4 * dim, dim))
        dims = [token_dim, *channels]
        pairs = list(zip(dims[:-1], dims[1:]))  # [(D, 32), (32, 128), (128, 256)]
        self.downs = nn.ModuleList()
        for i, (c_in, c_out) in enumerate(pairs):
            last = i == len(pairs) - 1
            self.downs.append(nn.ModuleList([
                ResidualTemporalBlock(c_in, c_out, dim, kernel, padding),
                ResidualTemporalBlock(c_out, c_out, dim, kernel, padding),
                nn.Identity() if last else nn.Conv1d(c_out, c_out, 3, stride=2, padding=1, padding_mode=padding),
            ]))
        self.mid1 = ResidualTemporalBlock(channels[-1], channels[-1], dim, kernel, padding)
        self.mid2 = ResidualTemporalBlock(channels[-1], channels[-1], dim, kernel, padding)
        self.ups = nn.ModuleList()
        for c_in, c_out in reversed(pairs[1:]):
            self.ups.append(nn.ModuleList([
                ResidualTemporalBlock(2 * c_out, c_in, dim, kernel, padding),
                ResidualTemporalBlock(c_in, c_in, dim, kernel, padding),
                nn.ConvTranspose1d(c_in, c_in, 4, stride=2, padding=1),
            ]))
        self.final = nn.Sequential(ConvBlock(dim, dim, kernel, padding), nn.Conv1d(dim, token_dim, 1))

    def forward(self, x: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        assert x.ndim == 3 and x.shape[-1] == self.token_dim and t.shape == x.shape[:2], (
            f"x {tuple(x.shape)} / t {tuple(t.shape)}: expected [B, T, {self.token_dim}] / [B, T]"
        )
        length = x.shape[1]
        edge = min(self.edge_frames, length - 1)
        if edge:
            x = torch.cat((2 * x[:, :1] - x[:, 1:edge + 1].flip(1), x, 2 * x[:, -1:] - x[:, -edge - 1:-1].flip(1)), 1)
        pad = -x.shape[1] % self.factor
        h = x.transpose(1, 2)  # [B, D, T]
        if pad:
            h = F.pad(h, (0, pad), mode="replicate")
        e = self.time_mlp(t[:, -1])  # [B, dim]
        skips = []
        for block1, block2, down in self.downs:
            h = block2(block1(h, e), e)
            skips.append(h)
            h = down(h)
        h = self.mid2(self.mid1(h, e), e)
        for block1, block2, up in self.ups:
            h = torch.cat((h, skips.pop()), dim=1)
            h = up(block2(block1(h, e), e))
        return self.final(h)[..., edge:edge + length].transpose(1, 2)

    def num_params(self) -> int:
        return sum(p.numel() for p in self.parameters())
