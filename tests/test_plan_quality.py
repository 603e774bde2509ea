"""jobs/bench/quality_curve.py on a maze model: the plan-level numbers, their relations, the digest cache."""

from __future__ import annotations

import json
import shutil

from conftest import load_job


def test_quality_curve_measures_a_maze_checkpoint_once(tiny_checkpoint, tmp_path, one_torch_thread):
    _, ckpt = tiny_checkpoint
    run = tmp_path / "run"
    shutil.copytree(ckpt, run, ignore=shutil.ignore_patterns("quality.json", "train_state.pt"))
    job = load_job("quality_curve")
    ((name, row),) = job.points(run)
    assert name == "latest" and row["digest"] == json.loads((run / "manifest.json").read_text())["digest"]
    for key in ("unguided_no_warp", "guided_no_warp", "guided_valid", "unguided_valid", "guided_first_warp"):
        assert 0.0 <= row[key] <= 1.0, key
    # valid = warp-free AND crossing no wall, so never above warp-free; a first-step warp is a warp
    assert row["guided_valid"] <= row["guided_no_warp"] and row["unguided_valid"] <= row["unguided_no_warp"]
    assert row["guided_first_warp"] <= 1.0 - row["guided_no_warp"]
    cached = json.loads((run / "quality.json").read_text())
    assert cached["guided_valid"] == row["guided_valid"]
    (run / "quality.json").write_text(json.dumps({**cached, "guided_no_warp": -1.0}))
    assert job.points(run)[0][1]["guided_no_warp"] == -1.0  # read from the cache, not measured again
    assert "guided valid (no warp, no wall)" in job.table(run, job.points(run))
