"""Navigate datasets: determinism, verification errors, lazy windows for H=1 and H=5, normalisation."""

import json
import shutil

import numpy as np
import pytest

from conftest import TINY_DATA
from fmctd_dist.config import load_config
from fmctd_dist.families.maze.data import dataset_dir, load_dataset, make_dataset
from fmctd_dist.tokens import Normaliser, PlanCodec, frames_to_tokens, tokens_to_frames
from fmctd_dist.data.windows import WindowSampler, start_balance_cdf, train_data
from fmctd_dist.errors import ConfigError, DatasetError


def test_same_seed_same_bytes(tiny_dataset, tmp_path):
    """Same config, same bytes, whether one process or several (data.workers) made the episodes."""
    cfg, path = tiny_dataset
    cfg2 = load_config(TINY_DATA + [f"data.root={tmp_path}", "data.workers=3"], method="mctd")
    path2, manifest2 = make_dataset(cfg2, progress=False)
    for split in ("train", "val"):
        assert (path / f"{split}.npz").read_bytes() == (path2 / f"{split}.npz").read_bytes()
    assert (path / "manifest.json").read_text() == (path2 / "manifest.json").read_text()
    other = load_config(TINY_DATA + [f"data.root={tmp_path}", "data.seed=1"], method="mctd")
    path3, manifest3 = make_dataset(other, progress=False)
    assert manifest3["sha256"]["train"] != manifest2["sha256"]["train"]


def test_dataset_contents(tiny_dataset):
    cfg, path = tiny_dataset
    ds = load_dataset(cfg)
    assert ds.train.shape == (8, 301, 2) and ds.val.shape == (1, 301, 2)
    steps = np.linalg.norm(np.diff(ds.train, axis=1), axis=-1)
    assert steps.max() <= 0.2 * np.sqrt(2) + 1e-5  # point dynamics: |dxy| <= 0.2 per axis
    assert ds.normaliser.std.min() > 1.0
    from fmctd_dist.families.maze.geometry import maze_geometry

    assert maze_geometry("pointmaze-medium").in_free_cell(ds.train).all()


def _copy(tiny_dataset, tmp_path):
    cfg, path = tiny_dataset
    cfg2 = load_config(TINY_DATA + [f"data.root={tmp_path}"], method="mctd")
    dst = dataset_dir(cfg2)
    shutil.copytree(path, dst)
    return cfg2, dst


def test_corrupt_file_raises(tiny_dataset, tmp_path):
    cfg, dst = _copy(tiny_dataset, tmp_path)
    data = bytearray((dst / "train.npz").read_bytes())
    data[-10] ^= 0xFF
    (dst / "train.npz").write_bytes(bytes(data))
    with pytest.raises(DatasetError, match="train.npz is corrupt"):
        load_dataset(cfg)
    with pytest.raises(DatasetError, match="corrupt"):
        make_dataset(cfg, progress=False)  # never regenerates over a bad file
    assert (dst / "train.npz").read_bytes() == bytes(data)


