"""Hostile and broken files (issue 18 item 7): a model.pt carrying a pickled code payload is
refused with CheckpointError before the payload runs; a manifest with wrong types is one
CheckpointError naming the field; a dataset .npz with a wrong dtype or shape is one DatasetError."""

from __future__ import annotations

import json
import pickle
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from conftest import TINY_DATA
from fmctd_dist.config import load_config
from fmctd_dist.data.npz import save_npz
from fmctd_dist.artifacts import MANIFEST_FILE, MODEL_FILE, sha256_file
from fmctd_dist.diffusion.checkpoint import load_checkpoint, read_manifest, save_checkpoint
from fmctd_dist.diffusion.init_from import load_init_weights
from fmctd_dist.resume import TRAIN_STATE_FILE, load_train_state
from fmctd_dist.diffusion.model import DFTransformer
from fmctd_dist.errors import CheckpointError, DatasetError

TINY = ["model.width=32", "model.layers=2", "model.heads=2", "model.ff=64"]


class Payload:
    """Unpickling this runs code: it creates ``marker`` (what an attacker's os.system would do)."""

    def __init__(self, marker: Path):
        self.marker = str(marker)

    def __reduce__(self):
        return (exec, (f"open({self.marker!r}, 'w').write('pwned')",))


def tiny_checkpoint(path: Path):
    cfg = load_config(TINY)
    torch.manual_seed(0)
    model = DFTransformer.from_config(cfg.model, cfg.n_tokens)
    save_checkpoint(path, model, {"config": cfg.to_dict(), "dataset_digest": "abc", "data_seed": 0, "git_sha": "x",
                                  "train_steps": 1, "wall_time_s": 0.1, "final_losses": {},
                                  "normaliser": {"mean": [10.0, 9.0], "std": [5.0, 5.0]}})
    return cfg, model


def plant(ckpt: Path, name: str, obj) -> None:
    """Write ``obj`` with torch.save as ckpt/name and make the manifest vouch for it (sha256 matches),
    as an attacker who controls the directory would: only the unpickler stands in the way."""
    torch.save(obj, ckpt / name)
    if name == MODEL_FILE:
        m = json.loads((ckpt / MANIFEST_FILE).read_text())
        m["model_sha256"] = sha256_file(ckpt / MODEL_FILE)
        m["digest"] = m["model_sha256"][:16]
        (ckpt / MANIFEST_FILE).write_text(json.dumps(m))


def test_payload_is_real(tmp_path):
    """Control: the payload does run when unpickled without weights_only (so the refusals below mean something)."""
    marker = tmp_path / "ran"
    pickle.loads(pickle.dumps(Payload(marker)))
    assert marker.read_text() == "pwned"


@pytest.mark.parametrize("as_state_dict", [True, False], ids=["inside-state-dict", "whole-file"])
def test_model_pt_with_code_payload_is_refused_and_never_runs(tmp_path, as_state_dict):
    cfg, model = tiny_checkpoint(tmp_path / "ck")
    marker = tmp_path / "ran"
    obj = {**model.state_dict(), "evil": Payload(marker)} if as_state_dict else Payload(marker)
    plant(tmp_path / "ck", MODEL_FILE, obj)
    with pytest.raises(CheckpointError, match="weights_only=True") as e:
        load_checkpoint(tmp_path / "ck", cfg)
    assert "model.pt" in str(e.value) and "\n" not in str(e.value) and "weights_only=False" not in str(e.value)
    with pytest.raises(CheckpointError, match="train.init_from"):
        load_init_weights(tmp_path / "ck", cfg)
    assert not marker.exists()


def test_train_state_with_code_payload_is_refused_and_never_runs(tmp_path):
    tiny_checkpoint(tmp_path / "ck")
    marker = tmp_path / "ran"
    plant(tmp_path / "ck", TRAIN_STATE_FILE, {"model": {}, "step": Payload(marker)})
    with pytest.raises(CheckpointError, match="train_state.pt .*delete"):
        load_train_state(tmp_path / "ck")
    assert not marker.exists()
    plant(tmp_path / "ck", TRAIN_STATE_FILE, [1, 2, 3])  # loads, but is no training state
    with pytest.raises(CheckpointError, match="not a training state"):
        load_train_state(tmp_path / "ck")


def test_ant_checkpoints_with_code_payload_are_refused(tmp_path):
    from fmctd_dist.families.maze.expert.expert import load_expert
    from fmctd_dist.control.policy.checkpoint import load_policy
    from fmctd_dist.families.maze.ant_policy import ANT_SPEC
    from fmctd_dist.config import REPO_ROOT

    marker = tmp_path / "ran"
    for name, load in (("ant-expert", lambda d: load_expert(d)),
                       ("antmaze-medium-policy", lambda d: load_policy(d, ANT_SPEC, "antmaze-medium"))):
        d = tmp_path / name
        shutil.copytree(REPO_ROOT / "checkpoints" / name, d)
        plant(d, MODEL_FILE, Payload(marker))
        with pytest.raises(CheckpointError, match="model.pt is not a plain tensor state_dict.*UnpicklingError") as e:
            load(d)
        assert "\n" not in str(e.value) and "weights_only=False" not in str(e.value)
    assert not marker.exists()


