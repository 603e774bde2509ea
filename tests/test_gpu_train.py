"""jobs/gpu_train.py --dry-run: the prepared GPU training script keeps working on CPU (tiny data and model)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tarfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "jobs"))

from cli_words import merge  # noqa: E402  (job scripts, not package modules)
from gpu_train import SETS, VISUAL_START  # noqa: E402


def test_gpu_train_dry_run_packs_one_tar_per_model(tmp_path):
    out = tmp_path / "out"
    cmd = [sys.executable, "jobs/gpu_train.py", str(out), "--dry-run", "--runs", str(tmp_path / "runs")]
    done = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=600,
                          env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    names = [n for n, _ in SETS["campaign"]]
    files = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    assert files == sorted([f"{n}.tar" for n in names] + ["train_logs.txt"])
    assert len(files) <= 8 and all((out / f).stat().st_size <= 16 * 2**20 for f in files)  # the device's limits
    for name in names:
        with tarfile.open(out / f"{name}.tar") as tar:
            members = tar.getnames()
            manifest = json.load(tar.extractfile(f"{name}/manifest.json"))
        assert f"{name}/model.pt" in members
        assert any(m.startswith(f"{name}/snapshots/k") and m.endswith("model.pt") for m in members)
        maze, jump = name.rsplit("-h", 1)
        train = manifest["config"]["train"]
        assert manifest["config"]["env"]["name"] == maze and manifest["config"]["jump"] == int(jump)
        assert train["time_budget_s"] == 2.0 and train["lr_schedule"] == "cosine" and manifest["train_steps"] > 0
        # each model keeps the recipe levers its campaign manifest records
        assert train["boundary_weight"] == (0.0 if name == "pointmaze-medium-h5" else 3.0)
        assert train["clean_context"] == (0.5 if name in ("pointmaze-large-h1", "pointmaze-giant-h1") else 0.0)
    assert "sha256" in (out / "train_logs.txt").read_text()


def test_campaign_set_starts_from_the_shipped_campaign_weights():
    for name, words in SETS["campaign"]:
        assert f"train.init_from=checkpoints/campaign-{name}" in words
        assert (REPO / "checkpoints" / f"campaign-{name}" / "manifest.json").exists()


def test_merge_keeps_the_last_value_of_each_key():
    assert merge(["device=cuda", "train.batch_size=1024"], ["device=cpu"]) == ["device=cpu", "train.batch_size=1024"]


def test_ant_set_dry_run_makes_its_data_with_workers_and_fine_tunes(tmp_path):
    """The ant set's chain on CPU: the tiny ant dataset made by 2 worker processes, one model packed."""
    out = tmp_path / "out"
    cmd = [sys.executable, "jobs/gpu_train.py", str(out), "--dry-run", "--set", "ant", "--only", "antmaze-medium-h5",
           "--data-workers", "2", "--runs", str(tmp_path / "runs")]
    done = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=600,
                          env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    with tarfile.open(out / "antmaze-medium-h5.tar") as tar:
        manifest = json.load(tar.extractfile("antmaze-medium-h5/manifest.json"))
    assert (manifest["config"]["env"]["name"] == "antmaze-medium"
            and manifest["config"]["train"]["boundary_weight"] == 3.0)
    data = json.loads(next((tmp_path / "runs" / "data").glob("antmaze-medium-*/manifest.json")).read_text())
    assert data["generation"]["workers"] == 2


def test_ant_set_starts_from_the_dense_ant_weights_and_needs_the_expert():
    """Sparse and dense ant models start from the committed dense ant model of their maze (results 11.11), whose
    architecture (frame stack, width, depth) is the one every jump of the set trains."""
    from fmctd_dist.config import load_config

    assert len(SETS["ant"]) == 6
    for name, words in SETS["ant"]:
        env = name.rsplit("-h", 1)[0]
        start = REPO / "checkpoints" / f"{env}-h1"
        assert f"train.init_from=checkpoints/{env}-h1" in words and f"env={env}" in words
        model = json.loads((start / "manifest.json").read_text())["config"]["model"]
        cfg = load_config([w for w in words if not w.startswith("train.init_from")], method="mctd")
        assert all(model[k] == getattr(cfg.model, k) for k in ("frame_stack", "width", "layers", "heads", "ff"))
    assert (REPO / "checkpoints" / "ant-expert").is_dir()


N20_STORE = sorted((REPO / "data").glob("visual-pointmaze-medium-latents-seed0-n20-*/latents.npz"))


@pytest.mark.skipif(not N20_STORE, reason="no 20-episode visual-medium latent store in data/ (section 13.3 makes it)")
def test_visual_set_dry_run_trains_on_a_carried_store_without_making_data(tmp_path):
    """The visual chain makes no dataset (the store is carried) and trains on the latents; the words after
    the options (here the 20-episode store and the repo's data root) override the set's."""
    out = tmp_path / "out"
    cmd = [sys.executable, "jobs/gpu_train.py", str(out), "--dry-run", "--set", "visual", "--only",
           "visual-pointmaze-medium-h5", "--runs", str(tmp_path / "runs"), "visual.episodes=20",
           f"data.root={REPO / 'data'}"]
    done = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=600,
                          env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    with tarfile.open(out / "visual-pointmaze-medium-h5.tar") as tar:
        manifest = json.load(tar.extractfile("visual-pointmaze-medium-h5/manifest.json"))
    assert manifest["config"]["env"]["name"] == "visual-pointmaze-medium" and manifest["token_dim"] == 80
    assert manifest["latents"]["vae_digest"] and not (tmp_path / "runs" / "logs"
                                                      / "data-visual-pointmaze-medium.log").exists()


def test_visual_set_continues_each_mazes_best_committed_visual_model():
    assert [n for n, _ in SETS["visual"]] == ["visual-pointmaze-medium-h5", "visual-pointmaze-large-h5",
                                              "visual-pointmaze-medium-h1", "visual-pointmaze-large-h1"]
    for name, words in SETS["visual"]:
        maze = name.rsplit("-h", 1)[0].removeprefix("visual-pointmaze-")
        start = VISUAL_START[maze]
        assert f"train.init_from={start}" in words and "visual.episodes=100" in words
        manifest = json.loads((REPO / start / "manifest.json").read_text())
        assert manifest["config"]["env"]["name"] == f"visual-pointmaze-{maze}" and manifest["config"]["jump"] == 5
