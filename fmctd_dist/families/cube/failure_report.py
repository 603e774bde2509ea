"""Cube failures as text: one line per failed episode and the reasons counted per method (jobs/probes/why_failed.py).

The reason itself is decided when the episode ends (:func:`cube_failures.why_failed`, stored in the
row). Here a failed row is read against its goal so a reader can tell the planner's part from the
arm's: how far the first plan starts from where the cubes are (a plan that starts elsewhere sends
the arm to an empty spot), how close it ends to the goal (a plan that ends there was a good plan),
how close the cubes came during the episode, and how the search of each plan ended.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

import numpy as np

from fmctd_dist.families.cube.failures import REASONS
from fmctd_dist.evaluation.plan_tally import plan_statuses


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
