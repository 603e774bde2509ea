"""jobs/gpu/gpu_check.py --dry-run: the prepared GPU speed check keeps working on CPU (tiny sizes)."""

import subprocess
import sys

import pytest

from fmctd_dist.config import REPO_ROOT


@pytest.mark.slow
def test_gpu_check_dry_run_writes_its_tables(tmp_path):
    out = subprocess.run([sys.executable, "jobs/gpu/gpu_check.py", str(tmp_path), "--dry-run"], cwd=REPO_ROOT,
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]
    throughput = (tmp_path / "throughput.md").read_text()
    assert "| 3 | 2 |" in throughput and "bf16" in throughput and "GFLOP/s" in throughput
    compiled = (tmp_path / "compiled.md").read_text()
    assert "| 3 | 2 |" in compiled and "compiled: jobs/s" in compiled
    plans = (tmp_path / "plans.md").read_text()
    assert "| mctd |" in plans and "| fast-mctd |" in plans and "time / fast-mctd" in plans
