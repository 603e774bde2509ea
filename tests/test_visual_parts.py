"""Visual maze pre-trained parts (issue 21): the VAE, the latent store, the estimator, the inverse dynamics.

One tiny pipeline per module (tiny dataset, 32 frames, 1 + 1 episodes of 301 steps, a few steps
of each part), then: training resumes and is deterministic, the store round trip (state ->
image -> latent) is reproducible, and each loader refuses bad inputs with one clear error.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import TINY_DATA, torch_threads, with_words
from fmctd_dist.config import REPO_ROOT
from fmctd_dist.families.visual.env import render_states
from fmctd_dist.errors import CheckpointError, ConfigError, DatasetError
from fmctd_dist.families.visual.config import load_parts_args

MEDIUM = "visual-pointmaze-medium"
TINY_PARTS = ["vae.latent_dim=3", "vae.channels=[8,16,16]", "vae.max_steps=6", "vae.batch_size=8", "vae.val_every=3",
              "vae.ckpt_every=3", "latents.val_episodes=1", "estimator.hidden=[32]", "estimator.max_steps=20",
              "invdyn.hidden=[32,32]", "invdyn.max_steps=20", "reach.segments=2", "reach.steps=5", "visual.frames=32",
              "visual.episodes=1"]


def _args(root: Path, out: Path, *extra: str) -> list[str]:
    words = [w for w in TINY_DATA if not w.startswith("env=")]
    return with_words([f"env={MEDIUM}", *words, f"data.root={root}", *TINY_PARTS, f"vae.out={out / 'vae'}",
                       f"estimator.out={out / 'estimator'}", f"invdyn.out={out / 'invdyn'}"], *extra)


def _load(root: Path, out: Path, part: str, *extra: str):
    cfg, pcfg, p = load_parts_args(_args(root, out, f"part={part}", *extra))
    return cfg, pcfg


@pytest.fixture(scope="module")
def pipeline(tiny_dataset, tmp_path_factory):
    """Frames, VAE, episode frames, latents, estimator and inverse dynamics, each trained a few steps."""
    from fmctd_dist.families.visual.frame_sets import make_frames
    from fmctd_dist.families.visual.latents import make_latents
    from fmctd_dist.families.visual.train_head import train_head
    from fmctd_dist.families.visual.train_vae import train_vae

    data_cfg, _ = tiny_dataset
    root, out = Path(data_cfg.data.root), tmp_path_factory.mktemp("parts")
    with torch_threads(1):
        cfg, pcfg = _load(root, out, "vae")
        make_frames(cfg, progress=False)
        vae = train_vae(cfg, pcfg, progress=False)
        lat_path, lat = make_latents(cfg, pcfg, progress=False)
        est = train_head(cfg, pcfg, "estimator", progress=False)
        inv = train_head(cfg, pcfg, "invdyn", progress=False)
    return {"root": root, "out": out, "cfg": cfg, "pcfg": pcfg, "vae": vae, "latents": (lat_path, lat),
            "estimator": est, "invdyn": inv}


def test_each_part_trains_and_records_its_quality(pipeline):
    vae, est, inv = pipeline["vae"], pipeline["estimator"], pipeline["invdyn"]
    assert vae["step"] == 6 and np.isfinite(vae["val_mse"]) and vae["val_psnr_db"] > 0
    assert np.isfinite(vae["val_linear_xy_rmse"])
    assert est["step"] == 20 and np.isfinite(est["val_rmse"]) and est["val_rows"] == 3  # 32 x 0.1 val frames
    assert inv["step"] == 20 and np.isfinite(inv["val_mse"]) and inv["val_rows"] == 299  # 301 steps - 2
    assert inv["val_mse_true_positions"] < 0.05 < inv["val_mse_zero"]  # a_t is readable off positions
    m = json.loads((pipeline["out"] / "invdyn" / "manifest.json").read_text())
    vm = json.loads((pipeline["out"] / "vae" / "manifest.json").read_text())
    assert m["kind"] == "visual-invdyn" and m["vae"]["digest"] == vm["digest"] and m["window"] == 3
    assert vm["frames"]["sha256"] and vm["steps"] == 6 and len(vm["model_sha256"]) == 64


def test_reach_runs_closed_loop_and_is_recorded(pipeline):
    """Two 5-step segments through the renderer; the true-position reference follows its path exactly."""
    from fmctd_dist.families.visual.reach import run_reach

    with torch_threads(1):
        got = run_reach(pipeline["cfg"], pipeline["pcfg"], progress=False)["reach"]
    assert got["segments"] == 2 and 0 <= got["invdyn"]["reach_rate"] <= 1
    assert got["true_positions"]["reach_rate"] == 1.0
    m = json.loads((pipeline["out"] / "invdyn" / "manifest.json").read_text())
    assert m["metrics"]["reach"] == got
    from fmctd_dist.families.visual.load import load_invdyn, load_vae

    load_invdyn(pipeline["out"] / "invdyn", MEDIUM, load_vae(pipeline["out"] / "vae", MEDIUM))  # sha still holds


def test_vae_resumes_to_the_same_weights(pipeline, tmp_path):
    """3 steps, stop, 3 more == the fixture's uninterrupted 6 (same thread count)."""
    from fmctd_dist.families.visual.train_vae import train_vae

    root, out = pipeline["root"], tmp_path
    with torch_threads(1):
        train_vae(*_load(root, out, "vae", "vae.max_steps=3"), progress=False)
        got = train_vae(*_load(root, out, "vae"), progress=False)
    assert got["step"] == 6
    a = json.loads((out / "vae" / "manifest.json").read_text())
    b = json.loads((pipeline["out"] / "vae" / "manifest.json").read_text())
    assert a["model_sha256"] == b["model_sha256"]
    with pytest.raises(CheckpointError, match="vae.kl_weight"):
        train_vae(*_load(root, out, "vae", "vae.kl_weight=0.1", "vae.max_steps=9"), progress=False)


