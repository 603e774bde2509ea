"""jobs/bench/bench_recipe.py: a tiny bench end to end as a subprocess, and where its table goes in results.md."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from conftest import TINY_DATA, TINY_MODEL, load_job

REPO = Path(__file__).resolve().parent.parent


def bench_module():
    return load_job("bench_recipe")


def test_tiny_bench_trains_evaluates_and_appends_its_table(tiny_dataset, tmp_path):
    data_cfg, _ = tiny_dataset
    words = TINY_DATA + TINY_MODEL + [f"data.root={data_cfg.data.root}", "env.max_steps=100", "jump=5",
                                      "train.batch_size=16", "train.val_batches=1", "train.warmup=10",
                                      "method.budget=16", "method.parallel=4"]
    doc = tmp_path / "results.md"
    doc.write_text("## 4. Denoiser quality\n\nold text\n\n## 5. Next section\n")
    cmd = [sys.executable, "jobs/bench/bench_recipe.py", "--tag", "smoke", "--budget-s", "2", "--tasks", "1",
           "--seeds", "0",
           "--runs-dir", str(tmp_path / "runs"), "--results-out", str(tmp_path / "results"), "--doc", str(doc),
           "--episode-limit-s", "30", "--arm", "base:", "--arm", "v:model.param=v",
           "--arm", "vnet@v:diffusion.guidance_path=network", *words]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    out = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=600, env=env)
    assert out.returncode == 0, out.stderr[-3000:]
    lines = [ln for ln in out.stdout.splitlines() if ln.startswith("| ")]
    assert [ln.split(" | ")[0] for ln in lines[1:]] == ["| base", "| v", "| vnet"]
    for arm in ("base", "v"):
        manifest = json.loads((tmp_path / "runs" / "smoke" / arm / "manifest.json").read_text())
        assert manifest["config"]["train"]["time_budget_s"] == 2.0 and manifest["wall_time_s"] >= 2.0
        assert manifest["config"]["train"]["threads"] == 1
    v, vnet = (json.loads((tmp_path / "runs" / "smoke" / a / "bench.json").read_text()) for a in ("v", "vnet"))
    assert v["digest"] == vnet["digest"] and not (tmp_path / "runs" / "smoke" / "vnet" / "manifest.json").exists()
    assert v["fast_mctd_episodes"] == 1 and 0 <= v["unguided_no_warp"] <= 1
    assert v["guided_first_warp"] <= 1 - v["guided_no_warp"]  # a plan that warps at its first step warps
    assert v["guided_valid"] <= min(v["guided_no_warp"], v["guided_wall_free"])  # valid: both
    assert (tmp_path / "results" / "recipe-smoke-vnet" / "fast-mctd").is_dir()
    text = doc.read_text()
    assert text.index("old text") < text.index("### Recipe bench") < text.index("| vnet") < text.index("## 5. Next")
    assert "--arm vnet@v:diffusion.guidance_path=network" in text

    again = subprocess.run(cmd[:-len(words)] + ["--doc", ""] + words, cwd=REPO, capture_output=True, text=True,
                           timeout=300, env=env)  # resumes: trained and evaluated arms are read back
    assert again.returncode == 0, again.stderr[-3000:]
    assert [ln for ln in again.stdout.splitlines() if ln.startswith("| ")] == lines


def test_a_second_bench_run_goes_under_the_same_subsection(tmp_path):
    bench = bench_module()
    path = tmp_path / "r.md"
    path.write_text("## 4. Q\n\nx\n\n## 5. N\n\ny\n")
    bench.append_to_doc(path, "first table\n")
    bench.append_to_doc(path, "second table\n")
    text = path.read_text()
    assert text.count(bench.SECTION) == 1
    assert text.index("x") < text.index("first table") < text.index("second table") < text.index("## 5. N")
