"""DFTransformer: shapes, paper size, embeddings, equivalence with PyTorch's post-LN layer."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from torch import nn

from fmctd_dist.config import Config, load_config, ModelConfig
from fmctd_dist.diffusion.model import DFTransformer, EncoderBlock, SinusoidalEmbedding
from fmctd_dist.errors import ConfigError


def tiny(n_tokens: int = 11) -> DFTransformer:
    torch.manual_seed(0)
    return DFTransformer.from_config(ModelConfig(width=32, layers=2, heads=2, ff=64), n_tokens)


def test_forward_shape_and_dtype():
    m = tiny()
    x, t = torch.randn(3, 11, 20), torch.randint(0, 1000, (3, 11))
    y = m(x, t)
    assert y.shape == (3, 11, 20) and y.dtype == torch.float32


def test_paper_size_parameter_count():
    cfg = load_config(["model.layers=12", "jump=1"])  # the paper's size is one override away
    m = DFTransformer.from_config(cfg.model, cfg.n_tokens)
    w, ff, d = 128, 512, 20
    per_layer = (w * 3 * w + 3 * w) + (w * w + w) + 2 * 2 * w + (w * ff + ff) + (ff * w + w)
    expected = (d + w // 2) * w + w + w * w + w + 12 * per_layer + w * d + d
    assert m.num_params() == expected == 2_409_236  # docs/reference.md §5: ~2.4M
    assert len(m.blocks) == 12 and m.blocks[0].heads == 4 and m.token_dim == 20 and m.n_tokens == 51


def test_unknown_kind_is_config_error():
    with pytest.raises(ConfigError, match="model.kind"):
        DFTransformer.from_config(ModelConfig(kind="unet"), 11)


def test_sinusoidal_embedding_takes_raw_integers():
    emb = SinusoidalEmbedding(8)
    t = torch.tensor([0, 9, 999])
    half = 4
    freqs = np.exp(-math.log(10000.0) * np.arange(half) / (half - 1))
    arg = t.numpy()[:, None] * freqs
    expected = np.concatenate([np.sin(arg), np.cos(arg)], axis=1)
    np.testing.assert_allclose(emb(t).numpy(), expected, rtol=1e-5, atol=1e-4)
    assert emb(torch.tensor([998])).sub(emb(torch.tensor([999]))).abs().max() > 1e-3  # not rescaled to [0,1]


def test_block_matches_torch_post_ln_layer():
    torch.manual_seed(1)
    ref = nn.TransformerEncoderLayer(32, 2, 64, dropout=0.0, batch_first=True)
    blk = EncoderBlock(32, 2, 64)
    with torch.no_grad():
        blk.qkv.weight.copy_(ref.self_attn.in_proj_weight)
        blk.qkv.bias.copy_(ref.self_attn.in_proj_bias)
        blk.proj.weight.copy_(ref.self_attn.out_proj.weight)
        blk.proj.bias.copy_(ref.self_attn.out_proj.bias)
        for a, b in [(blk.ff1, ref.linear1), (blk.ff2, ref.linear2), (blk.norm1, ref.norm1), (blk.norm2, ref.norm2)]:
            a.weight.copy_(b.weight)
            a.bias.copy_(b.bias)
    h = torch.randn(4, 11, 32)
    np.testing.assert_allclose(blk(h).detach().numpy(), ref(h).detach().numpy(), rtol=1e-5, atol=1e-5)


def test_non_causal_and_per_token_timesteps():
    m = tiny().eval()
    x, t = torch.randn(1, 11, 20), torch.full((1, 11), 500)
    with torch.no_grad():
        y = m(x, t)
        x2 = x.clone()
        x2[0, -1] += 1.0
        assert not torch.allclose(m(x2, t)[0, 0], y[0, 0])  # last token is seen by the first
        t2 = t.clone()
        t2[0, 3] = 19
        assert not torch.allclose(m(x, t2)[0, 3], y[0, 3])


def test_grad_and_no_grad_forward_are_bitwise_equal():
    """Guidance runs the model under autograd; an unguided job must get the same bits."""
    m = tiny().eval()
    m.requires_grad_(False)
    x, t = torch.randn(4, 11, 20), torch.randint(0, 1000, (4, 11))
    with torch.no_grad():
        a = m(x, t)
    with torch.enable_grad():
        b = m(x.clone().requires_grad_(True), t)
    assert torch.equal(a, b.detach())
