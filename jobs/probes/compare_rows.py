"""Compare two runs' rows episode by episode: outcomes, plans and identity must be bit for bit the same.

    python jobs/probes/compare_rows.py /tmp/rows_before/sample /tmp/rows_after/sample

For a refactor that must not change behaviour (issue 53 item 5): run ``jobs/probes/sample_rows.sh`` in a
worktree of each commit, then this. Timing columns (``*_s``, ``*time*``, shares, call counts) and the git
sha are left out; everything else (success, steps, plans, trajectories, config hash and JSON, digests) counts.
"""

import sys
from pathlib import Path

import pyarrow.parquet as pq

from fmctd_dist.cli import run


def timing(column: str) -> bool:
    return column.endswith("_s") or any(t in column for t in ("time", "share", "sha", "calls"))


def main(argv: list[str]) -> int:
    a, b = Path(argv[0]), Path(argv[1])
    files = sorted(p.relative_to(a) for p in a.rglob("seed=*.parquet"))
    same = 0
    for rel in files:
        ra = pq.read_table(a / rel).to_pylist()[0]
        rb = pq.read_table(b / rel).to_pylist()[0] if (b / rel).exists() else {}
        diff = [k for k in ra if not timing(k) and ra[k] != rb.get(k)]
        same += not diff
        print(f"{'same' if not diff else 'DIFF'} {rel}" + (f": {diff}" if diff else ""))
    print(f"{same} of {len(files)} rows identical (timing and provenance columns aside)")
    return 0 if files and same == len(files) else 1


if __name__ == "__main__":
    run(main)
