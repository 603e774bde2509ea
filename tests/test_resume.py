"""fmctd_dist.resume: the train state, the resume check, the budget clock and the snapshot cadence of every loop."""

from __future__ import annotations

import time

import numpy as np
import pytest
import torch

from fmctd_dist.errors import CheckpointError
from fmctd_dist.resume import SNAPSHOTS, TRAIN_STATE_FILE, Clock, check_resume, load_train_state, save_train_state, \
    snapshot_due


def test_train_state_round_trips_atomically(tmp_path):
    rng = np.random.Generator(np.random.PCG64(3))
    assert load_train_state(tmp_path / "run") is None  # nothing to resume
    save_train_state(tmp_path / "run", {"step": 7, "rng": rng.bit_generator.state, "w": torch.ones(2)})
    st = load_train_state(tmp_path / "run")
    assert st["step"] == 7 and torch.equal(st["w"], torch.ones(2)) and st["rng"] == rng.bit_generator.state
    assert sorted(p.name for p in (tmp_path / "run").iterdir()) == [TRAIN_STATE_FILE]  # no .tmp left behind
    torch.save([1, 2], tmp_path / "run" / TRAIN_STATE_FILE)
    with pytest.raises(CheckpointError, match="not a training state.*delete"):
        load_train_state(tmp_path / "run")


def test_resume_check_names_the_field_and_the_fix(tmp_path):
    saved, now = {"a": {"hidden": [32, 32]}, "env": "x"}, {"a": {"hidden": [64, 64]}, "env": "x"}
    check_resume(tmp_path, "toy", "a.out", saved, saved, ["a.hidden", "env"], [("dataset", "d1", "d1")])
    with pytest.raises(CheckpointError, match=r"toy run with a.hidden=\[32, 32\] but the config has "
                                              r"a.hidden=\[64, 64\]; set 'a.hidden=\[32,32\]' to continue it, "
                                              r"or use a fresh a.out dir"):
        check_resume(tmp_path, "toy", "a.out", saved, now, ["env", "a.hidden"])
    with pytest.raises(CheckpointError, match="trained on dataset 0123456789abcdef but it is now ffff; regenerate it"):
        check_resume(tmp_path, "toy", "a.out", saved, saved, ["env"], [("dataset", "0123456789abcdef0", "ffff")],
                     "regenerate it")


def test_clock_counts_over_runs_and_stops_at_the_budget():
    clock = Clock(wall_s=10.0, cpu_s=2.0)
    assert 10.0 <= clock.used() < 11.0 and clock.over(10.0) and not clock.over(0.0) and not clock.over(1e9)
    time.sleep(0.01)
    clock.lap()
    assert clock.wall_s >= 10.01 and clock.cpu_s >= 2.0
    cpu = Clock(wall_s=1e6, cpu_s=5.0, kind="cpu")  # the CPU clock ignores wall time
    assert 5.0 <= cpu.used() < 6.0 and not cpu.over(100.0)


def test_snapshot_due_reads_the_folder(tmp_path):
    assert snapshot_due(tmp_path, 0.0, 1e9) is None and snapshot_due(tmp_path, 60.0, 59.0) is None
    assert snapshot_due(tmp_path, 60.0, 130.0) == "k002"
    (tmp_path / SNAPSHOTS / "k002-step0000040").mkdir(parents=True)
    assert snapshot_due(tmp_path, 60.0, 130.0) is None and snapshot_due(tmp_path, 60.0, 180.0) == "k003"
