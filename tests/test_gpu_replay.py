"""jobs/gpu/gpu_replay.py --dry-run: the prepared GPU replay of the committed traces keeps working on CPU (the
first call of two medium traces, real checkpoints), and writes its projected-vs-measured table."""

import subprocess
import sys
import tarfile

import pytest

from fmctd_dist.config import REPO_ROOT


@pytest.mark.slow
def test_gpu_replay_dry_run_writes_projected_beside_measured(tmp_path):
    out = subprocess.run([sys.executable, "jobs/gpu/gpu_replay.py", str(tmp_path), "--dry-run"], cwd=REPO_ROOT,
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]
    table = (tmp_path / "replay.md").read_text()
    for line in ("| pointmaze-medium | fast-mctd | call | 1 |", "| pointmaze-medium | mctd | call | 1 |",
                 "| pointmaze-medium | fast-mctd | trace | 1 |", "MCTD / Fast-MCTD: projected"):
        assert line in table, table
    with tarfile.open(tmp_path / "detail.tar") as tar:
        names = tar.getnames()
    assert "detail/pointmaze-medium/replay-cpu-call.md" in names and "detail/log-1.txt" in names, names
    assert sorted(p.name for p in tmp_path.iterdir()) == ["detail.tar", "replay.md"]  # <= 8 files come back
