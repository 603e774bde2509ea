"""The test layout itself: under ``-n 2 --dist loadgroup`` every Ray test must land in xdist's "ray" group."""

import pytest


@pytest.mark.ray
def test_a_ray_test_is_in_the_ray_group(request):
    # xdist appends the group to a node id (``...@ray``) only if the mark is there before its own hook reads
    # it (tests/conftest.py's ``tryfirst``); without it the Ray tests spread over both workers
    if not getattr(request.config.option, "loadgroup", False):  # set in each xdist worker by --dist loadgroup
        pytest.skip("not under pytest-xdist's loadgroup (run the suite as pyproject's addopts do)")
    assert request.node.nodeid.endswith("@ray"), request.node.nodeid
