"""Training loop: losses finite, checkpoints written, resume continues exactly where it stopped."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from fmctd_dist.config import Config, load_config
from fmctd_dist.tokens import Normaliser
from fmctd_dist.diffusion.checkpoint import load_checkpoint
from fmctd_dist.resume import load_train_state
from fmctd_dist.diffusion.model import DFTransformer
from fmctd_dist.diffusion.train import DFLoss, lr_at, train
from fmctd_dist.errors import CheckpointError

pytestmark = pytest.mark.usefixtures("one_torch_thread")



class FakeData:
    """64 straight-line windows (token 0 = start repeated), normalised; enough to learn something."""

    def __init__(self, n_tokens: int = 11, frame_stack: int = 10, seed: int = 0, digest: str = "fake-digest"):
        rng = np.random.default_rng(seed)
        start = rng.uniform(-1, 1, (64, 1, 2))
        vel = rng.uniform(-0.05, 0.05, (64, 1, 2))
        frames = start + vel * np.arange((n_tokens - 1) * frame_stack)[None, :, None]
        plan = frames.reshape(64, n_tokens - 1, 2 * frame_stack)
        ctx = np.tile(start, (1, 1, frame_stack))
        self.windows = np.concatenate([ctx, plan], axis=1).astype(np.float32)
        self.normaliser = Normaliser.from_lists([0.0, 0.0], [1.0, 1.0])
        self.digest, self.seed = digest, seed

    def sample(self, rng: np.random.Generator, batch: int) -> np.ndarray:
        return self.windows[rng.integers(0, len(self.windows), batch)]

    def val_batches(self, n: int, batch: int) -> list[np.ndarray]:
        rng = np.random.default_rng(99)
        return [self.sample(rng, batch) for _ in range(n)]


def tiny_cfg(max_steps: int, *extra: str) -> Config:
    """The tiny config; ``extra`` words replace the defaults of the keys they name."""
    words = ["model.width=32", "model.layers=2", "model.heads=2", "model.ff=64",
             f"train.max_steps={max_steps}", "train.batch_size=8", "train.warmup=5",
             "train.ckpt_every=10", "train.val_every=10", "train.val_batches=2", *extra]
    return load_config(list({w.split("=", 1)[0]: w for w in words}.values()))


def test_train_resume_continues_from_saved_step(tmp_path):
    data = FakeData()
    out = train(tiny_cfg(20), data, tmp_path, progress=False)
    assert out["step"] == 20 and out["resumed_from"] is None
    assert np.isfinite(out["final_losses"]["train"]) and np.isfinite(out["final_losses"]["val"])
    saved = load_train_state(tmp_path)
    assert saved["step"] == 20
    model, manifest = load_checkpoint(tmp_path, tiny_cfg(20))
    assert manifest["train_steps"] == 20 and manifest["dataset_digest"] == "fake-digest"
    assert [s for s, _ in manifest["val_history"]] == [10, 20]
    assert manifest["vs_paper"].startswith("20 of the paper's 200005 steps")  # what was traded, in words

    # The optimiser state that resume will restore is the one that was saved.
    opt_saved = saved["optimizer"]["state"]
    fresh = torch.optim.AdamW(model.parameters())
    fresh.load_state_dict(saved["optimizer"])
    for i, st in fresh.state_dict()["state"].items():
        assert torch.equal(st["exp_avg"], opt_saved[i]["exp_avg"]) and float(st["step"]) == 20

    out2 = train(tiny_cfg(30), data, tmp_path, progress=False)
    assert out2["step"] == 30 and out2["resumed_from"] == 20 and np.isfinite(out2["final_losses"]["train"])
    after = load_train_state(tmp_path)
    assert after["step"] == 30 and all(float(s["step"]) == 30 for s in after["optimizer"]["state"].values())
    assert [s for s, _ in after["history"]["val"]] == [10, 20, 30]

    again = train(tiny_cfg(30), data, tmp_path, progress=False)  # finished: returns at once
    assert again["step"] == 30 and again["resumed_from"] == 30


def test_killed_run_resumes_to_the_same_weights(tmp_path):
    data = FakeData()
    train(tiny_cfg(20), data, tmp_path / "straight", progress=False)
    train(tiny_cfg(10), data, tmp_path / "killed", progress=False)  # "killed" after its step-10 checkpoint
    train(tiny_cfg(20), data, tmp_path / "killed", progress=False)
    a, b = load_train_state(tmp_path / "straight"), load_train_state(tmp_path / "killed")
    for k in a["model"]:
        assert torch.equal(a["model"][k], b["model"][k]), k
    for i in a["optimizer"]["state"]:
        assert torch.equal(a["optimizer"]["state"][i]["exp_avg_sq"], b["optimizer"]["state"][i]["exp_avg_sq"])
    assert a["history"]["val"] == b["history"]["val"]


def test_resume_refuses_other_data_or_architecture(tmp_path):
    train(tiny_cfg(10), FakeData(), tmp_path, progress=False)
    with pytest.raises(CheckpointError, match="dataset"):
        train(tiny_cfg(20), FakeData(digest="other"), tmp_path, progress=False)
    with pytest.raises(CheckpointError, match="model.layers"):
        train(tiny_cfg(20, "model.layers=3"), FakeData(), tmp_path, progress=False)


def test_loss_pieces():
    cfg = tiny_cfg(1)
    assert lr_at(cfg, 0) == pytest.approx(cfg.train.lr / 5) and lr_at(cfg, 4) == cfg.train.lr == lr_at(cfg, 100)
    loss_fn = DFLoss(cfg, torch.device("cpu"))
    assert loss_fn.w_snr.max() == pytest.approx(5.0) and loss_fn.w_snr[-1] < 1e-3  # min(SNR, 5)
    torch.manual_seed(0)
    model = DFTransformer.from_config(cfg.model, cfg.n_tokens)
    x0 = torch.as_tensor(FakeData().windows[:4])
    l1 = loss_fn(model, x0, torch.Generator().manual_seed(1))
    l2 = loss_fn(model, x0, torch.Generator().manual_seed(1))
    assert torch.isfinite(l1) and torch.equal(l1, l2)


def test_shipped_checkpoint_without_train_state_is_continued_not_overwritten(tmp_path):
    """Shipped dirs hold model.pt + manifest only; training there warm-starts from them."""
    data = FakeData()
    train(tiny_cfg(10), data, tmp_path, progress=False)
    (tmp_path / "train_state.pt").unlink()
    shipped, _ = load_checkpoint(tmp_path, tiny_cfg(10))
    again = train(tiny_cfg(10), data, tmp_path, progress=False)  # already at max_steps: untouched
    assert again["step"] == 10 and again["resumed_from"] == 10
    out = train(tiny_cfg(20), data, tmp_path, progress=False)
    assert out["resumed_from"] == 10 and out["step"] == 20
    model, manifest = load_checkpoint(tmp_path, tiny_cfg(20))
    assert manifest["train_steps"] == 20
    assert not torch.equal(model.state_dict()["out.weight"], shipped.state_dict()["out.weight"])
    with pytest.raises(CheckpointError, match="dataset"):
        (tmp_path / "train_state.pt").unlink()
        train(tiny_cfg(30), FakeData(digest="other"), tmp_path, progress=False)


def test_init_from_starts_a_new_env_and_horizon_from_another_checkpoints_weights(tmp_path):
    src, dst = tmp_path / "point", tmp_path / "ant"
    train(tiny_cfg(10), FakeData(), src, progress=False)
    _, src_manifest = load_checkpoint(src, tiny_cfg(10))
    # another maze, horizon (21 tokens instead of 11) and dataset; lr 1e-30 (> 0, the field's range) keeps the
    # float32 weights as loaded
    cfg = tiny_cfg(10, "env=pointmaze-giant", f"train.init_from={src}", "train.lr=1e-30")
    train(cfg, FakeData(n_tokens=21, digest="other-data"), dst, progress=False)
    model, manifest = load_checkpoint(dst, cfg)
    source, _ = load_checkpoint(src, tiny_cfg(10))
    assert all(torch.equal(a, b) for a, b in zip(model.state_dict().values(), source.state_dict().values()))
    assert manifest["init_from"]["digest"] == src_manifest["digest"] and manifest["init_from"]["train_steps"] == 10
    assert "started from the weights of" in manifest["vs_paper"]
    # the training behind the weights counts the ancestor's steps and CPU time, and a grandchild counts both
    assert manifest["lineage_steps"] == 20
    assert manifest["lineage_cpu_s"] == pytest.approx(manifest["cpu_time_s"] + src_manifest["cpu_time_s"])
    grand = tiny_cfg(5, "env=pointmaze-giant", f"train.init_from={dst}", "train.lr=1e-30", "train.batch_size=4")
    train(grand, FakeData(n_tokens=21, digest="other-data"), tmp_path / "grand", progress=False)
    _, g = load_checkpoint(tmp_path / "grand", grand)
    assert g["init_from"]["lineage_steps"] == 20 and g["lineage_steps"] == 25
    assert g["lineage_cpu_s"] == pytest.approx(g["cpu_time_s"] + manifest["lineage_cpu_s"])
    # samples: each run's steps at its own batch size (a CPU run continued on a GPU changes it)
    batch = lambda m: m["config"]["train"]["batch_size"]  # noqa: E731
    assert manifest["lineage_samples"] == 10 * batch(manifest) + 10 * batch(src_manifest)
    assert g["lineage_samples"] == 5 * batch(g) + manifest["lineage_samples"]


def test_lineage_of_a_manifest_from_before_the_field():
    """Provenance written before lineage existed kept the parent's steps but not its CPU time: the steps
    still add up, the hours say unknown (None) rather than a number too small."""
    from fmctd_dist.diffusion.checkpoint import lineage

    old_child = {"train_steps": 3654, "cpu_time_s": 2100.0, "init_from": {"digest": "9c01", "train_steps": 6000}}
    assert lineage(old_child) == {"lineage_steps": 9654, "lineage_cpu_s": None, "lineage_samples": None}
    assert lineage({"train_steps": 10, "wall_time_s": 5.0}) == {"lineage_steps": 10, "lineage_cpu_s": 5.0,
                                                                "lineage_samples": None}


def test_lineage_reads_an_ancestor_still_on_disk(tmp_path):
    """A record made from an old parent (whose own ancestor it could not see) undercounts; the parent's
    manifest, still on disk under the recorded path and digest, is read again. Other weights at that path
    (the digest differs) are not."""
    from fmctd_dist.diffusion.checkpoint import lineage

    parent = {"digest": "p", "train_steps": 7769, "cpu_time_s": 2100.0,
              "init_from": {"digest": "gone", "train_steps": 6000}}  # written before the lineage fields
    (tmp_path / "parent").mkdir()
    (tmp_path / "parent" / "manifest.json").write_text(json.dumps(parent))
    child = {"train_steps": 1000, "cpu_time_s": 10.0,
             "init_from": {"digest": "p", "path": str(tmp_path / "parent"), "train_steps": 7769, "lineage_steps": 7769}}
    assert lineage(child) == {"lineage_steps": 14769, "lineage_cpu_s": None, "lineage_samples": None}
    replaced = {**child, "init_from": {**child["init_from"], "digest": "other"}}
    assert lineage(replaced) == {"lineage_steps": 8769, "lineage_cpu_s": None, "lineage_samples": None}


def test_lineage_finds_an_ancestor_whose_path_now_holds_other_weights(tmp_path, monkeypatch):
    """A shipped checkpoint swapped for its continuation no longer holds the ancestor a run recorded; the
    ancestor's manifest is found elsewhere (a run dir) by its digest."""
    from fmctd_dist.diffusion import checkpoint

    for name, record in (("shipped", {"digest": "new", "train_steps": 5}),
                         ("moved", {"digest": "p", "train_steps": 7769, "cpu_time_s": 2100.0,
                                    "init_from": {"digest": "root", "train_steps": 6000, "lineage_steps": 6000,
                                                  "lineage_cpu_s": 900.0}})):
        (tmp_path / name).mkdir()
        (tmp_path / name / "manifest.json").write_text(json.dumps(record))
    monkeypatch.setattr(checkpoint, "_manifests_by_digest", lambda: {"p": [tmp_path / "moved" / "manifest.json"]})
    child = {"train_steps": 1000, "cpu_time_s": 10.0,
             "init_from": {"digest": "p", "path": str(tmp_path / "shipped"), "train_steps": 7769}}
    assert checkpoint.lineage(child) == {"lineage_steps": 14769, "lineage_cpu_s": 3010.0, "lineage_samples": None}


