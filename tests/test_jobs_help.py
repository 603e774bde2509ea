"""Every script under jobs/ prints its usage on ``--help`` and exits 0, without running anything.

Run in this process (``runpy``), so the imports are paid once for all scripts, not once per script."""

from __future__ import annotations

import contextlib
import io
import runpy
import subprocess
import sys
from pathlib import Path

import pytest

JOBS = Path(__file__).resolve().parent.parent / "jobs"
SCRIPTS = sorted(p.relative_to(JOBS.parent).as_posix() for p in JOBS.rglob("*.py"))
SUPPORTED_AT_MOST = 15  # the entry points a newcomer meets at the top of jobs/ (README, "Layout")


def test_the_top_of_jobs_holds_only_the_supported_entry_points():
    top = sorted(p.name for p in JOBS.iterdir() if p.is_file())
    assert len(top) <= SUPPORTED_AT_MOST, top
    assert {p.name for p in JOBS.iterdir() if p.is_dir() and p.name != "__pycache__"} <= {
        "bench", "figures", "probes", "gpu"}


@pytest.mark.parametrize("script", SCRIPTS)
def test_help_prints_the_usage(script, monkeypatch):
    path = JOBS.parent / script
    monkeypatch.setattr(sys, "argv", [str(path), "--help"])
    monkeypatch.syspath_prepend(str(path.parent))
    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit) as done:
        runpy.run_path(str(path), run_name="__main__")
    assert done.value.code in (0, None), out.getvalue()
    text = out.getvalue()
    assert len(text.splitlines()) >= 2, text
    if "usage:" not in text:  # argparse writes its own usage line; the others show their docstring's
        assert script in text, f"{script}'s usage does not name the script itself:\n{text}"


def test_paper_tables_help():
    done = subprocess.run(["bash", str(JOBS / "paper_tables.sh"), "--help"], capture_output=True, text=True,
                          timeout=30)
    assert done.returncode == 0 and "paper_tables.sh" in done.stdout, done
