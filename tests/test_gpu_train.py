"""jobs/gpu/gpu_train.py --dry-run: the prepared GPU training script keeps working on CPU (tiny data and model)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tarfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "jobs" / "gpu"))

from fmctd_dist.cli_words import merge  # noqa: E402
from gpu_train import MAX_TARS, SETS, VISUAL_START, XY_START, pack_all  # noqa: E402


def test_gpu_train_dry_run_packs_one_tar_per_model(tmp_path):
    out = tmp_path / "out"
    cmd = [sys.executable, "jobs/gpu/gpu_train.py", str(out), "--dry-run", "--runs", str(tmp_path / "runs")]
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


def test_campaign_set_continues_the_shipped_pointmaze_models():
    """The campaign set continues each shipped PointMaze model (the default checkpoint of its env and jump; the
    campaign-* snapshots it once named held the same bytes) with the recipe levers that model's manifest records."""
    for name, words in SETS["campaign"]:
        assert f"train.init_from=checkpoints/{name}" in words
        manifest = json.loads((REPO / "checkpoints" / name / "manifest.json").read_text())
        maze, jump = name.rsplit("-h", 1)
        assert manifest["config"]["env"]["name"] == maze and manifest["config"]["jump"] == int(jump)
        train = manifest["config"]["train"]
        levers = {k: float(v) for k, v in (w.split("=", 1) for w in words) if k in ("train.boundary_weight",
                                                                                  "train.clean_context")}
        assert levers.get("train.boundary_weight", 0.0) == train["boundary_weight"]
        assert levers.get("train.clean_context", 0.0) == train["clean_context"]


def test_merge_keeps_the_last_value_of_each_key():
    assert merge(["device=cuda", "train.batch_size=1024"], ["device=cpu"]) == ["device=cpu", "train.batch_size=1024"]


def test_ant_set_dry_run_makes_its_data_with_workers_and_fine_tunes(tmp_path):
    """The ant set's chain on CPU: the tiny ant dataset made by 2 worker processes, one model packed."""
    out = tmp_path / "out"
    cmd = [sys.executable, "jobs/gpu/gpu_train.py", str(out), "--dry-run", "--set", "ant",
           "--only", "antmaze-medium-h5", "--data-workers", "2", "--runs", str(tmp_path / "runs")]
    done = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=600,
                          env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    with tarfile.open(out / "antmaze-medium-h5.tar") as tar:
        manifest = json.load(tar.extractfile("antmaze-medium-h5/manifest.json"))
    train = manifest["config"]["train"]
    assert (manifest["config"]["env"]["name"] == "antmaze-medium" and train["boundary_weight"] == 3.0
            and train["wall_weight"] == 0.1 and manifest["wall_depth"]["maze"] == "antmaze-medium")
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
    cmd = [sys.executable, "jobs/gpu/gpu_train.py", str(out), "--dry-run", "--set", "visual-latent", "--only",
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


def test_visual_latent_set_continues_each_mazes_best_committed_latent_model():
    assert [n for n, _ in SETS["visual-latent"]] == ["visual-pointmaze-medium-h5", "visual-pointmaze-large-h5",
                                                     "visual-pointmaze-medium-h1", "visual-pointmaze-large-h1"]
    for name, words in SETS["visual-latent"]:
        maze = name.rsplit("-h", 1)[0].removeprefix("visual-pointmaze-")
        start = VISUAL_START[maze]
        assert f"train.init_from={start}" in words and "visual.episodes=100" in words
        manifest = json.loads((REPO / start / "manifest.json").read_text())
        assert manifest["config"]["env"]["name"] == f"visual-pointmaze-{maze}" and manifest["config"]["jump"] == 5


def test_visual_set_continues_the_shipped_xy_planners_with_their_recipe():
    """The [z, x, y] planners (visual.plan_xy) continue the shipped ones, named as Config.run_name names them; the
    dense large one starts from the sparse large one, which is also a plan_xy model of the same maze."""
    assert [n for n, _ in SETS["visual"]] == ["visual-pointmaze-medium-h5-xy", "visual-pointmaze-large-h5-xy",
                                              "visual-pointmaze-medium-h1-xy", "visual-pointmaze-large-h1-xy"]
    for name, words in SETS["visual"]:
        maze, jump = name.removeprefix("visual-pointmaze-").removesuffix("-xy").rsplit("-h", 1)
        start = XY_START[maze, int(jump)]
        assert f"train.init_from={start}" in words and "visual.plan_xy=true" in words and f"jump={jump}" in words
        manifest = json.loads((REPO / start / "manifest.json").read_text())
        assert manifest["config"]["env"]["name"] == f"visual-pointmaze-{maze}" and manifest["latents"]["plan_xy"]
        train = manifest["config"]["train"]
        assert all(f"train.{k}={v:g}" in words for k, v in train.items() if k in ("boundary_weight", "position_weight"))
        assert f"train.boundary_space={train['boundary_space']}" in words


def _fake_run(runs: Path, name: str, snapshot: bool = True) -> None:
    for d in [runs / name] + ([runs / name / "snapshots" / "k0001000"] if snapshot else []):
        d.mkdir(parents=True)
        (d / "model.pt").write_bytes(b"w" * 1000)
        (d / "manifest.json").write_text(json.dumps({"train_steps": 7, "digest": name}))


def test_pack_all_keeps_one_tar_per_model_up_to_seven_then_shares_tars(tmp_path):
    """Up to MAX_TARS models: one tar each with its snapshot; more (sets joined by commas): they share at most
    MAX_TARS tars without snapshots, so the tars and train_logs.txt stay within the device's 8 files."""
    few, many = [f"m{i}" for i in range(3)], [f"n{i}" for i in range(MAX_TARS + 3)]
    for name in few + many:
        _fake_run(tmp_path / "runs", name)
    _fake_run(tmp_path / "runs", "late", snapshot=False)
    (tmp_path / "a").mkdir()
    lines = pack_all(few + ["missing"], tmp_path / "runs", tmp_path / "a")
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == ["m0.tar", "m1.tar", "m2.tar"]
    with tarfile.open(tmp_path / "a" / "m1.tar") as tar:
        assert sorted(tar.getnames()) == ["m1/manifest.json", "m1/model.pt", "m1/snapshots/k0001000/manifest.json",
                                          "m1/snapshots/k0001000/model.pt"]
    assert lines[-1] == "no model.pt" and "2 checkpoint(s) in m0.tar" in lines[0]
    (tmp_path / "b").mkdir()
    lines = pack_all(many + ["late"], tmp_path / "runs", tmp_path / "b")
    tars = sorted((tmp_path / "b").iterdir())
    assert len(tars) <= MAX_TARS and all(t.name.startswith("models-") for t in tars)
    names = []
    for t in tars:
        with tarfile.open(t) as tar:
            names += tar.getnames()
    assert sorted(names) == sorted(f"{n}/{f}" for n in many + ["late"] for f in ("model.pt", "manifest.json"))
    assert all("1 checkpoint(s) in models-" in line for line in lines)


def test_sets_join_with_commas_and_an_unknown_set_is_named(tmp_path):
    cmd = [sys.executable, "jobs/gpu/gpu_train.py", str(tmp_path / "out"), "--set", "ant,visual,nope", "--dry-run"]
    done = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=60)
    assert done.returncode != 0 and "no set nope" in done.stderr and not (tmp_path / "out").exists()