def test_store_round_trip_state_image_latent(pipeline):
    """The latent store's latents = the VAE applied to frames rendered afresh from the dataset's states."""
    from fmctd_dist.families.visual.latents import load_latents, make_latents
    from fmctd_dist.families.visual.load import load_vae

    cfg, pcfg = pipeline["cfg"], pipeline["pcfg"]
    path, m = pipeline["latents"]
    vae = load_vae(pipeline["out"] / "vae", MEDIUM)
    store = load_latents(cfg, pcfg, vae)
    s = store.split("train")
    assert s["mu"].shape == (1, 301, 3) and store.manifest["vae"]["digest"] == vae.digest
    from fmctd_dist.families.maze.data import load_dataset
    from fmctd_dist.families.visual.frame_sets import episode_subset, point_config

    data = load_dataset(point_config(cfg))
    e = int(episode_subset(cfg)[0])
    assert s["episodes"].tolist() == [e]
    np.testing.assert_array_equal(s["xy"][0], data.train[e])
    steps = [0, 150, 300]
    images = render_states(MEDIUM, data.train[e][steps].astype(np.float64), shadowsize=cfg.visual.shadowsize)
    with torch_threads(1):  # 3 frames here, one batch of 301 in the store: a CPU's conv kernels may round
        # differently per batch shape (seen on an Intel Xeon with AMX: 4e-8), so equal up to float32 rounding;
        # re-encoding the store (below) is bitwise
        np.testing.assert_allclose(vae.encode(images), s["mu"][0, steps], rtol=0, atol=1e-6)
    shutil.rmtree(path)  # encoded again (episode frames are kept): the same bytes
    with torch_threads(1):
        _, m2 = make_latents(cfg, pcfg, progress=False)
    assert m2["sha256"] == m["sha256"] and m2["frames_digest"] == m["frames_digest"]
    with open(path / "latents.npz", "r+b") as f:  # one flipped byte -> refused
        f.seek(-1, 2)
        b = f.read(1)
        f.seek(-1, 2)
        f.write(bytes([b[0] ^ 1]))
    with pytest.raises(DatasetError, match="sha256"):
        load_latents(cfg, pcfg, vae)
    shutil.rmtree(path)


