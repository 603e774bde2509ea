"""The test layout itself: under ``-n 2 --dist loadgroup`` every Ray test must land in xdist's "ray" group."""

import pytest


@pytest.mark.ray
def test_a_ray_test_is_in_the_ray_group(request):
    # xdist appends the group to a node id (``...@ray``) only if the mark is there before its own hook reads
    # it (tests/conftest.py's ``tryfirst``); without it the Ray tests spread over both workers
    if not getattr(request.config.option, "loadgroup", False):  # set in each xdist worker by --dist loadgroup
        pytest.skip("not under pytest-xdist's loadgroup (run the suite as pyproject's addopts do)")
    assert request.node.nodeid.endswith("@ray"), request.node.nodeid


def test_each_worker_gets_its_share_of_the_cores(monkeypatch):
    # two workers on two cores: one torch thread each (and in the jobs they start), not torch's one per core
    import os

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
