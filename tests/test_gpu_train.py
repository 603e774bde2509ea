"""jobs/gpu_train.py --dry-run: the prepared GPU training script keeps working on CPU (tiny data and model)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def test_gpu_train_dry_run_writes_a_checkpoint_per_maze(tmp_path):
    out = tmp_path / "out"
    cmd = [sys.executable, "jobs/gpu_train.py", str(out), "--dry-run", "--runs", str(tmp_path / "runs")]
    done = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=600,
                          env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    files = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    mazes = ("medium", "large", "giant")
    assert files == sorted([f"pointmaze-{m}-h5/{n}" for m in mazes for n in ("model.pt", "manifest.json")]
                           + ["train_logs.txt"])
    assert len(files) <= 8 and all((out / f).stat().st_size <= 16 * 2**20 for f in files)  # the device's limits
    for m in mazes:
        manifest = json.loads((out / f"pointmaze-{m}-h5" / "manifest.json").read_text())
        assert manifest["config"]["env"]["name"] == f"pointmaze-{m}" and manifest["config"]["jump"] == 5
        assert manifest["config"]["train"]["time_budget_s"] == 2.0 and manifest["train_steps"] > 0
