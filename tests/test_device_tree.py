"""jobs/gpu/device_tree.py: what a device run sends, and slim / restore leaving checkpoints/ behind."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "jobs" / "gpu"))
import device_tree as dt  # noqa: E402


def git(repo: Path, *args: str) -> str:
    return subprocess.run(["git", *args], cwd=repo, check=True, capture_output=True, text=True).stdout


@pytest.fixture
def repo(tmp_path: Path) -> Path:
    git(tmp_path, "init", "-q")
    git(tmp_path, "config", "user.email", "t@t")
    git(tmp_path, "config", "user.name", "t")
    (tmp_path / "checkpoints" / "m").mkdir(parents=True)
    (tmp_path / "checkpoints" / "m" / "model.pt").write_bytes(b"w" * 5000)
    (tmp_path / "code.py").write_text("print(1)\n")
    (tmp_path / ".gitignore").write_text("runs/\n")
    (tmp_path / "runs").mkdir()
    (tmp_path / "runs" / "big.pt").write_bytes(b"x" * 9000)  # ignored: never travels
    git(tmp_path, "add", "-A")
    git(tmp_path, "commit", "-q", "-m", "init")
    (tmp_path / "notes.txt").write_text("untracked, not ignored: travels\n")
    return tmp_path


def names(repo: Path) -> set[str]:
    return {str(p.relative_to(repo)) for p in dt.travelling(repo)}


def test_slim_leaves_checkpoints_behind_and_restore_undoes_it(repo: Path):
    assert names(repo) == {".gitignore", "code.py", "notes.txt", "checkpoints/m/model.pt"}
    full, lines = dt.size_report(repo)
    assert "(full)" in lines[0] and full > 5000

    dt.slim(repo)
    assert names(repo) == {".gitignore", "code.py", "notes.txt"}
    assert (repo / "checkpoints" / "m" / "model.pt").read_bytes() == b"w" * 5000  # nothing deleted
    assert dt.is_slim(repo) and "slim" in dt.size_report(repo)[1][0]
    dt.slim(repo)  # twice is harmless: one exclude line
    assert dt.exclude_file(repo).read_text().count(dt.MARK) == 1

    dt.restore(repo)
    assert names(repo) == {".gitignore", "code.py", "notes.txt", "checkpoints/m/model.pt"}
    assert not dt.is_slim(repo) and git(repo, "status", "--porcelain") == "?? notes.txt\n"


def test_slim_refuses_uncommitted_checkpoint_changes(repo: Path):
    (repo / "checkpoints" / "m" / "model.pt").write_bytes(b"changed")
    with pytest.raises(SystemExit, match="uncommitted changes"):
        dt.slim(repo)
    assert not dt.is_slim(repo)


def test_this_repo_without_checkpoints_fits_the_device_limit():
    """Code, docs, tests and configs must stay far under the device's 64 MiB once checkpoints stay behind."""
    here = Path(__file__).resolve().parents[1]
    if not (here / ".git").exists():
        pytest.skip("not a git checkout")
    rest = sum(p.stat().st_size for p in dt.travelling(here) if p.relative_to(here).parts[0] != dt.LEFT_BEHIND)
    assert rest < dt.LIMIT / 4, f"{rest / 2**20:.1f} MiB travel besides checkpoints/"
