"""The repository: its root, paths under it, and its commit (recorded in manifests and result rows)."""

from __future__ import annotations

import subprocess
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]
CONFIG_DIR = REPO_ROOT / "configs"


def resolve_path(p: str | Path) -> Path:
    """``p`` itself when absolute, else under the repository root."""
    p = Path(p).expanduser()
    return p if p.is_absolute() else REPO_ROOT / p


def git(*args: str) -> str | None:
    """``git args`` run in the repository -> its stdout, or None when git fails or is missing."""
    try:
        out = subprocess.run(["git", *args], cwd=REPO_ROOT, capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() if out.returncode == 0 else None


def git_sha() -> str:
    """The repository's HEAD commit, recorded in manifests and result rows ("unknown" outside git)."""
    return git("rev-parse", "HEAD") or "unknown"