WRONG_TYPES = [  # (path into the manifest, bad value, text the message names)
    (("n_tokens",), "11", "n_tokens"),
    (("config",), [1, 2], "config"),
    (("config", "jump"), "5", "config.jump"),
    (("config", "model", "width"), "32", "config.model.width"),
    (("config", "model", "kind"), 3, "config.model.kind"),
    (("config", "env"), "pointmaze-medium", "config.env"),
    (("normaliser", "mean"), ["a", "b"], "normaliser.mean"),
    (("token_dim",), None, "token_dim"),
    (("model_sha256",), 12, "model_sha256"),
    (("train_steps",), True, "train_steps"),
    ((), [1, 2], "top level"),
]


@pytest.mark.parametrize("where, value, name", WRONG_TYPES, ids=[w[2] for w in WRONG_TYPES])
def test_manifest_with_wrong_types_is_one_checkpoint_error(tmp_path, where, value, name):
    cfg, _ = tiny_checkpoint(tmp_path / "ck")
    mf = tmp_path / "ck" / MANIFEST_FILE
    m = json.loads(mf.read_text())
    if where:
        node = m
        for part in where[:-1]:
            node = node[part]
        node[where[-1]] = value
    else:
        m = value
    mf.write_text(json.dumps(m))
    for load in (lambda: load_checkpoint(tmp_path / "ck", cfg), lambda: read_manifest(tmp_path / "ck"),
                 lambda: load_init_weights(tmp_path / "ck", cfg)):
        with pytest.raises(CheckpointError, match="is malformed") as e:
            load()
        assert name in str(e.value) and "\n" not in str(e.value)


def copy_dataset(tiny_dataset, tmp_path) -> tuple:
    cfg, path = tiny_dataset
    dst = tmp_path / "data" / path.name
    shutil.copytree(path, dst)
    return load_config(TINY_DATA + [f"data.root={tmp_path / 'data'}"]), dst


def rewrite(dst: Path, split: str, change) -> None:
    """Replace one array of ``split``.npz and update the manifest's sha256 (a consistent but wrong file)."""
    with np.load(dst / f"{split}.npz") as z:
        arrays = {k: z[k] for k in z.files}
    change(arrays)
    save_npz(dst / f"{split}.npz", arrays)
    m = json.loads((dst / "manifest.json").read_text())
    m["sha256"][split] = sha256_file(dst / f"{split}.npz")
    (dst / "manifest.json").write_text(json.dumps(m))


BAD_ARRAYS = [
    ("int64", lambda a: a.update(observations=a["observations"].astype(np.int64)), "dtype int64"),
    ("float64", lambda a: a.update(observations=a["observations"].astype(np.float64)), "dtype float64"),
    ("strings", lambda a: a.update(observations=a["observations"].astype(str)), "dtype <U"),
    ("extra-axis", lambda a: a.update(observations=a["observations"][..., None]), "shape"),
    ("short-episodes", lambda a: a.update(observations=a["observations"][:, :-1]), "shape"),
    ("3-D-points", lambda a: a.update(observations=np.concatenate([a["observations"]] * 2, -1)[..., :3]), "shape"),
    ("no-observations", lambda a: a.update(observations=None) or a.pop("observations"), "no array 'observations'"),
]


@pytest.mark.parametrize("name, change, message", BAD_ARRAYS, ids=[b[0] for b in BAD_ARRAYS])
def test_dataset_npz_with_wrong_dtype_or_shape_is_one_dataset_error(tiny_dataset, tmp_path, name, change, message):
    from fmctd_dist.families.maze.data import load_dataset

    cfg, dst = copy_dataset(tiny_dataset, tmp_path)
    load_dataset(cfg, dst)  # intact: loads
    rewrite(dst, "val", change)
    with pytest.raises(DatasetError, match="val.npz") as e:
        load_dataset(cfg, dst)
    assert message in str(e.value) and "regenerate" in str(e.value) and "\n" not in str(e.value)


def test_dataset_npz_with_object_array_is_refused_unpickled(tiny_dataset, tmp_path):
    from fmctd_dist.families.maze.data import load_dataset

    cfg, dst = copy_dataset(tiny_dataset, tmp_path)
    marker = tmp_path / "ran"
    with np.load(dst / "train.npz") as z:
        arrays = {k: z[k] for k in z.files}
    arrays["observations"] = np.array([Payload(marker)], dtype=object)
    np.savez(dst / "train.npz", **arrays)  # savez pickles object arrays
    m = json.loads((dst / "manifest.json").read_text())
    m["sha256"]["train"] = sha256_file(dst / "train.npz")
    (dst / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(DatasetError, match="train.npz is malformed"):
        load_dataset(cfg, dst)
    assert not marker.exists()


@pytest.mark.parametrize("key, value", [("episodes", {"train": "8", "val": 1}), ("episode_steps", "301"),
                                        ("obs_mean", "10"), ("sha256", ["x"])])
def test_dataset_manifest_with_wrong_types_is_one_dataset_error(tiny_dataset, tmp_path, key, value):
    from fmctd_dist.families.maze.data import load_dataset

    cfg, dst = copy_dataset(tiny_dataset, tmp_path)
    m = json.loads((dst / "manifest.json").read_text())
    m[key] = value
    (dst / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(DatasetError, match=f"malformed: {key} is"):
        load_dataset(cfg, dst)
