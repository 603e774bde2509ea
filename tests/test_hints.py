"""Hints that work (issue 18 item 3): the command an error suggests, run as printed (the failing
config's own words keep it smoke-sized), makes exactly what was missing, where the config looks."""

from __future__ import annotations

import os
import re
import shutil
import subprocess

import pytest

from conftest import TINY_DATA, TINY_MODEL
from fmctd_dist.config import REPO_ROOT, load_config
from fmctd_dist.diffusion.checkpoint import load_checkpoint
from fmctd_dist.errors import CheckpointError, DatasetError
from fmctd_dist.evaluation.grid import prepare
from fmctd_dist.families import hooks_for

pytestmark = pytest.mark.slow

# What makes a suggested training run tiny: part of the failing config, so the hint carries it.
SMOKE = ["train.max_steps=2", "train.batch_size=4", "train.val_batches=1", "train.val_every=0", "env.max_steps=100"]


def suggested(e: BaseException) -> str:
    """The one command inside backticks that starts a job (the first, when alternatives follow)."""
    cmds = [c for c in re.findall(r"`([^`]+)`", str(e)) if "jobs/" in c]
    assert cmds, f"no command in: {e}"
    return cmds[-1]


def run(cmd: str) -> None:
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    out = subprocess.run(cmd, shell=True, cwd=REPO_ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, f"{cmd}\n{out.stdout[-2000:]}\n{out.stderr[-3000:]}"


def words(tiny_dataset, ckpt, *extra) -> list[str]:
    data_cfg, _ = tiny_dataset
    return TINY_DATA + [f"data.root={data_cfg.data.root}", f"checkpoint={ckpt}"] + SMOKE + list(extra)


@pytest.mark.parametrize("extra", [["method=p-mctd"] + TINY_MODEL, ["method=fast-mctd"] + TINY_MODEL,
                                   ["method=diffuser", "model.unet_channels=[8,16]", "model.unet_edge_frames=2"]],
                         ids=["p-mctd", "fast-mctd-jump5", "diffuser"])
def test_missing_checkpoint_hint_trains_it_where_the_config_looks(tiny_dataset, tmp_path, extra):
    cfg = load_config(words(tiny_dataset, tmp_path / "ck", *extra))
    with pytest.raises(CheckpointError, match="does not exist") as e:
        prepare(cfg, hooks_for)
    cmd = suggested(e.value)
    assert f"train.out={tmp_path / 'ck'}" in cmd and f"jump={cfg.jump}" in cmd and "runs/" not in cmd
    assert ("model.kind=diffuser" in cmd) == (cfg.model.kind == "diffuser")
    run(cmd)
    prepare(cfg, hooks_for)  # what failed now passes: present, intact, trained for this config
    model, manifest = load_checkpoint(cfg.checkpoint_dir(), cfg)
    assert manifest["train_steps"] == 2 and manifest["config"]["jump"] == cfg.jump


def test_corrupt_checkpoint_hint_replaces_it(tiny_checkpoint, tiny_dataset, tmp_path):
    _, ckpt = tiny_checkpoint
    bad = tmp_path / "ck"
    shutil.copytree(ckpt, bad)
    raw = bytearray((bad / "model.pt").read_bytes())
    raw[len(raw) // 2] ^= 0xFF
    (bad / "model.pt").write_bytes(bytes(raw))
    cfg = load_config(words(tiny_dataset, bad, "method=p-mctd", *TINY_MODEL))
    with pytest.raises(CheckpointError, match="corrupt") as e:
        prepare(cfg, hooks_for)
    cmd = suggested(e.value)
    assert cmd.startswith(f"mv {bad} {bad}.broken && python jobs/train.py") and f"train.out={bad}" in cmd
    run(cmd)
    prepare(cfg, hooks_for)
    load_checkpoint(bad, cfg)
    assert (tmp_path / "ck.broken" / "model.pt").exists()  # the broken one is kept aside, not deleted


def test_shipped_checkpoint_hint_restores_it_from_git(tmp_path):
    """A corrupt shipped checkpoint: `git checkout` (the first command offered) brings it back."""
    from fmctd_dist.diffusion.checkpoint import _train_fix

    cfg = load_config(["method=fast-mctd"])
    fix = _train_fix(cfg, cfg.checkpoint_dir(), broken=True)
    assert fix.startswith("restore the shipped one with `git checkout -- checkpoints/pointmaze-medium-h5`")


def test_jump_mismatch_hint_offers_both_fixes_and_both_work(tiny_checkpoint, tiny_dataset, tmp_path):
    """method=fast-mctd (jump 5) with a jump-1 checkpoint: `jump=1` plans with it as is; the training
    command makes a jump-5 model elsewhere (never over the jump-1 one) and names it."""
    _, ckpt = tiny_checkpoint
    cfg = load_config(words(tiny_dataset, ckpt, "method=fast-mctd", *TINY_MODEL))
    with pytest.raises(CheckpointError, match="trained with jump=1 but the config has jump=5") as e:
        prepare(cfg, hooks_for)
    msg = str(e.value)
    assert "set jump=1" in msg
    prepare(load_config(words(tiny_dataset, ckpt, "method=fast-mctd", *TINY_MODEL, "jump=1")), hooks_for)
    cmd = suggested(e.value)
    assert "jump=5" in cmd and f"train.out={ckpt}" not in cmd
    new = re.search(r"set checkpoint=(\S+)$", msg)
    assert new, msg
    out = REPO_ROOT / new.group(1)
    try:
        run(cmd)
        fixed = load_config(words(tiny_dataset, new.group(1), "method=fast-mctd", *TINY_MODEL))
        prepare(fixed, hooks_for)
        load_checkpoint(fixed.checkpoint_dir(), fixed)
    finally:
        shutil.rmtree(out, ignore_errors=True)


def test_p_mctd_with_shipped_jump5_checkpoint_points_at_the_jump1_one():
    cfg = load_config(["method=p-mctd", "checkpoint=checkpoints/pointmaze-medium-h5"])
    with pytest.raises(CheckpointError) as e:
        prepare(cfg, hooks_for)
    msg = str(e.value)
    assert "trained with jump=5 but the config has jump=1" in msg and "set jump=5" in msg
    assert "checkpoints/pointmaze-medium-h1 holds one: drop checkpoint=" in msg
    prepare(load_config(["method=p-mctd", "checkpoint=checkpoints/pointmaze-medium-h5", "jump=5"]), hooks_for)
    prepare(load_config(["method=p-mctd"]), hooks_for)


def test_missing_dataset_hint_makes_that_dataset(tmp_path):
    from fmctd_dist.families.maze.data import load_dataset

    cfg = load_config(["env.horizon=100", "data.train_window=100", "data.episodes=2", "data.episode_steps=120",
                       f"data.root={tmp_path}", "data.seed=3"])
    with pytest.raises(DatasetError, match="no dataset") as e:
        load_dataset(cfg)
    run(suggested(e.value))
    ds = load_dataset(cfg)
    assert ds.train.shape == (2, 120, 2)


def test_corrupt_dataset_hint_regenerates_it(tiny_dataset, tmp_path):
    from fmctd_dist.families.maze.data import load_dataset

    data_cfg, path = tiny_dataset
    shutil.copytree(path, tmp_path / path.name)
    cfg = load_config(TINY_DATA + [f"data.root={tmp_path}"])
    raw = bytearray((tmp_path / path.name / "val.npz").read_bytes())
    raw[-10] ^= 0xFF
    (tmp_path / path.name / "val.npz").write_bytes(bytes(raw))
    with pytest.raises(DatasetError, match="corrupt") as e:
        load_dataset(cfg)
    cmd = suggested(e.value)
    assert cmd.startswith(f"rm -r {tmp_path / path.name} && python jobs/make_dataset.py"), cmd
    run(cmd)
    assert load_dataset(cfg).manifest["sha256"] == load_dataset(data_cfg).manifest["sha256"]  # the same bytes again
