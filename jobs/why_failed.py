"""Why episodes failed: one line per failed episode of a run, from its result rows.

    python jobs/why_failed.py results/main/fast-mctd/antmaze-medium
    python jobs/why_failed.py results/main/fast-mctd/pointmaze-giant results/main/s-mctd/pointmaze-giant

For each failure: how the search ended (plan_status; replanning methods: the count of plans),
the first plan's length and end distance to the goal, the share of the path along it (10 points
per step) inside free maze cells (below 100% the plan cuts through a wall, which the authors'
value function does not test), how close the executed trajectory came to the goal, and whether
the robot stood still for its last 200 steps (a fallen ant never gets up). A summary line per
directory counts wall-cutting plans and robots that stopped.
"""

from __future__ import annotations

from pathlib import Path

from fmctd_dist.cli import run
from fmctd_dist.errors import ConfigError
from fmctd_dist.evaluation.diagnose import failures
from fmctd_dist.evaluation.results import ResultStore


def main(argv: list[str]) -> int:
    if not argv:
        raise ConfigError("why_failed: give one or more result dirs, e.g. results/main/fast-mctd/antmaze-medium")
    for d in map(Path, argv):
        full = d.resolve()  # <out>/<run>/<method>/<env>
        rows = (ResultStore(full.parents[2], full.parents[1].name).rows(full.parent.name, full.name)
                if len(full.parents) > 2 else [])
        if not rows:
            raise ConfigError(f"why_failed: {d} has no task=*/seed=*.parquet rows (a <run>/<method>/<env> dir)")
        fails = failures(rows)
        print(f"{d}: {len(fails)} of {len(rows)} episodes failed")
        for f in fails:
            print(f"  task {f['task']} seed {f['seed']}: {f['status']}, plan {f['plan_len']} steps ending "
                  f"{f['plan_end_to_goal']:.1f} from the goal, {100 * f['plan_in_free']:.1f}% in free cells; "
                  f"closest approach {f['closest']:.2f} in {f['steps']} steps{', then stood still' if f['stopped'] else ''}")
        cut = sum(f["plan_in_free"] < 1.0 for f in fails)
        still = sum(f["stopped"] for f in fails)
        print(f"  {cut} of {len(fails)} failed first plans cut through a wall; {still} robots stood still at the end")
    return 0


if __name__ == "__main__":
    run(main)
