"""jobs/probes/warp_sites.py: where plans warp (first step, later boundaries, inside tokens)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import load_job

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def test_sites_splits_warps_by_where_they_sit():
    job = load_job("warp_sites")
    steps = np.full((4, 6), 0.1)  # 4 plans, 6 steps, tokens of 3 frames: boundaries at steps 0 and 3
    steps[1, 0] = 2.0  # plan 1: only its first step
    steps[2, 3] = 2.0  # plan 2: a later boundary
    steps[3, [0, 4]] = 2.0  # plan 3: the first step and inside a token
    s = job.sites(steps, warp=1.0, frame_stack=3)
    assert s == {"no_warp": 0.25, "first": 0.5, "later_boundary": 0.25, "inside": 0.25, "only_first": 0.25}


def test_warp_sites_on_a_tiny_checkpoint(tiny_checkpoint):
    job = load_job("warp_sites")
    _, ckpt = tiny_checkpoint
    r = job.warp_sites(ckpt, samples_per_task=2, val_starts=4)
    for name in ("unguided", "guided"):
        s = r[name]
        assert s["only_first"] <= s["first"] <= 1 - s["no_warp"] + 1e-9 and s["first_step"] > 0
        assert len(s["per_task"]) == 5 and all(0 <= v <= 1 for v in s["per_task"])
        assert np.mean(s["per_task"]) == pytest.approx(s["no_warp"])
    assert r["val_starts"]["n"] == 4 and r["cell_centres"]["n"] > 10
    text = "\n".join(job.lines(r))
    assert "| guided |" in text and "free cell centres" in text
