"""Evaluation integrity: every field's range checked, results keyed by what produced them."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from fmctd_dist.config import REPO_ROOT, Config, Range, config_from_dict, field_ranges, load_config
from fmctd_dist.errors import ConfigError, ResultsError
from fmctd_dist.evaluation.grid import Prepared, missing, provenance
from fmctd_dist.evaluation.identity import CONFIG_SCHEMA, config_hash, plan_fields
from fmctd_dist.evaluation.report import paper_table
from fmctd_dist.registry import tables
from fmctd_dist.evaluation.results import ResultStore, markdown_table, summarise

GOLDEN_DEFAULTS = Path(__file__).parent / "golden" / "config_defaults.json"
NUMERIC = ("int", "float", "list[int]", "list[float]")


def numeric_fields(node=None, prefix=""):
    node = Config() if node is None else node
    out = []
    for f in dataclasses.fields(node):
        value = getattr(node, f.name)
        if dataclasses.is_dataclass(value):
            out += numeric_fields(value, f"{prefix}{f.name}.")
        elif f.type in NUMERIC:
            out.append((f"{prefix}{f.name}", f.type))
    return out


def out_of_range(rng: Range, ftype: str) -> str:
    """A value the range refuses, written as an override."""
    is_int = "int" in ftype
    if rng.ge is not None:
        bad = rng.ge - 1 if is_int else rng.ge - 0.5
    elif rng.gt is not None:
        bad = rng.gt
    elif rng.le is not None:
        bad = rng.le + 1
    else:
        bad = rng.lt
    bad = int(bad) if is_int else float(bad)
    return f"[{bad}]" if ftype.startswith("list") else str(bad)


FIELDS = numeric_fields()


def test_every_numeric_field_declares_its_range():
    ranges = field_ranges(Config())
    undeclared = [k for k, _ in FIELDS if k not in ranges or ranges[k].describe() == ""]
    assert not undeclared, f"numeric config fields without a declared range: {undeclared}"
    print(f"{len(FIELDS)} numeric config fields, each with a declared range")
    assert len(FIELDS) >= 40


@pytest.mark.parametrize("key, ftype", FIELDS, ids=[f"{i + 1}/{len(FIELDS)}:{k}" for i, (k, _) in enumerate(FIELDS)])
def test_out_of_range_value_is_one_config_error_naming_the_field(key, ftype):
    value = out_of_range(field_ranges(Config())[key], ftype)
    with pytest.raises(ConfigError) as e:
        load_config([f"{key}={value}"])
    assert str(e.value).startswith(f"{key}="), str(e.value)
    assert "must be" in str(e.value)


def test_non_finite_numbers_are_refused():
    for value in ("nan", "inf"):
        with pytest.raises(ConfigError, match="train.lr="):
            load_config([f"train.lr={value}"])


def test_a_key_given_twice_names_both_values():
    with pytest.raises(ConfigError) as e:
        load_config(["tasks=[7]", "seeds=[0]", "tasks=[1]"])
    msg = str(e.value)
    assert "eval.tasks" in msg and "[7]" in msg and "[1]" in msg and "twice" in msg


def test_config_defaults_keep_their_meaning():
    """A default that changes must bump CONFIG_SCHEMA (result rows hash the fields that differ from defaults)."""
    golden = json.loads(GOLDEN_DEFAULTS.read_text())
    now = {k: v for k, v in plan_fields(Config()).items()}
    changed = {k: (v, now.get(k, "<removed>")) for k, v in golden["defaults"].items() if now.get(k, "<removed>") != v}
    assert not changed or golden["schema"] != CONFIG_SCHEMA, (
        f"config defaults changed {changed}: bump identity.CONFIG_SCHEMA and rewrite {GOLDEN_DEFAULTS.name}")


def test_config_hash_ignores_where_the_grid_runs_but_not_the_plan():
    base = config_hash(load_config([]))
    assert config_hash(load_config(["eval.run=x", "ray.denoiser_actors=2", "seeds=[3]", "eval.threads=1",
                                    "data.workers=4"])) == base
    assert config_hash(load_config(["method.parallel=50"])) != base
    assert config_hash(load_config(["eval.episode_time_limit=60"])) != base


# ---- results keyed by config and checkpoint ----

def prepared(*overrides: str, digest: str = "d" * 16) -> Prepared:
    cfg = load_config(["tasks=[1,2]", "seeds=[0]", *overrides])
    return Prepared(cfg, Path("ckpt"), digest, "cpu", config_hash(cfg), "sha")


def fake_row(p: Prepared, task: int, seed: int, success: bool = True) -> dict:
    return {"method": p.cfg.method.name, "env": p.cfg.env.name, "task": task, "seed": seed, "success": success,
            "timed_out": False, "plan_time_s": 1.0, "denoise_share": 0.9, "expansions": 10, "iterations": 2,
            **provenance(p, 1)}


def test_rerun_with_another_config_is_refused_listing_what_differs(tmp_path):
    store = ResultStore(tmp_path, "r")
    p = prepared()
    store.write(fake_row(p, 1, 0))
    assert missing(p, store) == [(2, 0)]
    with pytest.raises(ResultsError) as e:
        missing(prepared("method.parallel=50", "method.warp_threshold=1.5"), store)
    msg = str(e.value)
    assert "method.parallel: rows have 200, this run has 50" in msg
    assert "method.warp_threshold: rows have 2.0, this run has 1.5" in msg
    assert "eval.run=<new name>" in msg and "aside" in msg
    with pytest.raises(ResultsError, match="checkpoint digest"):
        missing(prepared(digest="e" * 16), store)
    with pytest.raises(ConfigError, match="resume_mixed=true: removed in session 26.*eval.run=<new name>"):
        prepared("eval.resume_mixed=true")  # the opt-in that let a run mix them is gone, and says so


def test_a_stored_config_with_a_retired_field_still_loads():
    """Manifests and rows written while eval.resume_mixed existed hold it: they load, without it."""
    d = load_config([]).to_dict()
    d["eval"]["resume_mixed"] = False
    assert config_from_dict(d) == load_config([])


def test_rows_of_another_low_level_policy_are_refused(tmp_path):
    """The robot's low-level policy keys rows beside the planner checkpoint (a retrained ant or arm policy
    must not mix into a run), and an episode runner that loaded another policy than the job checked stops."""
    import dataclasses

    from fmctd_dist.errors import CheckpointError
    from fmctd_dist.evaluation.grid import same_policy

    store = ResultStore(tmp_path, "r")
    p = dataclasses.replace(prepared(), policy_digest="a" * 16)
    store.write(fake_row(p, 1, 0))
    assert missing(p, store) == [(2, 0)]
    with pytest.raises(ResultsError, match=f"low-level policy digest: rows have {'a' * 16}, this run has {'b' * 16}"):
        missing(dataclasses.replace(p, policy_digest="b" * 16), store)
    with pytest.raises(ResultsError, match="low-level policy digest: rows have a+, this run has none"):
        missing(prepared(), store)
    same_policy(p, type("Episodes", (), {"policy_digest": "a" * 16})())
    with pytest.raises(CheckpointError, match="env.policy changed while the job ran"):
        same_policy(p, type("Episodes", (), {"policy_digest": "c" * 16})())


def test_rows_from_before_config_json_list_their_knobs(tmp_path):
    store = ResultStore(tmp_path, "r")
    p = prepared()
    old = {k: v for k, v in fake_row(p, 1, 0).items() if k not in ("config_json", "config_schema")}
    store.write({**old, "config_hash": "0123456789abcdef"})
    with pytest.raises(ResultsError, match="parallel: rows have 200, this run has 50"):
        missing(prepared("method.parallel=50"), store)


def test_unreadable_row_is_reported_and_rerun(tmp_path):
    store = ResultStore(tmp_path, "r")
    p = prepared()
    path = store.write(fake_row(p, 1, 0))
    path.write_bytes(path.read_bytes()[:40])  # truncated by a kill mid-copy
    lines: list[str] = []
    assert missing(p, store, lines.append) == [(1, 0), (2, 0)]
    assert len(lines) == 1 and str(path) in lines[0] and "re-run" in lines[0]
    store.write(fake_row(p, 1, 0))
    assert missing(p, store) == [(2, 0)] and not store.report()


def test_foreign_parquet_is_one_clear_error(tmp_path):
    store = ResultStore(tmp_path, "r")
    path = store.path("fast-mctd", "pointmaze-medium", 1, 0)
    path.parent.mkdir(parents=True)
    pq.write_table(pa.table({"price": [1.0], "ticker": ["X"]}), path)
    with pytest.raises(ResultsError, match="not a result row of this project"):
        missing(prepared(), store)


def test_tables_never_average_different_configs():
    a, b = prepared(), prepared("method.parallel=50")
    rows = [fake_row(a, t, s, True) for t in (1, 2) for s in (0, 1)] + \
        [fake_row(b, t, s, False) for t in (1, 2) for s in (0, 1)]
    for r in rows:
        r["run"] = "main"
    summary = summarise(rows)
    assert sorted(s["success"] for s in summary) == [0.0, 100.0]
    assert all(s["variant"].startswith("config ") for s in summary)
    for table in (markdown_table(summary), paper_table(rows, tables()["maze"])):
        assert table.count("| fast-mctd [config ") == 2 and "| 50 ± 0 |" not in table


@pytest.mark.slow
def test_eval_job_refuses_a_changed_config_before_any_work(tiny_checkpoint, tmp_path):
    from test_planning import SEARCH, run_eval

    args, _ = tiny_checkpoint
    args = args + SEARCH + [f"eval.out={tmp_path}", "eval.run=t", "runner=local", "tasks=[1]", "seeds=[0]"]
    assert run_eval(args).returncode == 0
    files = list(tmp_path.rglob("*.parquet"))
    out = run_eval(args + ["method.uct_c=1.0"])
    assert out.returncode == 2 and out.stderr.startswith("error: ") and "Traceback" not in out.stderr
    assert "method.uct_c: rows have 1.4142135623730951, this run has 1.0" in out.stderr
    assert list(tmp_path.rglob("*.parquet")) == files
