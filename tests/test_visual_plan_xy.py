"""visual.plan_xy: the visual planner on [z, estimated x, y] frames (fmctd_dist/families/visual/frames_xy.py).

The frames, the dataset, the readout guidance and value use, widening a latent model's weights to the
new frames (train.init_from), the checks that keep a [z, x, y] model and a latent config apart, and a
short Fast-MCTD episode with a widened model trained two steps on a fake store (runs in CI: no data).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from conftest import torch_threads
from fmctd_dist.config import REPO_ROOT, load_config
from fmctd_dist.errors import CheckpointError, ConfigError

MEDIUM = "visual-pointmaze-medium"
SHIPPED = REPO_ROOT / "checkpoints" / f"{MEDIUM}-h5"
ESTIMATOR = REPO_ROOT / "checkpoints" / f"{MEDIUM}-estimator"
needs_parts = pytest.mark.skipif(not (SHIPPED / "model.pt").exists() or not (ESTIMATOR / "model.pt").exists(),
                                 reason="the medium planner / estimator is not shipped")


def _estimator():
    from fmctd_dist.families.visual.guide import Positions, load_estimator_net

    net, m = load_estimator_net(load_config([f"env={MEDIUM}"]), _vae_digest(), 8)
    return Positions(net), str(m["digest"])


def _vae_digest() -> str:
    return json.loads((REPO_ROOT / f"checkpoints/{MEDIUM}-vae/manifest.json").read_text())["digest"]


def _fake_xy_dataset(episodes: int = 2, steps: int = 1001):
    """A store of random 8-D latents, framed as visual.plan_xy frames with the shipped estimator."""
    from fmctd_dist.families.visual.dataset import VisualLatentDataset
    from fmctd_dist.families.visual.frames_xy import PlanFrames

    pos, digest = _estimator()
    rng = np.random.default_rng(0)
    z = np.cumsum(rng.normal(scale=0.05, size=(episodes, steps, 8)), axis=1).astype(np.float32)
    f = PlanFrames(pos, 8, True).of_latents(z)
    manifest = {"sha256": "ab" * 32, "vae": {"digest": _vae_digest(), "path": f"checkpoints/{MEDIUM}-vae"},
                "latent_dim": 8, "episodes": [3, 5], "val_episodes": [1], "frames_digest": "cd" * 32}
    return VisualLatentDataset(Path("/nowhere"), manifest, f, f[:1], np.array([10.0, 8.0]), np.array([5.0, 4.0]),
                               digest)


def test_plan_xy_adds_two_numbers_per_frame_and_only_on_visual_mazes():
    latent = load_config([f"env={MEDIUM}", "jump=5", "visual.plan_xy=false"])
    assert latent.frame_dim == 8 and latent.checkpoint_dir() == SHIPPED
    cfg = load_config([f"env={MEDIUM}", "jump=5", "visual.plan_xy=true"])
    assert cfg.frame_dim == 10 and cfg.token_dim == 100
    assert cfg.checkpoint_dir() == REPO_ROOT / "checkpoints" / f"{MEDIUM}-h5-xy"  # the variant's own default
    assert load_config([f"env={MEDIUM}", "jump=1", "visual.plan_xy=true"]).run_name == f"{MEDIUM}-h1-xy"
    with pytest.raises(ConfigError, match=r"visual.plan_xy=true.*pointmaze-medium.*Drop visual.plan_xy"):
        load_config(["env=pointmaze-medium", "visual.plan_xy=true"])


def test_plan_frames_carry_the_estimators_position_and_give_back_the_latent():
    from fmctd_dist.families.visual.frames_xy import PlanFrames

    est = lambda z: np.stack([z[..., 0] * 2.0, z[..., 1] - 1.0], axis=-1)  # noqa: E731 - a toy estimator
    z = np.arange(24, dtype=np.float32).reshape(3, 8)
    xy = PlanFrames(est, 8, True)
    f = xy.of_latents(z)
    assert f.shape == (3, 10) and f.dtype == np.float32 and xy.dim == 10
    np.testing.assert_array_equal(xy.latents(f), z)
    np.testing.assert_array_equal(xy(f), est(z))
    f[:, 8:] = 7.0  # positions are the frames' own, not the estimator's reading of their latents
    assert (xy(f) == 7.0).all()
    plain = PlanFrames(est, 8, False)
    assert plain.dim == 8 and plain.of_latents(z) is not None and np.array_equal(plain(z), est(z))
    np.testing.assert_array_equal(plain.latents(z), z)


def test_widened_weights_predict_the_old_numbers_as_the_old_model_does():
    """widen_frames: the old frame numbers' x0_hat is unchanged whatever the new numbers hold; new ones start at 0."""
    from fmctd_dist.diffusion.init_from import widen_frames
    from fmctd_dist.diffusion.model import DFTransformer

    torch.manual_seed(0)
    old, new = DFTransformer(8 * 3, 4, 32, 2, 4, 64, frame_dim=8), DFTransformer(10 * 3, 4, 32, 2, 4, 64, frame_dim=10)
    new.load_state_dict(widen_frames(old.state_dict(), 8, 10, 3))
    x, t = torch.randn(2, 4, 3, 8), torch.randint(0, 1000, (2, 4))
    wide = torch.cat([x, torch.randn(2, 4, 3, 2)], dim=-1).reshape(2, 4, 30)
    with torch.no_grad():
        got = new(wide, t).reshape(2, 4, 3, 10)
        ref = old(x.reshape(2, 4, 24), t).reshape(2, 4, 3, 8)
    torch.testing.assert_close(got[..., :8], ref)
    assert got[..., 8:].abs().max() == 0