def test_loaders_refuse_bad_inputs(pipeline, tiny_checkpoint, tmp_path):
    from fmctd_dist.families.visual.load import load_estimator, load_invdyn, load_vae

    out = pipeline["out"]
    vae = load_vae(out / "vae", MEDIUM)
    est = load_estimator(out / "estimator", MEDIUM, vae)
    inv = load_invdyn(out / "invdyn", MEDIUM, vae)
    assert est(np.zeros((5, 3))).shape == (5, 2) and inv(np.zeros((2, 4, 9))).shape == (2, 4, 2)
    assert vae.decode(np.zeros((2, 3))).shape == (2, 64, 64, 3)
    with pytest.raises(CheckpointError, match=r"last axis 8.*latent_dim=3"):  # wrong latent size
        est(np.zeros((5, 8)))
    with pytest.raises(CheckpointError, match="3 x 3-D latents"):
        inv(np.zeros((5, 3)))
    with pytest.raises(CheckpointError, match="latent_dim=3 but the latents here are 8-D"):
        load_vae(out / "vae", MEDIUM, latent_dim=8)
    with pytest.raises(CheckpointError, match=r"kind='df' \(a Diffusion Forcing planner.*env pointmaze-medium"):
        load_vae(Path(tiny_checkpoint[1]), MEDIUM)  # a point maze planner given to the visual env
    with pytest.raises(CheckpointError, match="kind='visual-estimator'.*part=vae"):
        load_vae(out / "estimator", MEDIUM)
    with pytest.raises(CheckpointError, match="env='visual-pointmaze-medium' but this run's env is "
                                              "'visual-pointmaze-large'"):
        load_vae(out / "vae", "visual-pointmaze-large")
    with pytest.raises(CheckpointError, match="does not exist.*jobs/train_visual.py part=invdyn"):
        load_invdyn(tmp_path / "none", MEDIUM, vae)
    other = tmp_path / "vae2"  # the same VAE retrained with another seed: heads of the first are refused
    with torch_threads(1):
        from fmctd_dist.families.visual.train_vae import train_vae

        train_vae(*_load(pipeline["root"], tmp_path, "vae", f"vae.out={other}", "vae.seed=1", "vae.max_steps=1"),
                  progress=False)
    with pytest.raises(CheckpointError, match="vae.digest=.* but the VAE given is"):
        load_estimator(out / "estimator", MEDIUM, load_vae(other, MEDIUM))
    bad = tmp_path / "bad"
    shutil.copytree(out / "invdyn", bad)
    (bad / "model.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(CheckpointError, match="sha256"):
        load_invdyn(bad, MEDIUM, vae)


def test_config_refuses_bad_words(tmp_path):
    for words, match in ((["part=vea"], "did you mean 'vae'"), (["part=vae", "vae.latentdim=3"], "vae.latent_dim"),
                         (["part=vae", "vae.kl_weight=-1"], "vae.kl_weight=-1"), ([], "part= is missing"),
                         (["part=vae", "env=pointmaze-medium"], "built for visual-pointmaze envs only"),
                         (["part=invdyn", "invdyn.hidden=[]"], "invdyn.hidden")):
        with pytest.raises(ConfigError, match=match):
            load_parts_args(words)


def test_train_visual_job_names_the_missing_frames(tmp_path):
    """The job as a subprocess: no frames is one `error:` line naming the render command."""
    words = [w for w in TINY_DATA if not w.startswith("env=")]
    out = subprocess.run([sys.executable, "jobs/train_visual.py", "part=vae", f"env={MEDIUM}", *words,
                          f"data.root={tmp_path}", f"vae.out={tmp_path / 'vae'}"],
                         cwd=REPO_ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 2, out.stderr
    assert out.stderr.startswith("error: ")
    assert "jobs/render_frames.py env=visual-pointmaze-medium" in out.stderr


def test_episodes_skip_what_another_process_rendered(tiny_dataset, tmp_path, monkeypatch):
    """Two processes may share `part=episodes` (one from each end of the list): an episode whose file
    appears while this one renders is kept as it is, not rendered again, and still enters the digest."""
    from fmctd_dist.families.maze.data import dataset_dir
    from fmctd_dist.data.npz import load_npz, save_npz
    from fmctd_dist.families.visual.frame_sets import point_config
    from fmctd_dist.families.visual import episodes as ep

    data_cfg, path = tiny_dataset
    (tmp_path / path.name).symlink_to(path)  # the point dataset, under this test's own data root
    cfg, pcfg = _load(tmp_path, tmp_path / "parts", "episodes")
    assert dataset_dir(point_config(cfg)) == tmp_path / path.name
    out = ep.episodes_dir(cfg, pcfg)
    ids = {"train": ep.episode_subset(cfg), "val": ep.val_episode_subset(cfg, 1, 1)}
    other = out / ep._file("val", int(ids["val"][0]))
    steps, calls = data_cfg.data.episode_steps, []

    class OtherProcessRenders:
        """Renders grey frames; on its first call 'another process' finishes the val episode."""

        def __init__(self, *args, **kwargs):
            pass

        def render(self, xy):
            if not other.exists():
                save_npz(other, {"images": np.full((steps, 64, 64, 3), 7, np.uint8),
                                 "xy": np.zeros((steps, 2), np.float32), "actions": np.zeros((steps, 2), np.float32)})
            calls.append(len(xy))
            return np.zeros((len(xy), 64, 64, 3), np.uint8)

        def close(self):
            pass

    monkeypatch.setattr(ep, "FrameRenderer", OtherProcessRenders)
    monkeypatch.setattr(ep, "render_info", lambda r: {"renderer": "test"})
    _, m = ep.make_episodes(cfg, pcfg, progress=False)
    assert sum(calls) == steps and m["generation"]["rendered_frames"] == steps  # the train episode only
    shape = {"images": (np.uint8, (steps, 64, 64, 3))}
    assert (load_npz(other, shape, "")["images"] == 7).all()  # the other process's file, untouched
    assert not list(out.glob("*.tmp"))
    assert m["episodes"] == ids["train"].tolist() and m["val_episodes"] == ids["val"].tolist()