def test_missing_manifest_field_raises(tiny_dataset, tmp_path):
    cfg, dst = _copy(tiny_dataset, tmp_path)
    m = json.loads((dst / "manifest.json").read_text())
    del m["obs_std"]
    (dst / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(DatasetError, match="'obs_std'"):
        load_dataset(cfg)


def test_mismatched_manifest_raises(tiny_dataset, tmp_path):
    cfg, dst = _copy(tiny_dataset, tmp_path)
    m = json.loads((dst / "manifest.json").read_text())
    m["noise"] = 0.3
    (dst / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(DatasetError, match="noise"):
        load_dataset(cfg)


def test_missing_dataset_says_how_to_make_it(tmp_path):
    cfg = load_config(TINY_DATA + [f"data.root={tmp_path}"], method="mctd")
    with pytest.raises(DatasetError, match="make_dataset.py env=pointmaze-medium"):
        load_dataset(cfg)


@pytest.mark.parametrize("jump, tokens", [(1, 11), (5, 3)])
def test_window_shapes_and_subsampling(tiny_dataset, jump, tokens):
    cfg, _ = tiny_dataset
    cfg = load_config(TINY_DATA + [f"data.root={cfg.data.root}", f"jump={jump}"], method="mctd")
    ds = load_dataset(cfg)
    data = train_data(cfg, ds)
    assert data.n_tokens == tokens
    x = data.sample(np.random.default_rng(0), 4)
    assert x.shape == (4, tokens, 20) and x.dtype == np.float32
    # window 7: episode 0, offset 7 -> raw frames 7, 7+jump, ..., 7+100
    w = data.train.windows(np.array([7]))[0]
    frames = ds.normaliser.unnormalise(tokens_to_frames(w[1:], 10))
    np.testing.assert_allclose(frames, ds.train[0, 7 + jump : 7 + 101 : jump], atol=1e-5)
    np.testing.assert_allclose(ds.normaliser.unnormalise(w[0].reshape(10, 2)), np.repeat(ds.train[0, 7:8], 10, 0),
                               atol=1e-5)
    assert data.train.n_windows == 8 * 201  # every offset, never materialised
    v1, v2 = data.val_batches(2, 3), data.val_batches(2, 3)
    assert all((a == b).all() for a, b in zip(v1, v2))


def test_normalisation_round_trip():
    rng = np.random.default_rng(0)
    n = Normaliser.from_lists([10.2, 9.5], [5.8, 5.2])
    x = rng.uniform(-4, 30, size=(3, 50, 2))
    z = n.normalise(x)
    np.testing.assert_allclose(z.mean(axis=(0, 1)), ((x - n.mean) / n.std).mean(axis=(0, 1)), rtol=1e-5)
    np.testing.assert_allclose(n.unnormalise(z), x, atol=1e-4)
    codec = PlanCodec(n, frame_stack=10)
    tokens = np.concatenate([codec.context(x[:, 0]), codec.encode_frames(x)], axis=1)
    np.testing.assert_allclose(codec.decode(tokens), x, atol=1e-4)
    np.testing.assert_array_equal(tokens_to_frames(frames_to_tokens(x, 10), 10), x)


def test_window_sampler_rejects_short_episodes():
    n = Normaliser.from_lists([0, 0], [1, 1])
    with pytest.raises(AssertionError):
        WindowSampler(np.zeros((2, 50, 2), np.float32), 100, 1, 10, n)


def test_start_balance_weights_depend_on_the_start_cell_only():
    """alpha 1: every occupied 1x1 start cell gets the same total mass; alpha 0.5: mass ~ sqrt(count)."""
    # 3 episodes x 6 offsets: 12 starts in cell (0, 0), 4 in cell (5, 5), 2 in cell (9, 0)
    starts = np.zeros((3, 6, 2))
    starts[0] = [0.1, 0.2]
    starts[1, :] = [0.5, 0.5]
    starts[1, 2:] = [5.5, 5.5]
    starts[2, :4] = [0.9, 0.9]
    starts[2, 4:] = [9.2, 0.3]
    cells = np.floor(starts.reshape(-1, 2)).astype(int)
    for alpha, expect in ((1.0, [1 / 3] * 3), (0.5, np.sqrt([12, 4, 2]) / np.sqrt([12, 4, 2]).sum())):
        w = np.diff(start_balance_cdf(starts, alpha), prepend=0.0)
        mass = [w[(cells == c).all(axis=1)].sum() for c in ([0, 0], [5, 5], [9, 0])]
        np.testing.assert_allclose(mass, expect, rtol=1e-9)
        assert np.allclose(w[(cells == [0, 0]).all(axis=1)], w[0])  # same cell, same weight


def test_start_balance_oversamples_rare_starts_and_zero_is_the_uniform_sampler(tiny_dataset):
    cfg, _ = tiny_dataset
    base = TINY_DATA + [f"data.root={cfg.data.root}"]
    plain, bal = (train_data(c, load_dataset(c))
                  for c in (load_config(base, method="mctd"),
                            load_config(base + ["train.start_balance=1"], method="mctd")))
    # balance 0 draws exactly as before (rng.integers): bitwise the same batch as the uniform sampler
    ref = plain.train.windows(np.random.default_rng(3).integers(0, plain.train.n_windows, size=64))
    np.testing.assert_array_equal(plain.sample(np.random.default_rng(3), 64), ref)
    # the rarest start cell's share of drawn windows grows with balance 1
    starts = load_dataset(load_config(base, method="mctd")).train[:, : plain.train.offsets_per_episode]
    cells = np.floor(starts.reshape(-1, 2)).astype(int)
    _, inv, counts = np.unique(cells, axis=0, return_inverse=True, return_counts=True)
    rare = counts[inv.reshape(-1)] == counts.min()
    share = [rare[np.searchsorted(np.arange(1, plain.train.n_windows + 1) / plain.train.n_windows,
                                  np.random.default_rng(0).random(20000), side="right")].mean(),
             rare[np.searchsorted(bal.train._cdf, np.random.default_rng(0).random(20000), side="right")].mean()]
    assert share[1] > 3 * share[0], share
    assert np.array_equal(bal.val_batches(1, 4)[0], plain.val_batches(1, 4)[0])  # validation stays uniform
    with pytest.raises(ConfigError, match="train.start_balance"):
        load_config(base + ["train.start_balance=1.5"], method="mctd")
