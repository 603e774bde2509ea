"""fmctd_dist.resume: the train state, the resume check, the budget clock, the step cadences, the parts' states and the
snapshot cadence of every loop."""

from __future__ import annotations

import time

import numpy as np
import pytest
import torch

from fmctd_dist.errors import CheckpointError
from fmctd_dist.resume import SNAPSHOTS, TRAIN_STATE_FILE, Clock, TrainRun, check_resume, load_part_states, \
    load_train_state, part_states, save_train_state, snapshot_due, stream_rng


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


def test_train_run_keeps_the_cadences_and_the_history(tmp_path):
    run = TrainRun("toy", 5, {"history": {"train": [], "val": []}}, progress=False, names=("step", "two"))
    saves, logged = [], []
    while not run.last:
        run.tick(float(run.step), torch.tensor(2.0))  # a float and a device tensor, averaged per log window
        if run.due(2):
            logged.append(run.log())
        run.checkpoint(3, lambda: saves.append(run.step))
    run.close()
    assert run.step == 5 and saves == [3, 5] and logged == [[0.5, 2.0], [2.5, 2.0], [4.0, 2.0]]
    assert run.history["train"] == [[2, 0.5, 2.0], [4, 2.5, 2.0], [5, 4.0, 2.0]]
    again = TrainRun("toy", 7, run.state(), progress=False)  # a rerun continues from the saved state
    assert again.step == 5 and not again.last and again.clock.wall_s == run.clock.wall_s
    assert TrainRun("toy", 9, {"step": 1, "wall_time_s": 10.0, "history": {}}, budget_s=5.0, progress=False).last


def test_part_states_round_trip_every_kind_of_part():
    net, rng, gen = torch.nn.Linear(2, 2), stream_rng(0, 1), torch.Generator().manual_seed(3)
    opt = torch.optim.Adam(net.parameters())
    saved = part_states(net=net, opt=opt, rng=rng, gen=gen)
    a, b = rng.random(), torch.rand(1, generator=gen)
    with torch.no_grad():
        net.weight.zero_()
    load_part_states(saved, net=net, rng=rng, gen=gen, opt=opt)
    assert rng.random() == a and torch.equal(torch.rand(1, generator=gen), b) and net.weight.abs().sum() > 0
    assert stream_rng(0, 1).random() != stream_rng(0, 2).random()
