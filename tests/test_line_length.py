"""Every Python line of the package, the jobs and the tests fits in 120 characters, so code reads
side by side with its diff; there is no formatter in the toolchain to keep it so."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LIMIT = 120


def long_lines(files: list[Path]) -> list[str]:
    return [f"{f.relative_to(ROOT) if f.is_relative_to(ROOT) else f}:{i}: {len(line)} characters"
            for f in files for i, line in enumerate(f.read_text().splitlines(), 1) if len(line) > LIMIT]


def test_the_checker_finds_a_long_line(tmp_path):
    f = tmp_path / "m.py"
    f.write_text("x = 1\n" + "y = '" + "a" * LIMIT + "'\n")
    assert long_lines([f]) == [f"{f}:2: {LIMIT + 6} characters"]


def test_no_python_line_over_the_limit():
    files = sorted(p for d in ("fmctd_dist", "jobs", "tests") for p in (ROOT / d).rglob("*.py"))
    assert files and not long_lines(files), "\n".join(long_lines(files))
