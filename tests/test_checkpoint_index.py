"""checkpoints/README.md is what fmctd_dist/checkpoint_index.py makes of the manifests today, and every dir under
checkpoints/ is read by a config or has a listed purpose (issue 54: snapshots leave the tree)."""

from __future__ import annotations

import json

import pytest

from fmctd_dist.checkpoint_index import CHECKPOINTS, INDEX_FILE, PURPOSES, checkpoint_index, config_readers, rows
from fmctd_dist.config import REPO_ROOT
from fmctd_dist.errors import ConfigError
from fmctd_dist.families import hooks_for


@pytest.fixture(scope="module")
def found() -> tuple[dict[str, list[str]], dict[str, str]]:
    """config_readers() once for the module (every config's eval checks: half a minute): readers, absent."""
    absent: dict[str, str] = {}
    return config_readers(hooks_for, absent), absent


@pytest.fixture(scope="module")
def readers(found) -> dict[str, list[str]]:
    return found[0]


def test_committed_index_equals_the_manifests(found):
    committed = (CHECKPOINTS / INDEX_FILE).read_text()
    assert committed == checkpoint_index(CHECKPOINTS, *found), ("checkpoints/README.md is stale: regenerate it with "
                                             "`python jobs/report.py --checkpoints` and commit it")


def test_every_checkpoint_dir_is_read_by_a_config_or_a_listed_purpose(readers):
    dirs = {p.name for p in CHECKPOINTS.iterdir() if p.is_dir()}
    unread = sorted(dirs - set(readers) - set(PURPOSES))
    assert not unread, (f"no config reads {unread} and PURPOSES names none for them: a snapshot leaves the tree "
                        "(git rm it; record its digest and last commit in docs/notebook/checkpoint-snapshots.md), "
                        "or name what needs it in fmctd_dist/checkpoint_index.PURPOSES")


def test_each_listed_purpose_is_a_shipped_dir_that_its_named_file_still_reads(readers):
    for name, why in PURPOSES.items():
        assert (CHECKPOINTS / name / "manifest.json").is_file(), f"PURPOSES names {name}, which is not shipped"
        assert name not in readers, f"{name} is read by a config ({readers.get(name, [''])[0]}): drop its purpose"
        user = REPO_ROOT / why.split()[0]
        assert user.is_file() and f"checkpoints/{name}" in user.read_text(), f"{user} no longer names {name}"


def test_the_default_planners_policies_and_parts_are_read(readers):
    """Spot checks of config_readers against what the configs say (one line each family)."""
    r = readers
    assert "env=pointmaze-medium method=fast-mctd: eval" in r["pointmaze-medium-h5"]
    assert "env=pointmaze-medium method=diffusion-forcing jump=10: eval" in r["pointmaze-medium-h10"]
    assert "env=antmaze-large method=fast-mctd: eval" in r["antmaze-large-policy"]
    assert "env=antmaze-medium method=mctd: data.expert" in r["ant-expert"]
    assert "env=cube-triple method=fast-mctd: eval" in r["cube-single-policy"]
    assert "env=visual-pointmaze-medium method=fast-mctd: eval" in r["visual-pointmaze-medium-h5-xy"]
    assert "env=visual-pointmaze-medium method=fast-mctd visual.plan_xy=false: eval" in r["visual-pointmaze-medium-h5"]
    assert "env=visual-pointmaze-large method=mctd: eval" in r["visual-pointmaze-large-vae"]
    assert "pointmaze-medium-h5" not in r.get("pointmaze-large-h5", [])


def test_a_dir_nothing_reads_says_so_and_one_without_manifest_is_refused(tmp_path):
    shipped = json.loads((CHECKPOINTS / "pointmaze-medium-h5" / "manifest.json").read_text())
    (tmp_path / "old-snapshot").mkdir()
    (tmp_path / "old-snapshot" / "manifest.json").write_text(json.dumps(shipped))
    (tmp_path / "old-snapshot" / "model.pt").write_bytes(b"w" * 2_000_000)
    [row] = rows(tmp_path, readers={})
    assert row["name"] == "old-snapshot" and row["family"] == "pointmaze" and row["digest"] == shipped["digest"]
    assert row["what"] == "Diffusion Forcing planner, pointmaze-medium, H=5, 11 tokens"
    assert row["read_by"].startswith("**nothing**") and row["mb"] == pytest.approx(2.0, abs=0.1)
    assert row["quality"].startswith("val loss ")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ConfigError, match="no manifest.json"):
        rows(tmp_path, readers={})
