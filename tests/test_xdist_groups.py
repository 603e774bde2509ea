"""The test layout itself: under ``-n 2 --dist loadgroup`` every Ray test runs in one xdist worker."""

import os
from pathlib import Path

import pytest


@pytest.mark.ray
def test_the_ray_tests_share_one_worker(ray_cluster):
    # the effect, checked without xdist's node ids: the session cluster was claimed by this worker, and a
    # second worker's ray_cluster would have raised (tests/conftest.py, claim_ray_worker)
    worker = os.environ.get("PYTEST_XDIST_WORKER")
    if worker is None:
        pytest.skip("not under pytest-xdist (run the suite as pyproject's addopts do)")
    from conftest import RUN_DIR

    assert (Path(os.environ[RUN_DIR]) / "ray-cluster-worker").read_text() == worker
    listed = "".join(f.read_text() for f in Path(os.environ[RUN_DIR]).glob("ray-tests-*.txt"))
    assert "test_the_ray_tests_share_one_worker" in listed


def test_a_second_worker_claiming_the_cluster_is_an_error(tmp_path):
    from conftest import claim_ray_worker

    claim_ray_worker(tmp_path, "gw0")
    claim_ray_worker(tmp_path, "gw0")  # the same worker again: its own cluster, fine
    with pytest.raises(RuntimeError, match="two xdist workers"):
        claim_ray_worker(tmp_path, "gw1")


def test_each_worker_gets_its_share_of_the_cores(monkeypatch):
    # two workers on two cores: one torch thread each (and in the jobs they start), not torch's one per core
    from conftest import worker_threads

    monkeypatch.setenv("PYTEST_XDIST_WORKER_COUNT", "2")
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    assert worker_threads() == 1
    monkeypatch.setattr(os, "cpu_count", lambda: 16)
    assert worker_threads() == 8
    monkeypatch.delenv("PYTEST_XDIST_WORKER_COUNT")
    assert worker_threads() == 16
    if "PYTEST_XDIST_WORKER" in os.environ:  # set at import of conftest, before any job is started
        assert os.environ.get("OMP_NUM_THREADS") is not None