def test_init_from_with_another_architecture_is_one_clear_error(tmp_path):
    train(tiny_cfg(10), FakeData(), tmp_path / "src", progress=False)
    cfg = tiny_cfg(10, "model.width=64", f"train.init_from={tmp_path / 'src'}")
    with pytest.raises(CheckpointError, match=r"model.width=32 but the config has model.width=64"):
        train(cfg, FakeData(), tmp_path / "dst", progress=False)


def test_snapshots_for_quality_curves(tmp_path, monkeypatch):
    """train.snapshot_every_s keeps loadable copies of the shipped weights; a resumed run neither repeats nor
    skips one (the folder says which exist)."""
    from fmctd_dist.diffusion import train as train_mod
    from fmctd_dist.resume import SNAPSHOTS, snapshot_due

    assert snapshot_due(tmp_path, 0.0, 1e9) is None and snapshot_due(tmp_path, 60.0, 59.0) is None
    assert snapshot_due(tmp_path, 60.0, 130.0) == "k002"
    clock = iter(range(0, 10_000, 7))  # a fake budget clock: 7 s more at every save
    monkeypatch.setattr(train_mod, "snapshot_due", lambda out, every, used: snapshot_due(out, every, next(clock)))
    cfg = tiny_cfg(30, "train.snapshot_every_s=10")
    train(cfg, FakeData(), tmp_path, progress=False)  # saves at steps 10, 20, 30: clock 0, 7, 14 -> k001 once
    snaps = sorted(p.name for p in (tmp_path / SNAPSHOTS).iterdir())
    assert snaps == ["k001-step0000030"]
    model, manifest = load_checkpoint(tmp_path / SNAPSHOTS / snaps[0], cfg)
    assert manifest["train_steps"] == 30
    train(tiny_cfg(50, "train.snapshot_every_s=10"), FakeData(), tmp_path, progress=False)  # 21, 28 -> k002
    assert sorted(p.name for p in (tmp_path / SNAPSHOTS).iterdir()) == ["k001-step0000030", "k002-step0000040"]
