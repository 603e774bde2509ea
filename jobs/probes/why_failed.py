"""Why episodes failed: one line per failed episode of a run, from its result rows.

    python jobs/probes/why_failed.py results/main/fast-mctd/antmaze-medium
    python jobs/probes/why_failed.py results/main/fast-mctd/pointmaze-giant results/main/s-mctd/pointmaze-giant
    python jobs/probes/why_failed.py results/cube-methods-s9          # a whole run: every <method>/<env> in it

Maze rows: how the search ended (plan_status; replanning methods: the count of plans),
the first plan's length and end distance to the goal, the share of the path along it (10 points
per step) inside free maze cells (below 100% the plan cuts through a wall, which the authors'
value function does not test), how close the executed trajectory came to the goal, and whether
the robot stood still for its last 200 steps (a fallen ant never gets up). A summary line per
directory counts wall-cutting plans and robots that stopped.

Rows that carry a ``why_failed`` reason (the cube episodes: wrong cube, dropped, stack knocked
over, time out, planning time out) print that reason with how the plans ended, how close the
first plan and the cubes came to the goal; then a table counts the reasons per method and env.
"""

from __future__ import annotations

from pathlib import Path

from fmctd_dist.cli import run
from fmctd_dist.errors import ConfigError
from fmctd_dist.families.cube.failure_report import failure_line, has_reasons, reason_table
from fmctd_dist.families.maze.diagnose import failures
from fmctd_dist.evaluation.results import ResultStore


def result_dirs(d: Path) -> list[Path]:
    """``d`` if it is a <run>/<method>/<env> dir; the <method>/<env> dirs in it if it is a <run> dir."""
    if any(d.glob("task=*")):
        return [d]
    return sorted({p.parent for p in d.glob("*/*/task=*") if p.is_dir()})


def read_rows(d: Path) -> list[dict]:
    full = d.resolve()  # <out>/<run>/<method>/<env>
    return (ResultStore(full.parents[2], full.parents[1].name).rows(full.parent.name, full.name)
            if len(full.parents) > 2 else [])


def print_maze(d: Path, rows: list[dict]) -> None:
    fails = failures(rows)
    print(f"{d}: {len(fails)} of {len(rows)} episodes failed")
    for f in fails:
        print(f"  task {f['task']} seed {f['seed']}: {f['status']}, plan {f['plan_len']} steps ending "
              f"{f['plan_end_to_goal']:.1f} from the goal, {100 * f['plan_in_free']:.1f}% in free cells; "
              f"closest approach {f['closest']:.2f} in {f['steps']} steps"
              f"{', then stood still' if f['stopped'] else ''}")
    cut = sum(f["plan_in_free"] < 1.0 for f in fails)
    still = sum(f["stopped"] for f in fails)
    print(f"  {cut} of {len(fails)} failed first plans cut through a wall; {still} robots stood still at the end")


def print_reasons(d: Path, rows: list[dict]) -> None:
    fails = [r for r in rows if not r["success"]]
    print(f"{d}: {len(fails)} of {len(rows)} episodes failed")
    for r in sorted(fails, key=lambda r: (r["task"], r["seed"])):
        print(f"  {failure_line(r)}")


def main(argv: list[str]) -> int:
    if not argv:
        raise ConfigError("why_failed: give one or more result dirs, e.g. results/main/fast-mctd/antmaze-medium "
                          "or a whole run, results/cube-methods-s9")
    with_reasons = []
    for arg in map(Path, argv):
        dirs = result_dirs(arg)
        if not dirs:
            raise ConfigError(f"why_failed: {arg} has no task=*/seed=*.parquet rows (a <run>/<method>/<env> dir, "
                              "or a <run> dir holding such dirs)")
        for d in dirs:
            rows = read_rows(d)
            if not rows:
                raise ConfigError(f"why_failed: {d} has no readable task=*/seed=*.parquet rows")
            if has_reasons(rows):
                print_reasons(d, rows)
                with_reasons += rows
            else:
                print_maze(d, rows)
    if with_reasons:
        print("\nFailure reasons per method (episodes read from the rows' why_failed):\n")
        print(reason_table(with_reasons))
    return 0


if __name__ == "__main__":
    run(main)
