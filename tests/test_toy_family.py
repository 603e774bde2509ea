"""A new env family plugs in by its package, one registry record and its configs only (docs/adding-a-family.md).

The toy family (tests/toy_family: a point on an open plane) is registered here as a newcomer would
register theirs, then trained, evaluated and reported through the jobs, with nothing of the core changed.
"""

from __future__ import annotations

import pytest

from conftest import TINY_MODEL, load_job
from fmctd_dist import registry

SEARCH = ["method=p-mctd", "method.parallel=8", "method.budget=24"]


@pytest.fixture
def toy_family(monkeypatch):
    monkeypatch.setitem(registry.FAMILIES, "toy", "toy_family.record")  # step 2: its registry record
    registry.records.cache_clear()
    registry.env_specs.cache_clear()
    yield
    monkeypatch.undo()
    registry.records.cache_clear()
    registry.env_specs.cache_clear()


def test_a_toy_family_trains_evaluates_and_reports(toy_family, tmp_path, capsys):
    from fmctd_dist.config import load_config
    from fmctd_dist.families import hooks_for

    data = [f"data.root={tmp_path / 'data'}"]
    ckpt = tmp_path / "toy-plane-h1"
    assert load_config(["env=toy-plane"]).env.max_steps == 100  # its config, read from its own folder
    assert hooks_for("toy-plane").__name__ == "toy_family.hooks"
    assert load_job("make_dataset").main(["env=toy-plane", *data]) == 0
    train = ["env=toy-plane", "jump=1", *TINY_MODEL, *data, "train.max_steps=30", "train.batch_size=16",
             "train.ckpt_every=30", "train.val_every=30", "train.val_batches=1", f"train.out={ckpt}"]
    assert load_job("train").main(train) == 0
    grid = ["env=toy-plane", *SEARCH, *TINY_MODEL, *data, f"checkpoint={ckpt}", "runner=local", "tasks=[1,2]",
            "seeds=[0]", f"eval.out={tmp_path / 'results'}", "eval.run=main"]
    assert load_job("eval").main(grid) == 0
    table = capsys.readouterr().out
    assert "| p-mctd | toy-plane | 2 |" in table, table
    doc = tmp_path / "results.md"
    doc.write_text("# Results\n\n<!-- report:families -->\n<!-- /report:families -->\n")
    assert load_job("report").main([f"results={tmp_path / 'results'}", f"doc={doc}",
                                    f"figures={tmp_path / 'figures'}"]) == 0
    assert "| p-mctd | toy-plane | 2 |" in doc.read_text(), doc.read_text()


def test_an_unregistered_family_is_refused(toy_family, monkeypatch):
    from fmctd_dist.config import load_config
    from fmctd_dist.errors import ConfigError

    monkeypatch.delitem(registry.FAMILIES, "toy")
    registry.records.cache_clear()
    registry.env_specs.cache_clear()
    with pytest.raises(ConfigError, match="toy-plane"):
        load_config(["env=toy-plane"])