@needs_parts
def test_init_from_a_latent_model_widens_it_and_refuses_a_narrower_config(tmp_path):
    from fmctd_dist.diffusion.init_from import load_init_weights

    cfg = load_config([f"env={MEDIUM}", "jump=5", "visual.plan_xy=true"])
    state, prov = load_init_weights(SHIPPED, cfg)
    assert state["out.weight"].shape[0] == 100 and prov["widened_frames"] == {"from": 8, "to": 10}
    with pytest.raises(CheckpointError, match=r"models 80 numbers per token.*this config has 20"):
        load_init_weights(SHIPPED, load_config(["env=pointmaze-medium", "jump=5"]))


@needs_parts
def test_xy_dataset_frames_readout_and_provenance():
    """[z, x, y] frames: the readout (boundary / position losses, guidance) reads the frames' (x, y)."""
    ds = _fake_xy_dataset()
    pos, digest = _estimator()
    assert ds.train.shape[-1] == 10 and ds.plan_xy and ds.digest == f"{'ab' * 32}+xy{digest}"
    np.testing.assert_allclose(ds.train[..., 8:], pos(ds.train[..., :8]), rtol=1e-5, atol=1e-5)
    prov = ds.provenance["latents"]
    assert prov["plan_xy"] is True and prov["estimator_digest"] == digest and prov["latent_dim"] == 8
    readout, rprov = ds.position_readout(load_config([f"env={MEDIUM}", "visual.plan_xy=true"]))
    f = ds.train[0, :9]
    with torch.no_grad():
        got = readout(torch.as_tensor(ds.normaliser.normalise(f), dtype=torch.float32)).numpy()
    np.testing.assert_allclose(got * ds.xy_std + ds.xy_mean, f[:, 8:], rtol=1e-4, atol=1e-4)
    assert "plan_xy" in rprov["readout"]


