"""jobs/probes/why_failed.py on cube rows (issue 20): a line per failed episode and the reasons counted per method."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np

from conftest import load_job
from fmctd_dist.config import REPO_ROOT
from fmctd_dist.evaluation.results import ResultStore

WHY = load_job("why_failed")  # jobs/probes/why_failed.py holds the cube failure report
failure_facts, has_reasons, reason_table = WHY.failure_facts, WHY.has_reasons, WHY.reason_table

GOAL = [3.0, 0.0, 0.2]


def cube_row(method: str, task: int, seed: int, why: str, final_x: float = 3.0) -> dict:
    """A one-cube row: the first plan goes to the goal; the cube is carried up to z 1.0, then set at x=final_x."""
    traj = np.array([[0.0, 0.0, 0.2], [1.0, 0.0, 1.0], [2.0, 0.0, 1.0], [final_x, 0.0, 0.2]], np.float32)
    plan = np.linspace([0.0, 0.0, 0.2], GOAL, 5).astype(np.float32)
    return {"method": method, "env": "cube-single", "task": task, "seed": seed, "success": why == "",
            "why_failed": why, "n_cubes": 1, "env_steps": 3, "plans": 2, "plan_status": "early_stop,not_reached",
            "targets": "0,0", "releases": 0, "goal_cubes": GOAL, "plan_cubes": plan.ravel().tolist(),
            "traj_cubes": traj.ravel().tolist(), "plan_time_s": 1.0}


def fixture_rows() -> list[dict]:
    return [cube_row("fast-mctd-replan", 1, 0, ""), cube_row("fast-mctd-replan", 2, 0, "dropped", final_x=1.5),
            cube_row("mctd-replan", 1, 0, "time out", final_x=0.5), cube_row("mctd-replan", 2, 0, "wrong cube", 1.0),
            cube_row("mctd-replan", 3, 0, "")]


def test_facts_of_a_failed_row_are_measured_from_its_plan_and_trajectory():
    f = failure_facts(cube_row("m", 2, 0, "dropped", final_x=1.5))
    assert f["reason"] == "dropped" and f["plans"] == 2 and f["statuses"] == {"early_stop": 1, "not_reached": 1}
    assert f["plan_end"] < 1e-6  # the plan reached the goal: the arm's part failed
    assert f["plan_start"] < 1e-6  # ... from where the cube was
    assert np.isclose(f["final"], 1.5) and np.isclose(f["max_z"], 1.0)
    assert np.isclose(f["closest"], np.hypot(1.0, 0.8))  # step 2: (2, 0, 1) against (3, 0, 0.2)


def test_a_plan_that_starts_away_from_the_cubes_is_measured():
    r = cube_row("m", 1, 0, "time out")
    plan = np.asarray(r["plan_cubes"]).reshape(-1, 3)
    plan[:, 1] += 1.5  # the model's plan, shifted 1.5 obs units off the real cube from its first frame
    r["plan_cubes"] = plan.ravel().tolist()
    f = failure_facts(r)
    assert np.isclose(f["plan_start"], 1.5) and np.isclose(f["plan_end"], 1.5)


def test_reason_table_counts_each_reason_per_method():
    rows = fixture_rows()
    assert has_reasons(rows) and not has_reasons([{k: v for k, v in rows[0].items() if k != "why_failed"}])
    table = reason_table(rows).splitlines()
    assert table[0] == "| method | env | episodes | failed | wrong cube | dropped | time out |"  # REASONS order
    assert "| fast-mctd-replan | cube-single | 2 | 1 | 0 | 1 | 0 |" in table
    assert "| mctd-replan | cube-single | 3 | 2 | 1 | 0 | 1 |" in table


def test_why_failed_job_reads_a_whole_cube_run(tmp_path):
    store = ResultStore(tmp_path, "cube-run")
    for r in fixture_rows():
        store.write(r)
    out = subprocess.run([sys.executable, "jobs/probes/why_failed.py", str(tmp_path / "cube-run")], cwd=REPO_ROOT,
                         capture_output=True, text=True, timeout=120, env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert out.returncode == 0, out.stderr
    assert "fast-mctd-replan/cube-single: 1 of 2 episodes failed" in out.stdout
    assert "mctd-replan/cube-single: 2 of 3 episodes failed" in out.stdout
    assert "task 2 seed 0: dropped; 2 plans (1 early_stop, 1 not_reached), targets 0,0" in out.stdout
    assert "first plan starts 0.00 from the cubes and ends 0.00 from the goal" in out.stdout
    assert "| mctd-replan | cube-single | 3 | 2 | 1 | 0 | 1 |" in out.stdout


def test_why_failed_job_names_a_dir_without_rows(tmp_path):
    out = subprocess.run([sys.executable, "jobs/probes/why_failed.py", str(tmp_path)], cwd=REPO_ROOT,
                         capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 2 and "has no task=*/seed=*.parquet rows" in out.stderr and "Traceback" not in out.stderr
