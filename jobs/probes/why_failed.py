"""Why episodes failed: one line per failed episode of a run, from its result rows.

    python jobs/probes/why_failed.py results/main/fast-mctd/antmaze-medium
    python jobs/probes/why_failed.py results/main/fast-mctd/pointmaze-giant results/main/s-mctd/pointmaze-giant
    python jobs/probes/why_failed.py results/cube-methods-s9          # a whole run: every <method>/<env> in it

Maze rows: how the search ended (plan_status; replanning methods: the count of plans),
the first plan's length and end distance to the goal, the share of the path along it (10 points
per step) inside free maze cells (below 100% the plan cuts through a wall, which the authors'
value function does not test), how close the executed trajectory came to the goal, and whether
the robot stood still for its last 200 steps (a fallen ant never gets up; ``rewalk.py`` walks the plans again
and tells a fallen ant from one pushing a wall). A summary line per directory counts wall-cutting plans and
robots that stopped.

Rows that carry a ``why_failed`` reason (the cube episodes: wrong cube, dropped, stack knocked
over, time out, planning time out) print that reason with how the plans ended, how close the
first plan and the cubes came to the goal; then a table counts the reasons per method and env. The
reason itself is decided when the episode ends (``families/cube/failures.py``, stored in the row); here
a failed row is read against its goal, so a reader can tell the planner's part from the arm's.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from fmctd_dist.cli import run
from fmctd_dist.errors import ConfigError
from fmctd_dist.evaluation.plan_tally import plan_statuses
from fmctd_dist.evaluation.results import ResultStore
from fmctd_dist.families.cube.failures import REASONS
from fmctd_dist.families.maze.episode import stood_still
from fmctd_dist.families.maze.geometry import densify, maze_geometry


def failures(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per failed row: status, first-plan length / end distance to the goal / share of its path in free
    cells, closest approach of the executed trajectory, and whether the robot stood still at the end."""
    out = []
    for r in rows:
        if r["success"]:
            continue
        geo = maze_geometry(r["env"])
        goal = np.asarray(geo.task(r["task"]).goal_xy)
        plan = np.asarray(r["plan_xy"], dtype=np.float64).reshape(-1, 2)
        traj = np.asarray(r["traj_xy"], dtype=np.float64).reshape(-1, 2)
        path = densify(plan)  # 10 points along each plan step
        statuses = str(r["plan_status"]).split(",")
        out.append({"task": r["task"], "seed": r["seed"], "plan_len": len(plan),
                    "status": statuses[0] if len(statuses) == 1 else f"{len(statuses)} plans",
                    "plan_end_to_goal": float(np.linalg.norm(plan[-1] - goal)),
                    "plan_in_free": float(geo.in_free_cell(path).mean()),
                    "closest": float(np.linalg.norm(traj - goal, axis=1).min()), "steps": r["env_steps"],
                    "stopped": stood_still(traj)})
    return out


def has_reasons(rows: list[dict[str, Any]]) -> bool:
    """Rows that carry a ``why_failed`` reason (the cube episodes write one; the maze ones do not)."""
    return bool(rows) and all("why_failed" in r for r in rows)


def _cubes(r: dict[str, Any], key: str) -> np.ndarray:
    return np.asarray(r[key], np.float64).reshape(-1, int(r["n_cubes"]), 3)


def failure_facts(r: dict[str, Any]) -> dict[str, Any]:
    """The measured facts of one failed cube row (distances in obs units; success is within 0.4)."""
    goal = np.asarray(r["goal_cubes"], np.float64).reshape(-1, 3)
    plan, traj = _cubes(r, "plan_cubes"), _cubes(r, "traj_cubes")
    statuses = plan_statuses(r)
    return {"task": r["task"], "seed": r["seed"], "reason": r["why_failed"] or "?",
            "plans": int(r.get("plans", sum(statuses.values()))), "statuses": dict(statuses),
            "targets": str(r.get("targets", "")), "releases": int(r.get("releases", 0)), "steps": int(r["env_steps"]),
            # worst cube at the first plan's first frame against the cubes when it was made (step 0)
            "plan_start": float(np.linalg.norm(plan[0] - traj[0], axis=-1).max()),
            "plan_end": float(np.linalg.norm(plan[-1] - goal, axis=-1).max()),  # worst cube at the first plan's end
            "closest": float(np.linalg.norm(traj - goal, axis=-1).max(-1).min()),  # all cubes' worst, at its best step
            "final": float(np.linalg.norm(traj[-1] - goal, axis=-1).max()),
            "max_z": float(traj[..., 2].max())}


def failure_line(r: dict[str, Any]) -> str:
    f = failure_facts(r)
    statuses = ", ".join(f"{n} {s}" for s, n in f["statuses"].items())
    return (f"task {f['task']} seed {f['seed']}: {f['reason']}; {f['plans']} plans ({statuses}), targets "
            f"{f['targets'] or '-'}, {f['releases']} releases, {f['steps']} steps; first plan starts "
            f"{f['plan_start']:.2f} from the cubes and ends "
            f"{f['plan_end']:.2f} from the goal, cubes came within {f['closest']:.2f}, ended {f['final']:.2f} "
            f"away (highest z {f['max_z']:.2f})")


def reason_counts(rows: list[dict[str, Any]]) -> dict[tuple[str, str], Counter]:
    """(method, env) -> Counter of reasons over its failed rows ('' = success is counted as 'solved')."""
    out: dict[tuple[str, str], Counter] = {}
    for r in rows:
        out.setdefault((r["method"], r["env"]), Counter())[r["why_failed"] or "solved"] += 1
    return out


def reason_table(rows: list[dict[str, Any]]) -> str:
    """Markdown: per (method, env) the episodes, the failures and each reason's count (known reasons in
    :data:`REASONS` order, any other after)."""
    counts = reason_counts(rows)
    seen = {k for c in counts.values() for k in c if k != "solved"}
    cols = [k for k in REASONS if k in seen] + sorted(seen - set(REASONS))
    head = ["method", "env", "episodes", "failed", *cols]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for (method, env), c in sorted(counts.items()):
        n = sum(c.values())
        cells = "".join(f" {c.get(k, 0)} |" for k in cols)
        lines.append(f"| {method} | {env} | {n} | {n - c.get('solved', 0)} |{cells}")
    return "\n".join(lines)


def result_dirs(d: Path) -> list[Path]:
    """``d`` if it is a <run>/<method>/<env> dir; the <method>/<env> dirs in it if it is a <run> dir."""
    if any(d.glob("task=*")):
        return [d]
    return sorted({p.parent for p in d.glob("*/*/task=*") if p.is_dir()})


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
            rows = ResultStore.directory_rows(d)
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
