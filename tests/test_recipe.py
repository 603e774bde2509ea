"""Recipe levers (issue 17): each selectable and recorded, old manifests load as the paper's recipe,
guidance gradients exact under every lever, and train.time_budget_s stops and resumes."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from test_train_loop import FakeData, tiny_cfg

from fmctd_dist.config import Config, DiffusionConfig, ModelConfig, config_from_dict
from fmctd_dist.denoiser.local import LocalDenoiser
from fmctd_dist.denoiser.protocol import DenoiseBatch
from fmctd_dist.artifacts import MANIFEST_FILE, write_manifest
from fmctd_dist.diffusion.checkpoint import load_checkpoint
from fmctd_dist.diffusion.model import DFTransformer
from fmctd_dist.diffusion.sampler import GUIDANCE_GAIN, goal_reward, make_consts, transition
from fmctd_dist.diffusion.schedule import PyramidSchedule
from fmctd_dist.diffusion.train import DFLoss, boundary_loss, lr_at, position_loss, train, validation_loss, wall_loss
from fmctd_dist.errors import CheckpointError, ConfigError

pytestmark = pytest.mark.usefixtures("one_torch_thread")

# lever word -> the manifest's config path; the first three change the model, the rest training
LEVERS = {"model.param=v": ("model", "param"), "model.param=v_offset": ("model", "param"),
          "model.norm=pre": ("model", "norm"), "train.lr_schedule=cosine": ("train", "lr_schedule"),
          "train.lr_schedule=wsd": ("train", "lr_schedule"),
          "train.precision=bf16": ("train", "precision"),
          "diffusion.guidance_path=network": ("diffusion", "guidance_path"),
          "train.boundary_weight=2.0": ("train", "boundary_weight"),
          "train.clean_context=0.5": ("train", "clean_context")}
MODEL_LEVERS = ("model.param=v", "model.param=v_offset", "model.norm=pre")
RECIPE_FIELDS = {"model": ("param", "norm"), "train": ("lr_schedule", "precision", "time_budget_s", "boundary_weight",
                                                      "boundary_space", "position_weight", "clean_context",
                                                      "wall_weight"),
                 "diffusion": ("guidance_path",)}
PAPER = {"model": {"param": "x0", "norm": "post"}, "train": {"lr_schedule": "constant", "precision": "fp32",
                                                              "time_budget_s": 0.0, "boundary_weight": 0.0,
                                                              "boundary_space": "token", "position_weight": 0.0,
                                                              "clean_context": 0.0, "wall_weight": 0.0},
         "diffusion": {"guidance_path": "input"}}


def test_defaults_are_the_papers_recipe_and_bad_values_are_named():
    cfg = Config()
    for group, fields in PAPER.items():
        for name, value in fields.items():
            assert getattr(getattr(cfg, group), name) == value, f"{group}.{name}"
    with pytest.raises(ConfigError, match="model.param"):
        tiny_cfg(5, "model.param=eps")
    with pytest.raises(ConfigError, match="train.time_budget_s"):
        tiny_cfg(5, "train.time_budget_s=-1")
    with pytest.raises(ConfigError, match="model.kind=df only"):
        tiny_cfg(5, "method=diffuser", "model.kind=diffuser", "model.param=v")


@pytest.mark.parametrize("lever", list(LEVERS))
def test_lever_is_selectable_and_recorded_in_the_manifest(tmp_path, lever):
    cfg = tiny_cfg(6, lever, "train.ckpt_every=6", "train.val_every=6")
    out = train(cfg, FakeData(), tmp_path, progress=False)
    assert out["step"] == 6 and np.isfinite(out["final_losses"]["train"])
    manifest = json.loads((tmp_path / MANIFEST_FILE).read_text())
    group, name = LEVERS[lever]
    assert str(manifest["config"][group][name]) == lever.split("=")[1]
    model, _ = load_checkpoint(tmp_path, cfg)
    if lever in MODEL_LEVERS:
        assert getattr(model, name) == lever.split("=")[1]
        # the same checkpoint under the paper's recipe: one CheckpointError naming the field
        with pytest.raises(CheckpointError, match=f"trained with model.{name}="):
            load_checkpoint(tmp_path, tiny_cfg(6))
    if lever != "diffusion.guidance_path=network":
        assert lever in manifest["vs_paper"]


def test_old_manifest_without_the_recipe_fields_loads_as_the_papers_recipe(tmp_path):
    cfg = tiny_cfg(4, "train.ckpt_every=4", "train.val_every=4")
    train(cfg, FakeData(), tmp_path, progress=False)
    manifest = json.loads((tmp_path / MANIFEST_FILE).read_text())
    for group, fields in RECIPE_FIELDS.items():
        for name in fields:
            del manifest["config"][group][name]
    write_manifest(manifest, tmp_path / MANIFEST_FILE)  # model.pt untouched: its sha still matches
    model, loaded = load_checkpoint(tmp_path, cfg)
    assert (model.param, model.norm) == ("x0", "post")
    old = config_from_dict(loaded["config"])
    for group, fields in PAPER.items():
        for name, value in fields.items():
            assert getattr(getattr(old, group), name) == value
    with pytest.raises(CheckpointError, match="trained with model.param='x0' but the config has model.param='v'"):
        load_checkpoint(tmp_path, tiny_cfg(4, "model.param=v"))


# ------------------------------------------------------------------ guidance gradients

CASES = [("x0", "post", "input"), ("x0", "post", "network"), ("v", "post", "input"), ("v", "post", "network"),
         ("v_offset", "post", "input"), ("v_offset", "post", "network"), ("x0", "pre", "input"),
         ("v", "pre", "network")]
FD_STEP = 1e-6
FD_RTOL = 1e-5  # float64 central differences: truncation ~1e-12, round-off ~1e-10


def guidance_grad_from_transition(model, consts, x, a, b, scale, start, goal, path, boundary_weight=0.0):
    """The gradient the sampler added, read back from its guided and unguided x0 estimates.

    transition: eps_g = eps - s1b grad and x0_g = (x_in - s1a eps_g) / sa, so
    grad = (x0_g - x0) sa / (s1a s1b) on every token that moves (a > b).
    """
    _, x0_g = transition(model, consts, x, a, b, scale, start, goal, path, boundary_weight=boundary_weight)
    _, x0_u = transition(model, consts, x, a, b, torch.zeros_like(scale), start, goal, path)
    sa, s1a, s1b = (getattr(consts, f)[lv].double()[..., None] for f, lv in
                    (("sqrt_ab_in", a), ("sqrt_1m_ab_in", a), ("sqrt_1m_ab_out", b)))
    return (x0_g - x0_u) * sa / (s1a * s1b)


def finite_difference_grad(model, consts, x, a, scale, start, goal, path, tokens, boundary_weight=0.0):
    """Central differences of 62.5 scale R(x0_hat(x_in)) w.r.t. the plan tokens of x_in.

    path=network holds the skip path at the unperturbed input (DFTransformer.skip).
    """
    x_in = x.clone()
    x_in[:, 0] = consts.sqrt_ab_in[0].double() * x[:, 0]  # the stabilised context, as transition feeds it
    t_in = consts.t_in[a]
    frozen = model.skip(x_in, t_in)

    def objective(z):
        x0 = model(z, t_in)
        if path == "network":
            x0 = x0 - model.skip(z, t_in) + frozen
        return GUIDANCE_GAIN * scale * goal_reward(x0, start, goal, boundary_weight=boundary_weight)  # [B]

    grad = torch.zeros_like(x)
    with torch.no_grad():
        for tok in tokens:
            for d in range(x.shape[2]):
                hi, lo = x_in.clone(), x_in.clone()
                hi[:, tok, d] += FD_STEP
                lo[:, tok, d] -= FD_STEP
                grad[:, tok, d] = (objective(hi) - objective(lo)) / (2 * FD_STEP)
    return grad


@pytest.mark.parametrize("param, norm, path", CASES)
def test_guidance_gradient_matches_finite_differences(param, norm, path):
    torch.manual_seed(0)
    model = DFTransformer.from_config(ModelConfig(width=32, layers=2, heads=2, ff=64, param=param, norm=norm),
                                      n_tokens=4).double().eval().requires_grad_(False)
    consts = make_consts(DiffusionConfig())
    rng = np.random.default_rng(0)
    x = torch.as_tensor(rng.standard_normal((2, 4, 20)))
    start, goal = torch.as_tensor(rng.standard_normal((2, 2))), torch.as_tensor(rng.standard_normal((2, 2)))
    a = torch.tensor([[0, 3, 12, 40], [0, 2, 25, 50]])  # low, middle and high noise (b > 0: s1b > 0)
    b = (a - 1).clamp(min=0)
    scale = torch.tensor([1.0, 0.5], dtype=torch.float64)
    got = guidance_grad_from_transition(model, consts, x, a, b, scale, start, goal, path)[:, 1:]
    want = finite_difference_grad(model, consts, x, a, scale, start, goal, path, range(1, 4))[:, 1:]
    assert float(want.abs().max()) > 1e-3  # the check has something to compare
    torch.testing.assert_close(got, want, rtol=FD_RTOL, atol=FD_RTOL * float(want.abs().max()))
    if param != "x0":
        other = "input" if path == "network" else "network"
        alt = guidance_grad_from_transition(model, consts, x, a, b, scale, start, goal, other)[:, 1:]
        assert not torch.allclose(alt, got)  # the two paths differ where there is a skip path


@pytest.mark.parametrize("path", ["input", "network"])
def test_boundary_guidance_gradient_matches_finite_differences(path):
    """diffusion.boundary_guidance: the sampler's gradient of goal + boundary term is the finite difference's,
    and the term changes it (v model: both guidance paths)."""
    torch.manual_seed(0)
    model = DFTransformer.from_config(ModelConfig(width=32, layers=2, heads=2, ff=64, param="v"),
                                      n_tokens=4).double().eval().requires_grad_(False)
    consts = make_consts(DiffusionConfig())
    rng = np.random.default_rng(1)
    x = torch.as_tensor(rng.standard_normal((2, 4, 20)))
    start, goal = torch.as_tensor(rng.standard_normal((2, 2))), torch.as_tensor(rng.standard_normal((2, 2)))
    a = torch.tensor([[0, 3, 12, 40], [0, 2, 25, 50]])
    b = (a - 1).clamp(min=0)
    scale = torch.tensor([1.0, 0.5], dtype=torch.float64)
    got = guidance_grad_from_transition(model, consts, x, a, b, scale, start, goal, path, 2.0)[:, 1:]
    want = finite_difference_grad(model, consts, x, a, scale, start, goal, path, range(1, 4), 2.0)[:, 1:]
    torch.testing.assert_close(got, want, rtol=FD_RTOL, atol=FD_RTOL * float(want.abs().max()))
    plain = guidance_grad_from_transition(model, consts, x, a, b, scale, start, goal, path)[:, 1:]
    assert (got - plain).abs().max() > 1e-3 * float(want.abs().max())


def test_boundary_term_is_zero_for_steady_motion_and_the_jump_for_a_jump():
    from fmctd_dist.diffusion.sampler import boundary_kink

    line = torch.arange(30, dtype=torch.float64)[None, :, None] * torch.tensor([0.3, -0.1], dtype=torch.float64)
    assert float(boundary_kink(line, 10).abs().max()) < 1e-12  # steady motion: no kink at either boundary
    jump = line.clone()
    jump[:, 20:] += torch.tensor([3.0, 4.0], dtype=torch.float64)  # a 5-unit jump into token 2
    assert float(boundary_kink(jump, 10)) == pytest.approx(5.0 / 2)  # mean over the 2 boundaries
    x0 = torch.as_tensor(np.random.default_rng(0).standard_normal((3, 3, 20)))
    start, goal = x0[:, 0, :2], x0[:, -1, -2:]
    assert torch.equal(goal_reward(x0, start, goal), goal_reward(x0, start, goal, boundary_weight=0.0))
    assert (goal_reward(x0, start, goal, boundary_weight=1.0) < goal_reward(x0, start, goal)).all()


def test_boundary_guidance_on_one_frame_tokens_is_one_clear_error():
    """A one-frame token (the Diffuser's) has no step inside it to compare the boundary step with."""
    from fmctd_dist.config import load_config
    from fmctd_dist.errors import ConfigError

    with pytest.raises(ConfigError, match="diffusion.boundary_guidance=2 .*model.frame_stack=1"):
        load_config(["method=diffuser", "env=pointmaze-medium", "diffusion.boundary_guidance=2"])
    assert load_config(["method=diffuser", "env=pointmaze-medium"]).diffusion.boundary_guidance == 0


def test_a_v_checkpoint_plans_through_the_local_denoiser(tmp_path):
    cfg = tiny_cfg(6, "model.param=v_offset", "diffusion.guidance_path=network", "train.ckpt_every=6",
                   "train.val_every=6")
    train(cfg, FakeData(), tmp_path, progress=False)
    den = LocalDenoiser.from_checkpoint(tmp_path, cfg, micro_batch=2)
    assert den.model.param == "v_offset" and den.guidance_path == "network"
    full = PyramidSchedule(cfg.plan_tokens, cfg.diffusion.levels).full()
    rng = np.random.default_rng(0)
    x = rng.standard_normal((3, cfg.n_tokens, cfg.token_dim)).astype(np.float32)
    out = den.denoise(DenoiseBatch(x, np.broadcast_to(full, (3, *full.shape)).copy(),
                                   np.array([0.0, 1.0, 2.0], np.float32), np.zeros((3, 2), np.float32),
                                   np.ones((3, 2), np.float32)))
    assert np.isfinite(out.x).all() and not np.array_equal(out.x[1], out.x[2])


# ------------------------------------------------------------------ schedule and time budget


def test_cosine_lr_decays_to_zero_at_the_runs_end_by_steps_or_wall_time():
    cfg = tiny_cfg(100, "train.lr_schedule=cosine", "train.warmup=10")
    assert lr_at(cfg, 4) == pytest.approx(cfg.train.lr * 0.5 * (1 + np.cos(np.pi * 0.04)) / 2)
    assert lr_at(cfg, 50) == pytest.approx(cfg.train.lr / 2) and lr_at(cfg, 100) == pytest.approx(0, abs=1e-12)
    timed = tiny_cfg(100, "train.lr_schedule=cosine", "train.warmup=10", "train.time_budget_s=60")
    assert lr_at(timed, 20, wall_s=30.0) == pytest.approx(cfg.train.lr / 2)  # half the budget gone
    assert lr_at(tiny_cfg(100), 50) == cfg.train.lr  # the paper's: constant after warm-up


def test_wsd_lr_is_constant_then_falls_linearly_to_zero_over_the_last_decay_steps():
    cfg = tiny_cfg(100, "train.lr_schedule=wsd", "train.decay_steps=40", "train.warmup=10")
    assert lr_at(cfg, 4) == pytest.approx(cfg.train.lr * 0.5)  # warm-up as in every schedule
    assert lr_at(cfg, 30) == lr_at(cfg, 60) == pytest.approx(cfg.train.lr)
    assert lr_at(cfg, 80) == pytest.approx(cfg.train.lr / 2) and lr_at(cfg, 100) == pytest.approx(0, abs=1e-12)
    tail = tiny_cfg(100, "train.lr_schedule=wsd", "train.warmup=0")  # decay_steps 0: the last 20%
    assert lr_at(tail, 80) == pytest.approx(cfg.train.lr) and lr_at(tail, 90) == pytest.approx(cfg.train.lr / 2)


def test_a_constant_run_resumed_as_wsd_keeps_its_optimiser_and_anneals(tmp_path):
    words = ("train.ckpt_every=5", "train.val_every=100000")
    train(tiny_cfg(10, *words), FakeData(), tmp_path, progress=False)
    out = train(tiny_cfg(20, "train.lr_schedule=wsd", "train.decay_steps=10", *words), FakeData(), tmp_path,
                progress=False)
    assert out["resumed_from"] == 10 and out["step"] == 20
    manifest = json.loads((tmp_path / MANIFEST_FILE).read_text())
    assert manifest["config"]["train"]["lr_schedule"] == "wsd" and manifest["config"]["train"]["decay_steps"] == 10


def test_time_budget_stops_with_a_checkpoint_and_resumes(tmp_path):
    words = ("train.ckpt_every=100000", "train.val_every=100000")
    out = train(tiny_cfg(10**6, "train.time_budget_s=1.0", *words), FakeData(), tmp_path, progress=False)
    assert 0 < out["step"] < 10**6 and out["wall_time_s"] >= 1.0
    manifest = json.loads((tmp_path / MANIFEST_FILE).read_text())
    assert manifest["train_steps"] == out["step"] and manifest["val_history"][-1][0] == out["step"]
    again = train(tiny_cfg(10**6, "train.time_budget_s=1.0", *words), FakeData(), tmp_path, progress=False)
    assert again["step"] == out["step"] and again["resumed_from"] == out["step"]  # budget spent: nothing to do
    more = train(tiny_cfg(10**6, "train.time_budget_s=2.0", *words), FakeData(), tmp_path, progress=False)
    assert more["resumed_from"] == out["step"] and more["step"] > out["step"] and more["wall_time_s"] >= 2.0


def test_cpu_budget_clock_counts_process_cpu_time(tmp_path):
    """train.budget_clock=cpu: a run stops on its own CPU seconds, so a sleeping (starved) process trains on."""
    import time as _time

    words = ("train.ckpt_every=100000", "train.val_every=100000", "train.budget_clock=cpu", "train.threads=1")
    real = FakeData.sample

    def slow(self, rng, batch):  # wall time passes without this process computing (as when other jobs run)
        _time.sleep(0.05)
        return real(self, rng, batch)

    FakeData.sample = slow
    try:
        out = train(tiny_cfg(10**6, "train.time_budget_s=0.5", *words), FakeData(), tmp_path, progress=False)
    finally:
        FakeData.sample = real
    manifest = json.loads((tmp_path / MANIFEST_FILE).read_text())
    assert manifest["cpu_time_s"] >= 0.5 and manifest["wall_time_s"] > manifest["cpu_time_s"]
    assert manifest["config"]["train"]["budget_clock"] == "cpu" and out["step"] > 0


# ------------------------------------------------------------------ the token-boundary loss

def test_boundary_loss_sees_per_token_offsets_and_not_shared_ones():
    gen = torch.Generator().manual_seed(0)
    x0 = torch.randn(3, 5, 2 * 4, generator=gen)  # 5 tokens of 4 two-dimensional frames
    weight = torch.ones(3, 5)
    assert float(boundary_loss(x0, x0, weight, 4)) == 0.0
    shared = x0 + 0.3  # every token off by the same amount: the steps across boundaries are exact
    assert float(boundary_loss(shared, x0, weight, 4)) == pytest.approx(0.0, abs=1e-12)
    offsets = x0.clone()
    offsets[:, 2] += 0.5  # one token shifted: the steps into and out of it are both 0.5 off per coordinate
    assert float(boundary_loss(offsets, x0, weight, 4)) == pytest.approx(2 * 0.25 / 4)
    weight[:, 2] = 0.0  # a boundary counts with its noisier (lower-weighted) token's weight
    assert float(boundary_loss(offsets, x0, weight, 4)) == 0.0


def test_boundary_loss_in_position_space_sees_only_what_the_readout_reads():
    """train.boundary_space=position: a step the readout ignores costs nothing, one it reads costs in full."""
    gen = torch.Generator().manual_seed(0)
    x0 = torch.randn(3, 5, 3 * 4, generator=gen)  # 5 tokens of 4 three-dimensional frames
    weight = torch.ones(3, 5)
    readout = lambda f: 2.0 * f[..., :2]  # noqa: E731  positions: the first two dims, scaled
    unread, read = x0.clone(), x0.clone()
    unread[:, 2, 2::3] += 0.5  # token 2 shifted along the third dim only
    read[:, 2, 0::3] += 0.5  # token 2 shifted along the first dim
    assert float(boundary_loss(unread, x0, weight, 4, readout)) == 0.0
    assert float(boundary_loss(unread, x0, weight, 4)) > 0.0  # the token space sees both
    # two boundaries of the four, one of two position dims, each (2 * 0.5)**2 off
    assert float(boundary_loss(read, x0, weight, 4, readout)) == pytest.approx(2 * 1.0 / (4 * 2))


def test_position_space_on_maze_frames_is_the_token_space():
    """A maze frame is its normalised (x, y), so its readout changes nothing: the boundary loss is the same and
    the position loss is the token loss."""
    from fmctd_dist.families.maze.data import NavigateDataset

    readout, prov = NavigateDataset(None, {}, None, None).position_readout(tiny_cfg(1))
    x0 = torch.as_tensor(FakeData().windows[:4])
    pred = x0 + 0.1 * torch.randn(x0.shape, generator=torch.Generator().manual_seed(2))
    weight = torch.rand(4, x0.shape[1], generator=torch.Generator().manual_seed(3))
    assert float(boundary_loss(pred, x0, weight, 10, readout)) == float(boundary_loss(pred, x0, weight, 10))
    ends = [0, 1, 18, 19]  # the (x, y) of each token's first and last frame
    token = (weight[..., None] * (pred - x0)[..., ends].square()).mean()
    assert float(position_loss(pred, x0, weight, 10, readout)) == pytest.approx(float(token), rel=1e-6)
    assert prov["readout"]


def test_position_loss_sees_only_what_the_readout_reads():
    gen = torch.Generator().manual_seed(4)
    x0 = torch.randn(2, 3, 3 * 4, generator=gen)  # 3 tokens of 4 three-dimensional frames
    weight = torch.ones(2, 3)
    readout = lambda f: f[..., :2]  # noqa: E731
    unread, read = x0.clone(), x0.clone()
    unread[..., 2::3] += 1.0  # every frame off along the third dim only
    read[:, 1, 0::3] += 1.0  # token 1's frames off by 1 along the first dim
    assert float(position_loss(unread, x0, weight, 4, readout)) == 0.0
    # token 1's two end frames, one of two position dims: 2 of the 3 tokens x 2 ends x 2 dims = 12 entries
    assert float(position_loss(read, x0, weight, 4, readout)) == pytest.approx(2 / 12)
    inner = x0.clone()
    inner[:, 1, 3:6] += 1.0  # an inner frame (frame 1 of token 1) is not read
    assert float(position_loss(inner, x0, weight, 4, readout)) == 0.0


class _DataWithReadout(FakeData):
    def position_readout(self, cfg: Config):
        return torch.nn.Linear(2, 2), {"readout": "a test map"}


def test_position_space_is_recorded_and_bad_combinations_are_one_error_before_training(tmp_path):
    words = ("train.boundary_weight=3", "train.boundary_space=position", "train.ckpt_every=4")
    train(tiny_cfg(4, *words), _DataWithReadout(), tmp_path / "ok", progress=False)
    m = json.loads((tmp_path / "ok" / MANIFEST_FILE).read_text())
    assert m["config"]["train"]["boundary_space"] == "position" and m["position_readout"] == {"readout": "a test map"}
    with pytest.raises(ConfigError, match="no position readout.*train.boundary_space=token"):
        train(tiny_cfg(4, *words), FakeData(), tmp_path / "none", progress=False)
    with pytest.raises(ConfigError, match="train.boundary_weight=0.0"):
        train(tiny_cfg(4, "train.boundary_space=position"), _DataWithReadout(), tmp_path / "off", progress=False)
    with pytest.raises(ConfigError, match="train.boundary_space"):
        tiny_cfg(4, "train.boundary_space=latent")
    with pytest.raises(ConfigError, match="train.position_weight=2.0: the pointmaze-medium data has no position"):
        train(tiny_cfg(4, "train.position_weight=2"), FakeData(), tmp_path / "pos", progress=False)
    train(tiny_cfg(4, "train.position_weight=2", "train.ckpt_every=4"), _DataWithReadout(), tmp_path / "pw",
          progress=False)
    assert json.loads((tmp_path / "pw" / MANIFEST_FILE).read_text())["config"]["train"]["position_weight"] == 2.0
    assert not any((tmp_path / d).exists() for d in ("none", "off", "pos"))


def test_wall_loss_is_the_mean_depth_of_kept_tokens_frames():
    depth = lambda f: torch.relu(f[..., 0])  # noqa: E731  "inside a wall" = x > 0, depth x
    pred = torch.full((2, 3, 4 * 2), -1.0)  # 2 windows x 3 tokens x 4 frames of (x, y), all free
    kept = torch.tensor([[True, True, False], [True, True, True]])
    assert float(wall_loss(pred, kept, 4, depth)) == 0.0
    pred[0, 1, 0::2] = 0.5  # every frame of a kept token 0.5 deep
    pred[0, 2, 0::2] = 9.0  # a cut-off token (pure noise) is not counted
    assert float(wall_loss(pred, kept, 4, depth)) == pytest.approx(0.5 / 5)
    pred[1, 0, 0] = 2.0  # one frame of four
    assert float(wall_loss(pred, kept, 4, depth)) == pytest.approx((0.5 + 0.5) / 5)


class _DataWithWalls(FakeData):
    def wall_depth(self, cfg: Config):
        return (lambda f: torch.relu(f[..., 0] - 0.5)), {"maze": "a test wall"}


def test_wall_lever_is_recorded_and_data_without_walls_is_one_error_before_training(tmp_path):
    train(tiny_cfg(4, "train.wall_weight=1", "train.ckpt_every=4"), _DataWithWalls(), tmp_path / "ok", progress=False)
    m = json.loads((tmp_path / "ok" / MANIFEST_FILE).read_text())
    assert m["config"]["train"]["wall_weight"] == 1.0 and m["wall_depth"] == {"maze": "a test wall"}
    assert "train.wall_weight=1.0" in m["vs_paper"]
    with pytest.raises(ConfigError, match="train.wall_weight=2.0: the pointmaze-medium data has no maze walls.*drop "
                                          "train.wall_weight"):
        train(tiny_cfg(4, "train.wall_weight=2"), FakeData(), tmp_path / "none", progress=False)
    with pytest.raises(ConfigError, match="train.wall_weight"):
        tiny_cfg(4, "train.wall_weight=-1")
    assert not (tmp_path / "none").exists()


def test_validation_loss_leaves_the_boundary_term_out_so_arms_compare():
    cfg, cfg_bw = tiny_cfg(1), tiny_cfg(1, "train.boundary_weight=3")
    torch.manual_seed(0)
    model = DFTransformer.from_config(cfg.model, cfg.n_tokens)
    batches = [torch.as_tensor(FakeData().windows[:4])]
    dev = torch.device("cpu")
    plain, with_bw = DFLoss(cfg, dev), DFLoss(cfg_bw, dev)
    assert validation_loss(model, with_bw, batches, dev) == validation_loss(model, plain, batches, dev)
    gen = lambda: torch.Generator().manual_seed(1)  # noqa: E731
    with torch.no_grad():  # training sees the term
        assert float(with_bw(model, batches[0], gen())) > float(plain(model, batches[0], gen()))


class _Spy(torch.nn.Module):
    """Records the network's inputs; predicts zeros."""

    def forward(self, xt: torch.Tensor, k: torch.Tensor) -> torch.Tensor:
        self.seen = (xt.clone(), k.clone())
        return torch.zeros_like(xt)


def test_clean_context_feeds_the_context_as_the_sampler_does_and_is_off_by_default():
    x0 = torch.as_tensor(FakeData().windows[:6])
    dev = torch.device("cpu")
    gen = lambda: torch.Generator().manual_seed(3)  # noqa: E731
    spy = _Spy()
    cfg_on = tiny_cfg(1, "train.clean_context=1.0")
    DFLoss(cfg_on, dev)(spy, x0, gen())
    xt, k = spy.seen
    sampler = make_consts(cfg_on.diffusion)  # what the sampler feeds a level-0 token
    assert (k[:, 0] == sampler.t_in[0]).all()
    assert torch.allclose(xt[:, 0], sampler.sqrt_ab_in[0] * x0[:, 0], rtol=0, atol=1e-6)  # scaled, no noise
    # every other token is noised exactly as without the lever; off, the context is noised as the paper's
    DFLoss(tiny_cfg(1), dev)(spy, x0, gen())
    xt_off, k_off = spy.seen
    assert torch.equal(xt_off[:, 1:], xt[:, 1:]) and torch.equal(k_off[:, 1:], k[:, 1:])
    assert not torch.equal(xt_off[:, 0], xt[:, 0])
    # validation: the paper's loss whatever the lever says, so arms compare
    DFLoss(cfg_on, dev)(spy, x0, gen(), validation=True)
    assert torch.equal(spy.seen[0], xt_off) and torch.equal(spy.seen[1], k_off)
