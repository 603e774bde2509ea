"""jobs/bench/bench_grid_scaling.py (issue 55 item 4) in its tiny mode: the tiny checkpoint, two or three settings,
rows identical across them, the table, CSV and plot written; settings parsed; the projection's shape."""

from __future__ import annotations

import csv
import os
import subprocess
import sys

import pytest

from fmctd_dist.config import REPO_ROOT

SCRIPT = REPO_ROOT / "jobs" / "bench" / "bench_grid_scaling.py"
SEARCH = ["method=p-mctd", "method.parallel=4", "method.budget=8", "method.early_stop=false", "ray.micro_batch=4",
          "tasks=[1,2]", "seeds=[0]"]


def bench(tiny_checkpoint, out, settings: str, timeout: int = 300) -> subprocess.CompletedProcess:
    args, _ = tiny_checkpoint
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
    env["OMP_NUM_THREADS"] = "1"
    return subprocess.run([sys.executable, str(SCRIPT), f"settings={settings}", f"out={out}", *args, *SEARCH],
                          cwd=REPO_ROOT, env=env, capture_output=True, text=True, timeout=timeout)


def check_written(out, n_settings: int) -> list[dict]:
    with (out / "grid.csv").open() as f:
        recs = list(csv.DictReader(f))
    assert len(recs) == n_settings
    assert all(r["rows_identical"] == "yes" and r["episodes"] == "2" for r in recs), recs
    table = (out / "scaling.md").read_text()
    assert "| setting |" in table and "Projection on N GPUs" in table and "| 1 |" in table
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return recs
    assert (out / "scaling.png").stat().st_size > 1000
    return recs


def test_tiny_local_grid_rows_identical_and_table_written(tiny_checkpoint, tmp_path):
    out = tmp_path / "grid"
    done = bench(tiny_checkpoint, out, "[local:f1,local:f2]")
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    recs = check_written(out, 2)
    assert [r["setting"] for r in recs] == ["local:f1", "local:f2"] and recs[0]["vs_baseline"] == "1.0"
    assert "| `local:f2` | local |" in done.stdout
    again = bench(tiny_checkpoint, out, "[local:f1]")  # a timing is never resumed: a used folder is refused
    assert again.returncode == 2 and "is not empty" in again.stderr


@pytest.mark.ray
@pytest.mark.slow
def test_tiny_ray_and_simulated_cluster_rows_identical(tiny_checkpoint, tmp_path):
    """Its own private clusters, each in a child process (like tests/test_ray_multinode.py); marked ray so that
    under xdist it runs beside the other Ray tests, not at the same time as them on another worker."""
    out = tmp_path / "grid"
    done = bench(tiny_checkpoint, out, "[local:f1,ray:e2d1f2,cluster2:e2d2f1]", timeout=400)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    recs = check_written(out, 3)
    assert recs[2]["nodes"] == "2" and recs[2]["cluster_cpus"] == "2.0" and recs[2]["denoiser_actors"] == "2"


def test_settings_parse_and_refuse_what_they_cannot_mean():
    sys.path.insert(0, str(SCRIPT.parent))
    try:
        from bench_grid_scaling import parse_setting
    finally:
        sys.path.remove(str(SCRIPT.parent))
    from fmctd_dist.errors import ConfigError

    s = parse_setting("cluster3:e4d2f2")
    assert (s.where, s.nodes, s.env_actors, s.denoisers, s.in_flight, s.name) == ("cluster", 3, 4, 2, 2,
                                                                                  "cluster3-e4d2f2")
    assert parse_setting("local:f4").env_actors == 4
    for bad in ("local:e2d1f1", "ray:f2", "gpu:e1d1f1", "ray:e0d1f1"):
        with pytest.raises(ConfigError):
            parse_setting(bad)


def test_projection_pools_sparse_trees_but_not_full_batches():
    """The rate model: pooling F one-job trees on a GPU multiplies throughput by about F; pooling trees of K=200 jobs
    per call gains until the H200 saturates (about 1000 jobs per call at 11 tokens), then nothing; N GPUs multiply
    it until the host cores cap it."""
    sys.path.insert(0, str(SCRIPT.parent))
    try:
        from bench_grid_scaling import GridModel, projected_eph
    finally:
        sys.path.remove(str(SCRIPT.parent))
    sparse = GridModel(host_s=0.5, model_s=20.0, iterations=100, jobs_per_call=1, cpu_micro_batch=1)
    one, eight = projected_eph(sparse, 1, 1, 0.0, 1e9), projected_eph(sparse, 1, 8, 0.0, 1e9)
    assert 7.5 < eight / one <= 8.0
    dense = GridModel(host_s=0.5, model_s=20.0, iterations=10, jobs_per_call=200, cpu_micro_batch=8)
    assert projected_eph(dense, 1, 4, 0.0, 1e9) / projected_eph(dense, 1, 1, 0.0, 1e9) > 3
    gpu_bound = GridModel(host_s=0.001, model_s=20.0, iterations=10, jobs_per_call=200, cpu_micro_batch=8)
    assert projected_eph(gpu_bound, 1, 10, 0.0, 1e9) / projected_eph(gpu_bound, 1, 5, 0.0, 1e9) < 1.05
    assert projected_eph(dense, 4, 1, 0.0, 1e9) == pytest.approx(4 * projected_eph(dense, 1, 1, 0.0, 1e9))
    assert projected_eph(dense, 1000, 1, 0.0, 2) == pytest.approx(3600 * 2 / 0.5)
