"""The README a newcomer reads: short, its commands the ones CI and the pins use, its results generated."""

from __future__ import annotations

import re

from fmctd_dist.config import REPO_ROOT

README = (REPO_ROOT / "README.md").read_text()


def block(text: str, name: str) -> str:
    return re.search(rf"<!-- report:{name} -->\n(.*?)<!-- /report:{name} -->", text, re.S).group(1)


def test_the_readme_is_short():
    assert len(README.splitlines()) <= 200


def test_ci_runs_the_readme_test_command_word_for_word():
    command = "pip install torch==2.13.0 && pip install -e '.[dev]' -c constraints.txt && python -m pytest"
    assert command in README
    assert command in (REPO_ROOT / ".ci" / "run").read_text()
    assert "pip install torch==2.13.0 && pip install -e . -c constraints.txt && python jobs/eval.py" in README


def test_the_pins_cover_the_test_tools():
    pins = dict(line.split("==") for line in (REPO_ROOT / "constraints.txt").read_text().splitlines()
                if "==" in line and not line.startswith("#"))
    for package in ("pytest", "pytest-xdist", "ray", "numpy", "omegaconf", "mujoco", "gymnasium", "pyarrow",
                    "ogbench"):
        assert package in pins, package
    assert "torch" not in pins  # pinned in the command, so a GPU machine picks its CUDA wheel


def test_the_glance_table_is_the_generated_one():
    # jobs/report.py writes the same block into docs/results.md and the README
    assert block(README, "glance") == block((REPO_ROOT / "docs" / "results.md").read_text(), "glance")


def test_no_history_in_the_readme():
    assert not re.search(r"\bsession \d+|\bsessions? \d+", README, re.I)
