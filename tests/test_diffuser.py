"""Diffuser baseline: temporal U-Net, cosine betas, Diffuser loss, planner, train job, checkpoint checks."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest
import torch

from conftest import TINY_DATA
from fmctd_dist.config import REPO_ROOT, ModelConfig, load_config
from fmctd_dist.families import plan_rules
from fmctd_dist.families.maze.data import load_dataset
from fmctd_dist.data.windows import train_data
from fmctd_dist.denoiser.local import LocalDenoiser
from fmctd_dist.denoiser.protocol import DenoiseBatch
from fmctd_dist.diffusion.checkpoint import load_checkpoint, normaliser_from_manifest
from fmctd_dist.resume import load_train_state
from fmctd_dist.diffusion.models import build_model
from fmctd_dist.diffusion.sampler import make_consts
from fmctd_dist.diffusion.schedule import alphas_cumprod, cosine_betas, linear_betas, make_betas
from fmctd_dist.diffusion.train import DiffuserLoss, train
from fmctd_dist.diffusion.unet import TemporalUnet
from fmctd_dist.errors import CheckpointError, ConfigError
from fmctd_dist.planners import make_planner
from fmctd_dist.planners.fixed import FixedSchedulePlanner, uniform_levels

pytestmark = pytest.mark.usefixtures("one_torch_thread")

TINY_UNET = ["model.unet_channels=[8,16]", "diffusion.levels=4", "env.max_steps=100"]
GOAL = np.array([20.0, 20.0])



def tiny_unet(n_tokens: int = 11) -> TemporalUnet:
    torch.manual_seed(0)
    return build_model(ModelConfig(kind="diffuser", frame_stack=1, unet_channels=[8, 16, 16]), n_tokens).eval()


@pytest.fixture(scope="module")
def diffuser_checkpoint(tiny_dataset, tmp_path_factory):
    """A tiny U-Net trained 4 steps by `jobs/train.py model.kind=diffuser` (the smoke run) on the tiny dataset."""
    data_cfg, _ = tiny_dataset
    out = tmp_path_factory.mktemp("diffuser")
    args = TINY_DATA + TINY_UNET + [f"data.root={data_cfg.data.root}"]
    cmd = [sys.executable, "jobs/train.py", *args, "model.kind=diffuser", f"train.out={out}", "train.max_steps=4",
           "train.batch_size=4", "train.ckpt_every=2", "train.val_every=2", "train.val_batches=1", "train.threads=1"]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.run(cmd, cwd=REPO_ROOT, capture_output=True, text=True, timeout=600, env=env)
    assert proc.returncode == 0, proc.stderr
    return args + ["method=diffuser", f"checkpoint={out}"], out, proc


def denoiser_and_cfg(diffuser_checkpoint, *extra):
    args, ckpt, _ = diffuser_checkpoint
    cfg = load_config(args + list(extra))
    model, manifest = load_checkpoint(ckpt, cfg)
    return LocalDenoiser(model, cfg.diffusion, "cpu", micro_batch=cfg.ray.micro_batch), cfg, manifest


# ---- exact: schedule, shapes, levels ----

def test_cosine_betas_match_nichol_dhariwal():
    b = cosine_betas(100)
    t = np.arange(101) / 100
    f = np.cos((t + 0.008) / 1.008 * np.pi / 2) ** 2
    ab = f / f[0]
    assert b.shape == (100,) and b.dtype == np.float64
    np.testing.assert_allclose(alphas_cumprod(b)[:-1], ab[1:-1], rtol=1e-12)
    assert b[-1] == 0.999 and (b <= 0.999).all() and (np.diff(b) > 0).all()
    assert np.array_equal(make_betas("linear", 1000, 1e-4, 0.02), linear_betas(1000, 1e-4, 0.02))
    with pytest.raises(ValueError, match="cosine"):
        make_betas("quadratic", 10)


def test_diffuser_config_and_paper_size():
    for env, n in (("pointmaze-medium", 501), ("pointmaze-large", 501), ("pointmaze-giant", 1001)):
        cfg = load_config([f"env={env}", "method=diffuser"])
        assert cfg.n_tokens == n and cfg.token_dim == 2 and cfg.jump == 1
        assert cfg.checkpoint_dir().name == f"{env}-diffuser"
        assert cfg.diffusion.beta_schedule == "cosine" and cfg.method.guidance_scale == 0.1
        assert (cfg.train.lr, cfg.train.batch_size, cfg.train.ema_decay) == (2e-4, 32, 0.995)
    assert load_config(["method=diffuser-replan"]).method.replan_every == 50
    assert load_config(["method=diffuser"]).method.replan_every == 0
    assert load_config(["method=diffusion-forcing"]).checkpoint_dir().name == "pointmaze-medium-h1"
    model = build_model(load_config(["method=diffuser", "model.unet_channels=[32,128,256]"]).model, 501)
    assert isinstance(model, TemporalUnet) and model.channels == [32, 128, 256] and model.factor == 4
    assert 3_000_000 < model.num_params() < 4_500_000  # Janner's maze2d U-Net (dim 32, mults 1-4-8): ~3.7M
    shipped = build_model(load_config(["method=diffuser"]).model, 501)  # the width traded for steps on CPU
    assert shipped.channels == [32, 64, 128] and 900_000 < shipped.num_params() < 1_100_000


def test_unet_output_shape_any_length():
    model = tiny_unet()
    for n in (501, 501, 1001, 101, 7, 2, 1):
        x = torch.randn(2, n, 2)
        t = torch.randint(0, 100, (2, n))
        assert model(x, t).shape == (2, n, 2), n


def test_unet_reads_one_timestep_per_row():
    model = tiny_unet()
    x = torch.randn(2, 11, 2)
    t = torch.full((2, 11), 40)
    t2 = t.clone()
    t2[:, :-1] = 3  # only the last (plan) token's timestep is read
    with torch.no_grad():
        assert torch.equal(model(x, t), model(x, t2))
        assert not torch.equal(model(x, t), model(x, t + 1))


def test_uniform_levels():
    lv = uniform_levels(3, 4)
    assert lv.tolist() == [[0, 4, 4, 4], [0, 3, 3, 3], [0, 2, 2, 2], [0, 1, 1, 1], [0, 0, 0, 0]]
    assert np.array_equal(uniform_levels(3, 4, resample=1), lv)


def test_uniform_levels_with_resampling():
    """RePaint U=3 over 4 levels: each level above 0 is reached 3 times, by 3 + 2 x 2 ... model calls."""
    lv = uniform_levels(2, 4, resample=3)
    assert lv[:, 1].tolist() == [4, 3, 4, 3, 4, 3, 2, 3, 2, 3, 2, 1, 2, 1, 2, 1, 0]
    assert (lv[:, 0] == 0).all() and (lv[:, 1:] == lv[:, 1:2]).all()
    steps = np.diff(lv[:, 1])
    assert set(steps.tolist()) == {-1, 1}
    assert (steps < 0).sum() == 4 + 2 * 3  # U-Net calls: L + (U - 1)(L - 1)


def test_diffuser_loss_uniform_timestep_and_clean_start():
    cfg = load_config(["method=diffuser", "env.horizon=100", "data.train_window=100", "env.max_steps=100"])

    class Recorder(torch.nn.Module):
        def forward(self, x, t):
            self.x, self.t = x, t
            return torch.where(torch.arange(x.shape[1])[None, :, None] == 0, 1e6, x)  # garbage at token 0

    loss_fn, rec = DiffuserLoss(cfg, torch.device("cpu")), Recorder()
    x0 = torch.randn(4, 101, 2)
    loss = loss_fn(rec, x0, torch.Generator().manual_seed(0))
    assert float(loss) < 1e3  # token 0 is not in the loss
    assert (rec.t[:, 0] == cfg.diffusion.stabilization - 1).all()
    assert (rec.t[:, 1:] == rec.t[:, 1:2]).all()  # one timestep per sample
    c = make_consts(cfg.diffusion)
    assert torch.equal(rec.x[:, 0], c.sqrt_ab_in[0] * x0[:, 0])  # fed exactly as the sampler feeds level 0


def test_diffuser_loss_discount_weights_early_frames():
    base = ["method=diffuser", "env.horizon=100", "data.train_window=100", "env.max_steps=100"]
    flat = DiffuserLoss(load_config(base), torch.device("cpu"))
    disc = DiffuserLoss(load_config(base + ["train.loss_discount=0.9"]), torch.device("cpu"))
    w = disc.frame_weights(100, torch.device("cpu"))
    assert abs(float(w.mean()) - 1.0) < 1e-5 and bool((w[1:] < w[:-1]).all())
    assert torch.equal(flat.frame_weights(100, torch.device("cpu")), torch.ones(100))

    class ErrAt(torch.nn.Module):  # x0 error only at one plan frame
        def __init__(self, frame):
            super().__init__()
            self.frame = frame

        def forward(self, x, t):
            out = torch.zeros_like(x)
            out[:, self.frame] = 1.0
            return out

    x0 = torch.zeros(2, 101, 2)
    gen = lambda: torch.Generator().manual_seed(0)  # noqa: E731
    assert float(flat(ErrAt(1), x0, gen())) == pytest.approx(float(flat(ErrAt(90), x0, gen())))
    assert float(disc(ErrAt(1), x0, gen())) > 100 * float(disc(ErrAt(90), x0, gen()))
    with pytest.raises(ConfigError, match="train.loss_discount"):
        load_config(base + ["train.loss_discount=0"])


# ---- training: train() + resume, and the job as a subprocess ----

def test_tiny_diffuser_trains_and_resumes(tiny_dataset, tmp_path):
    data_cfg, _ = tiny_dataset
    base = TINY_DATA + TINY_UNET + [f"data.root={data_cfg.data.root}", "method=diffuser", "train.batch_size=4",
                                    "train.ckpt_every=2", "train.val_every=2", "train.val_batches=1"]
    cfg = lambda steps: load_config(base + [f"train.max_steps={steps}"])  # noqa: E731
    data = train_data(cfg(4), load_dataset(cfg(4)))
    straight = train(cfg(4), data, tmp_path / "straight", progress=False)
    train(cfg(2), data, tmp_path / "killed", progress=False)
    resumed = train(cfg(4), data, tmp_path / "killed", progress=False)
    assert straight["step"] == 4 and resumed["resumed_from"] == 2 and np.isfinite(resumed["final_losses"]["train"])
    a, b = load_train_state(tmp_path / "straight"), load_train_state(tmp_path / "killed")
    for k in a["model"]:
        assert torch.equal(a["model"][k], b["model"][k]), k
    model, manifest = load_checkpoint(tmp_path / "killed", cfg(4))
    assert isinstance(model, TemporalUnet) and manifest["model_kind"] == "diffuser" and manifest["n_tokens"] == 101
    with pytest.raises(CheckpointError, match="model.unet_channels"):
        other = [w for w in base if not w.startswith("model.unet_channels=")]  # a key may be given once
        train(load_config(other + ["train.max_steps=6", "model.unet_channels=[8,24]"]), data, tmp_path / "killed",
              progress=False)


def test_train_job_smoke(diffuser_checkpoint):
    _, ckpt, proc = diffuser_checkpoint
    assert "step 4" in proc.stdout
    manifest = json.loads((ckpt / "manifest.json").read_text())
    assert manifest["model_kind"] == "diffuser" and manifest["train_steps"] == 4
    assert manifest["config"]["method"]["name"] == "diffuser"  # model.kind=diffuser picks method=diffuser
    assert manifest["config"]["diffusion"]["beta_schedule"] == "cosine"
    assert manifest["n_tokens"] == 101 and manifest["token_dim"] == 2


# ---- contract: inpainting, guidance, determinism ----

def test_inpainting_keeps_the_start_exactly(diffuser_checkpoint):
    den, cfg, manifest = denoiser_and_cfg(diffuser_checkpoint)
    norm = normaliser_from_manifest(manifest)
    rng = np.random.default_rng(0)
    start = norm.normalise(np.array([[3.3, 7.1], [10.0, 2.5]]))
    x = np.concatenate([start[:, None], rng.standard_normal((2, cfg.plan_tokens, 2))], axis=1).astype(np.float32)
    lv = np.repeat(uniform_levels(cfg.plan_tokens, cfg.diffusion.levels)[None], 2, axis=0)
    goal = norm.normalise(GOAL[None]).repeat(2, 0)
    out = den.denoise(DenoiseBatch(x, lv, np.array([0.1, 0.0], np.float32), start, goal))
    assert np.array_equal(out.x[:, 0], x[:, 0])
    assert not np.array_equal(out.x[:, 1:], x[:, 1:]) and np.isfinite(out.x).all()


def test_guidance_scale_zero_equals_unguided(diffuser_checkpoint):
    den, cfg, manifest = denoiser_and_cfg(diffuser_checkpoint, "ray.micro_batch=2")
    norm = normaliser_from_manifest(manifest)
    rng = np.random.default_rng(1)
    x = rng.standard_normal((2, cfg.n_tokens, 2)).astype(np.float32)
    lv = np.repeat(uniform_levels(cfg.plan_tokens, cfg.diffusion.levels)[None], 2, axis=0)
    start, goal = x[:, 0].copy(), norm.normalise(GOAL[None]).repeat(2, 0)
    mixed = den.denoise(DenoiseBatch(x, lv, np.array([0.0, 0.1], np.float32), start, goal))  # grad path
    alone = den.denoise(DenoiseBatch(x[:1], lv[:1], np.array([0.0], np.float32), start[:1], goal[:1]))  # no_grad
    assert np.array_equal(mixed.x[0], alone.x[0]) and np.array_equal(mixed.x0[0], alone.x0[0])
    guided = den.denoise(DenoiseBatch(x[:1], lv[:1], np.array([0.1], np.float32), start[:1], goal[:1]))
    assert not np.array_equal(guided.x, alone.x)


def test_planner_is_deterministic_per_seed(diffuser_checkpoint):
    den, cfg, manifest = denoiser_and_cfg(diffuser_checkpoint)
    planner = make_planner(cfg, den, normaliser_from_manifest(manifest), plan_rules(cfg))
    assert isinstance(planner, FixedSchedulePlanner)
    assert np.array_equal(planner.levels, uniform_levels(cfg.plan_tokens, cfg.diffusion.levels, cfg.method.resample))
    a = planner.plan(np.array([1.0, 1.0]), GOAL, seed=3)
    b = planner.plan(np.array([1.0, 1.0]), GOAL, seed=3)
    c = planner.plan(np.array([1.0, 1.0]), GOAL, seed=4)
    assert a.waypoints.shape == (100, 2) and np.array_equal(a.waypoints, b.waypoints)
    assert not np.array_equal(a.waypoints, c.waypoints)
    assert a.denoise_calls == 1 and 0 < a.denoise_time_s <= a.plan_time_s
    unguided_cfg = load_config(diffuser_checkpoint[0] + ["method.guidance_scale=0"])
    unguided = make_planner(unguided_cfg, den, normaliser_from_manifest(manifest),
                            plan_rules(unguided_cfg)).plan(np.array([1.0, 1.0]), GOAL, seed=3)
    assert not np.array_equal(a.waypoints, unguided.waypoints)


def test_resampling_planner_is_deterministic_per_seed_and_costs_its_extra_calls(diffuser_checkpoint):
    den, cfg, manifest = denoiser_and_cfg(diffuser_checkpoint, "method.resample=3")
    planner = make_planner(cfg, den, normaliser_from_manifest(manifest), plan_rules(cfg))
    start = np.array([1.0, 1.0])
    a, b, c = (planner.plan(start, GOAL, seed=s) for s in (3, 3, 4))
    assert np.array_equal(a.waypoints, b.waypoints) and not np.array_equal(a.waypoints, c.waypoints)
    plain_cfg = load_config(diffuser_checkpoint[0])
    plain = make_planner(plain_cfg, den, normaliser_from_manifest(manifest), plan_rules(plain_cfg))
    assert not np.array_equal(a.waypoints, plain.plan(start, GOAL, seed=3).waypoints)
    # the resampled schedule costs L + (U - 1)(L - 1) U-Net calls, and re-noising needs the job's seed
    x = np.random.default_rng(0).standard_normal((1, cfg.n_tokens, 2)).astype(np.float32)
    lv = uniform_levels(cfg.plan_tokens, cfg.diffusion.levels, resample=3)[None]
    start, goal = x[:, 0].copy(), np.zeros((1, 2), np.float32)
    res = den.denoise(DenoiseBatch(x, lv, np.array([0.1], np.float32), start, goal, np.array([7])))
    assert res.stats["model_calls"] == cfg.diffusion.levels + 2 * (cfg.diffusion.levels - 1)
    with pytest.raises(ValueError, match="noise_seed"):
        den.denoise(DenoiseBatch(x, lv, np.array([0.1], np.float32), start, goal))


# ---- bad input ----

def test_df_checkpoint_with_diffuser_method_names_model_kind(tiny_checkpoint):
    args, ckpt = tiny_checkpoint
    cfg = load_config(args + ["method=diffuser"])
    with pytest.raises(CheckpointError, match="model.kind='df'.*model.kind='diffuser'"):
        load_checkpoint(ckpt, cfg)


def test_bad_diffuser_configs():
    with pytest.raises(ConfigError, match="method=diffuser"):
        load_config(["model.kind=diffuser", "method=mctd"])
    with pytest.raises(ConfigError, match="diffuser"):
        load_config(["model.kind=difuser"])
    with pytest.raises(ConfigError, match="cosine"):
        load_config(["diffusion.beta_schedule=cosin"])
    with pytest.raises(ConfigError, match="multiples of 8"):
        load_config(["method=diffuser", "model.unet_channels=[12,24]"])
    with pytest.raises(ConfigError, match="odd"):
        load_config(["method=diffuser", "model.unet_kernel=4"])
    with pytest.raises(ConfigError, match="model.unet_padding='reflect'"):
        load_config(["method=diffuser", "model.unet_padding=reflect"])
    with pytest.raises(ConfigError, match="model.unet_edge_frames=-1"):
        load_config(["method=diffuser", "model.unet_edge_frames=-1"])
    with pytest.raises(ConfigError, match="method.resample"):
        load_config(["method=diffuser", "method.resample=0"])


def test_replicate_padding_reads_the_frames_before_the_start_as_the_start():
    """A trajectory resting at its start: with replicate padding every conv sees the same frames at the
    edges as in the middle, with zeros padding the edges see the normalised origin."""
    torch.manual_seed(0)
    zeros = build_model(ModelConfig(kind="diffuser", frame_stack=1, unet_channels=[8, 16]), 32).eval()
    rep = build_model(ModelConfig(kind="diffuser", frame_stack=1, unet_channels=[8, 16], unet_padding="replicate"),
                      32).eval()
    rep.load_state_dict(zeros.state_dict())  # padding is not in the state_dict: same weights
    still = torch.tensor([1.5, -2.0]).expand(1, 32, 2).transpose(1, 2)  # [B, D, T], constant in time
    with torch.no_grad():
        r, z = rep.downs[0][0].block1.conv(still), zeros.downs[0][0].block1.conv(still)
    assert torch.allclose(r, r[..., 16:17].expand_as(r), atol=1e-5)  # no edge effect
    assert (z[..., 0] - z[..., 16]).abs().max() > 1e-3  # Janner's zeros: the first frame differs
    assert torch.allclose(z[..., 4:-4], r[..., 4:-4], atol=1e-5)  # identical away from the edges


def test_edge_frames_continue_the_path_straight_and_are_cropped():
    """On a straight path the reflected frames are its exact continuation, so a U-Net with
    edge_frames=p on L frames computes what the plain U-Net computes on the L + 2p-frame path, cropped."""
    torch.manual_seed(0)
    plain = build_model(ModelConfig(kind="diffuser", frame_stack=1, unet_channels=[8, 16, 16]), 28).eval()
    edged = build_model(ModelConfig(kind="diffuser", frame_stack=1, unet_channels=[8, 16, 16], unet_edge_frames=6),
                        16).eval()
    edged.load_state_dict(plain.state_dict())  # the edge frames are not in the state_dict: same weights
    line = lambda n, first=0: torch.tensor([0.3, -1.0]) + 0.1 * torch.arange(  # noqa: E731
        first, first + n, dtype=torch.float32)[:, None] * torch.tensor([1.0, 0.5])
    t = lambda n: torch.full((1, n), 30)  # noqa: E731
    with torch.no_grad():
        out = edged(line(16)[None], t(16))
        ref = plain(line(28, first=-6)[None], t(28))[:, 6:22]
        assert out.shape == (1, 16, 2) and torch.allclose(out, ref, atol=1e-5)
        assert not torch.allclose(plain(line(16)[None], t(16)), ref, atol=1e-3)  # without them the edges differ


def test_old_manifests_without_unet_padding_load_as_zeros_and_a_mismatch_is_named(diffuser_checkpoint):
    args, ckpt, _ = diffuser_checkpoint
    manifest = json.loads((ckpt / "manifest.json").read_text())
    assert manifest["config"]["model"]["unet_padding"] == "zeros"
    del manifest["config"]["model"]["unet_padding"]  # as written before the field existed
    del manifest["config"]["model"]["unet_edge_frames"]
    (ckpt / "manifest.json").write_text(json.dumps(manifest))
    janner = args + ["model.unet_edge_frames=0"]  # what an old manifest means (the Diffuser config now says 16)
    load_checkpoint(ckpt, load_config(janner))
    with pytest.raises(CheckpointError, match="unet_edge_frames=0 but the config has model.unet_edge_frames=16"):
        load_checkpoint(ckpt, load_config(args))
    with pytest.raises(CheckpointError, match="model.unet_padding=None|model.unet_padding='zeros' but the config"):
        load_checkpoint(ckpt, load_config(janner + ["model.unet_padding=replicate"]))
    with pytest.raises(CheckpointError, match="unet_edge_frames"):
        load_checkpoint(ckpt, load_config(args + ["model.unet_edge_frames=4"]))
