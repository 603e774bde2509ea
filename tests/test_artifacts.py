"""fmctd_dist.artifacts: every trained part's weights + manifest + sha256 are written, read and verified alike."""

from __future__ import annotations

import hashlib
import json

import pytest
import torch

from fmctd_dist.artifacts import (
    MANIFEST_FILE, MODEL_FILE, load_weights, read_weights_manifest, save_weights, sha256_file, type_error,
    verify_weights, write_manifest,
)
from fmctd_dist.errors import CheckpointError


def tiny(seed: int = 0) -> torch.nn.Module:
    torch.manual_seed(seed)
    return torch.nn.Linear(3, 2)


def test_save_read_verify_load_round_trip(tmp_path):
    net = tiny()
    m = save_weights(tmp_path / "p", net, {"kind": "toy", "x": torch.tensor(1.5).numpy()})  # numpy -> plain JSON
    raw = (tmp_path / "p" / MODEL_FILE).read_bytes()
    assert m["model_sha256"] == hashlib.sha256(raw).hexdigest() == sha256_file(tmp_path / "p" / MODEL_FILE)
    assert m["digest"] == m["model_sha256"][:16] and m["param_count"] == 8 and m["x"] == 1.5
    assert read_weights_manifest(tmp_path / "p", "toy", "train one", "retrain it") == m
    assert verify_weights(tmp_path / "p", m, "toy", "retrain it") == m["model_sha256"]
    back = load_weights(tmp_path / "p", tiny(seed=1), "toy", "retrain it")
    assert all(torch.equal(a, b) for a, b in zip(back.state_dict().values(), net.state_dict().values()))
    assert not back.training and not list(tmp_path.glob("p/*.tmp"))  # eval mode; no half-written files left


def test_manifest_bytes_are_sorted_indented_json(tmp_path):
    write_manifest({"b": 1, "a": [1, 2]}, tmp_path / MANIFEST_FILE)
    assert (tmp_path / MANIFEST_FILE).read_text() == json.dumps({"a": [1, 2], "b": 1}, indent=2, sort_keys=True) + "\n"


def test_each_broken_dir_is_one_error_with_its_fix(tmp_path):
    with pytest.raises(CheckpointError, match=r"^toy: .*missing does not exist; train one$"):
        read_weights_manifest(tmp_path / "missing", "toy", "train one", "retrain it")
    save_weights(tmp_path / "p", tiny(), {"kind": "toy"})
    (tmp_path / "p" / MANIFEST_FILE).write_text("[1, 2]")
    with pytest.raises(CheckpointError, match="is malformed: the top level is a JSON list.*; retrain it$"):
        read_weights_manifest(tmp_path / "p", "toy", "train one", lambda: "retrain it")
    (tmp_path / "p" / MANIFEST_FILE).write_text("{not json")
    with pytest.raises(CheckpointError, match="is unreadable \\(JSONDecodeError"):
        read_weights_manifest(tmp_path / "p", "toy", "train one", "retrain it")
    (tmp_path / "p" / MODEL_FILE).unlink()
    with pytest.raises(CheckpointError, match="model.pt does not exist \\(an incomplete checkpoint dir\\); retrain"):
        read_weights_manifest(tmp_path / "p", "toy", "train one", "retrain it")


def test_weights_that_are_not_the_manifests_are_refused(tmp_path):
    m = save_weights(tmp_path / "p", tiny(), {"kind": "toy"})
    torch.save(tiny(seed=1).state_dict(), tmp_path / "p" / MODEL_FILE)
    with pytest.raises(CheckpointError, match="toy: model.pt has sha256 .* \\(corrupt or overwritten\\); retrain it"):
        verify_weights(tmp_path / "p", m, "toy", "retrain it")
    with pytest.raises(CheckpointError, match="does not fit the network its manifest describes.*; retrain it"):
        load_weights(tmp_path / "p", torch.nn.Linear(4, 2), "toy", "retrain it")
    (tmp_path / "p" / MODEL_FILE).write_bytes(b"")
    with pytest.raises(CheckpointError, match="model.pt does not load"):
        load_weights(tmp_path / "p", tiny, "toy", "retrain it")


def test_type_error_names_the_first_bad_field():
    types = {"a": (lambda v: isinstance(v, int), "an integer"), "b.c": (lambda v: isinstance(v, str), "a string")}
    assert type_error({"a": 1, "b": {"c": "x"}}, types) == ""
    assert type_error({"a": 1}, types) == "the field 'b.c' is missing"
    assert type_error({"a": "1", "b": {"c": "x"}}, types) == "a is \"1\" (str) but must be an integer"
    assert type_error({"a": 1, "b": {"c": "x"}}, {}, {"d": (lambda v: v > 0, "positive")}) == ""  # optional: absent