N100_LARGE = sorted((REPO / "data").glob("visual-pointmaze-large-latents-seed0-n100-*/latents.npz"))


@pytest.mark.skipif(not N100_LARGE, reason="no 100-episode visual-large latent store in data/ (section 13.4 makes it)")
def test_xy_set_dry_run_trains_a_plan_xy_model_on_the_carried_store(tmp_path):
    """What a lease runs for the visual maze: the [z, x, y] planner on the carried store, no data made."""
    out = tmp_path / "out"
    cmd = [sys.executable, "jobs/gpu/gpu_train.py", str(out), "--dry-run", "--set", "ant,visual", "--only",
           "visual-pointmaze-large-h5-xy", "--runs", str(tmp_path / "runs"), f"data.root={REPO / 'data'}"]
    done = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=600,
                          env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    with tarfile.open(out / "visual-pointmaze-large-h5-xy.tar") as tar:
        manifest = json.load(tar.extractfile("visual-pointmaze-large-h5-xy/manifest.json"))
    assert manifest["config"]["env"]["name"] == "visual-pointmaze-large" and manifest["latents"]["plan_xy"]
    assert manifest["config"]["train"]["boundary_space"] == "position"


def test_a_second_call_continues_each_model_from_the_first_calls_runs(tmp_path):
    """--continue-from: what a second call on the warm machine runs (each model from the last call's weights)."""
    runs = tmp_path / "runs"
    first = [sys.executable, "jobs/gpu/gpu_train.py", str(tmp_path / "a"), "--dry-run", "--only", "pointmaze-medium-h5",
             "--runs", str(runs)]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    assert subprocess.run(first, cwd=REPO, capture_output=True, timeout=600, env=env).returncode == 0
    second = first[:2] + [str(tmp_path / "b"), "--dry-run", "--only", "pointmaze-medium-h5", "--runs",
                          str(tmp_path / "runs2"), "--continue-from", str(runs), f"data.root={runs / 'data'}"]
    done = subprocess.run(second, cwd=REPO, capture_output=True, text=True, timeout=600, env=env)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    manifest = json.loads((tmp_path / "runs2" / "pointmaze-medium-h5" / "manifest.json").read_text())
    assert manifest["init_from"]["path"] == str(runs / "pointmaze-medium-h5")
    missing = second[:-3] + ["--continue-from", str(tmp_path / "nowhere")]
    done = subprocess.run(missing, cwd=REPO, capture_output=True, text=True, timeout=60, env=env)
    assert done.returncode != 0 and "no model.pt for pointmaze-medium-h5" in done.stderr