@needs_parts
def test_a_widened_model_plans_an_episode_and_configs_must_match_it(tmp_path):
    """Two training steps from the shipped latent model on a fake [z, x, y] store, then: a latent config refuses
    the checkpoint (and a [z, x, y] config the latent one), and a short Fast-MCTD episode runs from images with
    10-D plans whose latents the controller follows."""
    from fmctd_dist.data.windows import train_data
    from fmctd_dist.denoiser.local import LocalDenoiser
    from fmctd_dist.diffusion.checkpoint import normaliser_from_manifest, read_manifest
    from fmctd_dist.diffusion.train import train
    from fmctd_dist.families import guide_map, hooks_for, plan_rules
    from fmctd_dist.planners import make_planner

    out = tmp_path / "xy-h5"
    words = [f"env={MEDIUM}", "jump=5", "visual.plan_xy=true"]
    tcfg = load_config(words + ["train.max_steps=2", "train.batch_size=4", "train.val_batches=1", "train.warmup=1",
                                f"train.init_from={SHIPPED}", "train.ckpt_every=2"], method="fast-mctd")
    with torch_threads(1):
        train(tcfg, train_data(tcfg, _fake_xy_dataset()), out, progress=False)
    m = json.loads((out / "manifest.json").read_text())
    assert m["token_dim"] == 100 and m["latents"]["plan_xy"] and m["init_from"]["widened_frames"]["to"] == 10
    hooks = hooks_for(MEDIUM)
    with pytest.raises(CheckpointError, match=r"plans \[z, x, y\] frames.*visual.plan_xy=false; set visual.plan_xy"):
        hooks.check_episodes(load_config([f"env={MEDIUM}", "jump=5", "visual.plan_xy=false", f"checkpoint={out}"]))
    with pytest.raises(CheckpointError, match=r"plans latent frames.*visual.plan_xy=true; set visual.plan_xy=false"):
        hooks.check_episodes(load_config(words + [f"checkpoint={SHIPPED}"]))
    cfg = load_config(words + [f"checkpoint={out}", "method.budget=8", "method.parallel=4"],
                      method="fast-mctd")
    hooks.check_episodes(cfg)
    with torch_threads(1):
        norm = normaliser_from_manifest(read_manifest(out))
        denoiser = LocalDenoiser.from_checkpoint(out, cfg, guide_map=guide_map(cfg.env.name))
        planner = make_planner(cfg, denoiser, norm, plan_rules(cfg))
        episodes = hooks.episodes(cfg)
        first = []
        inner = planner.plan
        planner.plan = lambda s, g, seed: first.append((s, g)) or inner(s, g, seed)  # what the planner is given
        row = episodes.run(planner, 1, 0)
    s, g = first[0]
    assert s.shape == g.shape == (10,)
    np.testing.assert_allclose(s[8:], episodes.frames.estimator(s[:8]), rtol=1e-5)  # the start's own position
    assert row["plans"] >= 1 and np.isfinite(row["plan_xy"]).all() and row["env_steps"] <= cfg.env.max_steps


XY = REPO_ROOT / "checkpoints" / f"{MEDIUM}-h5-xy"


@pytest.mark.skipif(not (XY / "model.pt").exists(), reason=f"{XY} is not shipped")
def test_fast_mctd_with_the_shipped_xy_model_solves_task3_seed0():
    """The shipped [z, x, y] model (session 31, docs/results.md 13.4) at the maze's own warp rule: Fast-MCTD
    solves task 3 seed 0 from images (the latent default returns "stay" there). Task 1 seed 0, the issue's
    smoke test, it does not solve (it solves task 1 seeds 1, 5 and 6)."""
    from fmctd_dist.denoiser.local import LocalDenoiser
    from fmctd_dist.diffusion.checkpoint import normaliser_from_manifest, read_manifest
    from fmctd_dist.families import guide_map, hooks_for, plan_rules
    from fmctd_dist.planners import make_planner

    cfg = load_config([f"env={MEDIUM}", "method=fast-mctd", "visual.episodes=100", "visual.plan_xy=true",
                       f"checkpoint={XY}"])
    with torch_threads(1):
        denoiser = LocalDenoiser.from_checkpoint(XY, cfg, guide_map=guide_map(cfg.env.name))
        planner = make_planner(cfg, denoiser, normaliser_from_manifest(read_manifest(XY)), plan_rules(cfg))
        row = hooks_for(MEDIUM).episodes(cfg).run(planner, 3, 0)
    assert row["success"] and row["plan_status"] == "early_stop", (row["plan_status"], row["env_steps"])


@pytest.mark.skipif(not (XY / "model.pt").exists(), reason=f"{XY} is not shipped")
def test_an_xy_model_of_another_estimator_is_one_clear_error(tmp_path):
    """A [z, x, y] planner whose frames carry another estimator's (x, y) than the one loaded: refused by name."""
    import shutil

    from fmctd_dist.families import hooks_for

    other = tmp_path / "xy-other"
    shutil.copytree(XY, other)
    m = json.loads((other / "manifest.json").read_text())
    m["latents"]["estimator_digest"] = "0123456789abcdef"
    (other / "manifest.json").write_text(json.dumps(m))
    cfg = load_config([f"env={MEDIUM}", "jump=5", "visual.episodes=100", "visual.plan_xy=true", f"checkpoint={other}"])
    with pytest.raises(CheckpointError, match=r"estimator '0123456789abcdef'.*has digest.*retrain the planner with "
                                              r"visual.plan_xy=true on this estimator"):
        hooks_for(MEDIUM).check_episodes(cfg)
