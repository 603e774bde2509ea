"""Checkpoint format: round trip with weights_only, corruption and config mismatches are CheckpointErrors."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from fmctd_dist.config import Config, load_config
from fmctd_dist.denoiser.local import LocalDenoiser
from fmctd_dist.artifacts import MANIFEST_FILE, MODEL_FILE, sha256_file
from fmctd_dist.diffusion.checkpoint import load_checkpoint, normaliser_from_manifest, save_checkpoint
from fmctd_dist.resume import load_train_state, save_train_state
from fmctd_dist.diffusion.model import DFTransformer
from fmctd_dist.errors import CheckpointError

TINY = ["model.width=32", "model.layers=2", "model.heads=2", "model.ff=64"]


def tiny_cfg(*extra: str) -> Config:
    """fast-mctd: jump 5, horizon 500 -> 11 tokens; ``extra`` words replace TINY's values of their keys."""
    return load_config(list({w.split("=", 1)[0]: w for w in TINY + list(extra)}.values()))


def save_tiny(path, cfg: Config) -> tuple[DFTransformer, dict]:
    torch.manual_seed(0)
    model = DFTransformer.from_config(cfg.model, cfg.n_tokens)
    manifest = save_checkpoint(path, model, {
        "config": cfg.to_dict(), "dataset_digest": "abc123", "data_seed": 0, "git_sha": "unknown",
        "train_steps": 7, "wall_time_s": 1.5, "final_losses": {"train": 0.5, "val": 0.6},
        "normaliser": {"mean": np.array([10.2, 9.5]), "std": [5.8, 5.2]},
    })
    return model, manifest


def test_round_trip(tmp_path):
    cfg = tiny_cfg()
    model, manifest = save_tiny(tmp_path / "ck", cfg)
    assert set(p.name for p in (tmp_path / "ck").iterdir()) == {MODEL_FILE, MANIFEST_FILE}  # no *.tmp left
    loaded, m2 = load_checkpoint(tmp_path / "ck", cfg, expect_digest=manifest["digest"])
    assert m2 == json.loads(json.dumps(manifest, default=lambda o: o.tolist()))
    for k, v in model.state_dict().items():
        assert torch.equal(v, loaded.state_dict()[k])
    assert m2["param_count"] == model.num_params() and m2["n_tokens"] == 11 and m2["token_dim"] == 20
    assert m2["model_sha256"] == sha256_file(tmp_path / "ck" / MODEL_FILE) and m2["model_kind"] == "df"
    torch.load(tmp_path / "ck" / MODEL_FILE, weights_only=True)  # plain tensors only
    norm = normaliser_from_manifest(m2)
    np.testing.assert_allclose(norm.mean, [10.2, 9.5])
    den = LocalDenoiser.from_checkpoint(tmp_path / "ck", cfg, device="cpu", micro_batch=2)
    assert den.digest == manifest["digest"] and den.micro_batch == 2


def test_corrupt_model_file(tmp_path):
    cfg = tiny_cfg()
    save_tiny(tmp_path, cfg)
    raw = bytearray((tmp_path / MODEL_FILE).read_bytes())
    raw[len(raw) // 2] ^= 0xFF
    (tmp_path / MODEL_FILE).write_bytes(bytes(raw))
    with pytest.raises(CheckpointError, match="sha256"):
        load_checkpoint(tmp_path, cfg)


def test_wrong_expected_digest(tmp_path):
    cfg = tiny_cfg()
    save_tiny(tmp_path, cfg)
    with pytest.raises(CheckpointError, match="digest"):
        load_checkpoint(tmp_path, cfg, expect_digest="0" * 16)


@pytest.mark.parametrize("override, field", [
    ("jump=1", "jump"),  # also changes n_tokens; jump is named first
    ("model.width=64", "model.width"),
    ("env=pointmaze-large", "env.name"),
    ("env.horizon=1000", "n_tokens"),
    ("diffusion.beta_schedule=cosine", "diffusion.beta_schedule"),  # a sampler on another noise schedule
    ("diffusion.timesteps=100", "diffusion.timesteps"),
])
def test_config_mismatch_names_the_field(tmp_path, override, field):
    save_tiny(tmp_path, tiny_cfg())
    other = tiny_cfg(override, *(["env.max_steps=1000", "data.train_window=1000"] if "horizon" in override else []))
    with pytest.raises(CheckpointError) as err:
        load_checkpoint(tmp_path, other)
    msg = str(err.value)
    assert f"{field}=" in msg and "jobs/train.py" in msg


def test_missing_dir_and_files(tmp_path):
    with pytest.raises(CheckpointError, match="does not exist.*jobs/train.py env=pointmaze-medium jump=5"):
        load_checkpoint(tmp_path / "nope", tiny_cfg())
    save_tiny(tmp_path, tiny_cfg())
    (tmp_path / MANIFEST_FILE).unlink()
    with pytest.raises(CheckpointError, match="manifest.json does not exist"):
        load_checkpoint(tmp_path)


def test_train_state_round_trip_weights_only(tmp_path):
    rng = np.random.default_rng(3)
    gen = torch.Generator().manual_seed(5)
    opt_state = {"state": {0: {"step": torch.tensor(3.0), "exp_avg": torch.ones(2)}}, "param_groups": [{"lr": 1e-3}]}
    save_train_state(tmp_path, {"step": 3, "numpy_rng": rng.bit_generator.state, "torch_rng": gen.get_state(),
                                "optimizer": opt_state, "history": {"val": [[1, 0.5]]}})
    st = load_train_state(tmp_path)
    assert st["step"] == 3 and st["history"]["val"] == [[1, 0.5]]
    rng2 = np.random.default_rng(0)
    rng2.bit_generator.state = st["numpy_rng"]
    assert rng2.random() == rng.random()
    gen2 = torch.Generator()
    gen2.set_state(st["torch_rng"])
    assert torch.equal(torch.rand(4, generator=gen2), torch.rand(4, generator=gen))
    assert load_train_state(tmp_path / "none") is None


def test_a_manifest_without_a_noise_schedule_loads_under_any(tmp_path):
    """Manifests of models that do not denoise carry no diffusion block: nothing to compare, nothing refused."""
    save_tiny(tmp_path, tiny_cfg())
    manifest = json.loads((tmp_path / MANIFEST_FILE).read_text())
    del manifest["config"]["diffusion"]
    (tmp_path / MANIFEST_FILE).write_text(json.dumps(manifest))
    load_checkpoint(tmp_path, tiny_cfg("diffusion.beta_schedule=cosine"))
