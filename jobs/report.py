"""Regenerate the evaluation tables and figures of docs/results.md from the Parquet rows.

    python jobs/report.py          # results/ -> docs/results.md + docs/figures/ + checkpoints/README.md + README.md
    python jobs/report.py results=/tmp/res doc=/tmp/results.md
    python jobs/report.py --checkpoints            # only checkpoints/README.md, from the checkpoints' manifests

Reads the run ``main`` (the maze tables: every method x PointMaze / AntMaze maze) and the ablation runs
``ablate-w/*``, ``ablate-ras/*``, ``ablate-leaf/*``, ``ablate-k/*``, ``ablate-h/*`` (made by
``jobs/eval.py ... eval.run=ablate-k/10`` etc.; the commands are in docs/results.md), and
rewrites only the blocks between ``<!-- report:NAME -->`` markers. Runs cited by hand-written
sections (cubes, visual maze, recipe and option benches: ``ARCHIVED``) are not tabulated here but
their rows are archived with the rest; the exceptions are the robot table (block ``robot``):
every archived cube episode whose config hash is today's default for its method and env, and the
visual table (block ``visual``): the lines ``fmctd_dist/families/visual/table.py`` names, one run each. The block
``glance`` at the doc's top, where the doc has one, puts one success cell per method x env of those
tables beside the paper's. An episode
re-run with another identity (retrained weights at the same path) keeps its earlier row in the archive,
under run ``superseded/<run>@<config>-<ckpt>``, out of the tables. Also writes
``docs/eval_rows.parquet``: every row without its plan/trajectory arrays, so each number in the
tables can be traced to its episodes from git alone. That file is also read back: the tables are
its rows with each episode that ``results/`` also holds replaced by the fresh row, so a fresh
machine (no ``results/``) adds rows without losing earlier sessions' ones.

``checkpoints/README.md`` (every shipped checkpoint dir: what it is, digest, lineage, hours, quality, who reads
it; ``fmctd_dist/checkpoint_index.py``) is rewritten too when the doc is the project's own docs/results.md, and
alone with ``--checkpoints``; tests/test_checkpoint_index.py holds the committed file to the manifests.
"""

from __future__ import annotations

import importlib

import pyarrow as pa
import pyarrow.parquet as pq

from fmctd_dist.checkpoint_index import write_index
from fmctd_dist.families import hooks_for
from fmctd_dist.cli import run
from fmctd_dist.config import REPO_ROOT, Config, load_config, resolve_path
from fmctd_dist.evaluation.identity import config_hash
from fmctd_dist.evaluation.plots import plot_ablation, plot_success_vs_time
from fmctd_dist.evaluation.report import ABLATIONS, ablation_summary, ablation_table, current_rows, fill_markers, \
    glance_table, load_rows, manifest_digest, merge_rows, paper_table, row_key, superseded
from fmctd_dist.registry import tables
from fmctd_dist.evaluation.results import markdown_table, summarise
from fmctd_dist.errors import ConfigError


# run-name prefixes whose rows are archived in docs/eval_rows.parquet without a regenerated table
ARCHIVED = ("cube-", "visual-", "pool", "recipe-", "s10-", "s32-bg", "campaign-", "wall-", "side-", "superseded/")
# per-step arrays left out of the archive (git keeps the scalars; results/ keeps the rest)
TRAJECTORIES = ("plan_xy", "traj_xy", "plan_cubes", "traj_cubes", "traj_effector")


def parse(argv: list[str]) -> dict[str, str]:
    opts = {"results": "results", "doc": "docs/results.md", "figures": "docs/figures"}
    for a in argv:
        key, sep, value = a.partition("=")
        if not sep or key not in opts:
            raise ConfigError(f"report: unknown argument {a!r}; expected any of "
                              + ", ".join(f"{k}=<path>" for k in opts))
        opts[key] = value
    return opts


def shipped_digest(cfg: Config) -> str:
    """The digest of the checkpoint ``cfg`` names today ("" when it is not on this machine)."""
    return manifest_digest(cfg.checkpoint_dir())


def today(envs: list[str], methods: list[str]) -> tuple[dict[tuple[str, str], str], dict[tuple[str, str], str]]:
    """Per (method, env): the hash of today's default config, and the digest of its default checkpoint today
    (so a table line on weights that were replaced since, same path and so same config hash, is marked "older
    weights" instead of passing for today's)."""
    cfgs = {(m, e): load_config([f"env={e}", f"method={m}"]) for e in envs for m in methods}
    return {k: config_hash(c) for k, c in cfgs.items()}, {k: shipped_digest(c) for k, c in cfgs.items()}


def main(argv: list[str]) -> int:
    if "--checkpoints" in argv:
        if len(argv) > 1:
            raise ConfigError("report: --checkpoints takes no other argument (it rewrites checkpoints/README.md only)")
        print(f"wrote {write_index(hooks_for).relative_to(REPO_ROOT)}")
        return 0
    opts = parse(argv)
    root, doc, figures = resolve_path(opts["results"]), resolve_path(opts["doc"]), resolve_path(opts["figures"])
    lean_path = doc.parent / "eval_rows.parquet"
    committed = pq.read_table(lean_path).to_pylist() if lean_path.is_file() else []
    if not root.is_dir() and not committed:
        raise ConfigError(f"report: results={root} does not exist and there is no {lean_path}; "
                          f"write rows there first with `python jobs/eval.py eval.out={root}`, or point results= "
                          "at the eval.out dir of an earlier evaluation")
    fresh = load_rows(root) if root.is_dir() else []
    committed += superseded(committed, fresh)  # re-run episodes keep their earlier rows, under their own run
    sections: dict[str, str] = {}
    all_rows = []

    main_rows = merge_rows(committed, fresh, "main")
    all_rows += main_rows
    every_shipped = {manifest_digest(m.parent) for m in (REPO_ROOT / "checkpoints").glob("*/manifest.json")}
    for ab in ABLATIONS:
        rows = merge_rows(committed, fresh, ab.name)
        all_rows += rows
        if rows:
            sections[ab.name] = ablation_table(ab, rows, every_shipped)
            if ab.knob in ("parallel", "jump"):
                plot_ablation(ablation_summary(rows, ab.knob), ab.knob, figures / f"{ab.name}.png")

    # runs cited by sections that are not regenerated from rows (cubes, visual maze, benches): their rows are
    # kept in eval_rows.parquet too, so every number in docs/results.md traces to its episodes from git alone
    archived = {row_key(r): r for r in committed + fresh if r["run"].startswith(ARCHIVED)}
    archived_rows = [archived[k] for k in sorted(archived)]
    all_rows += archived_rows

    # the paper's tables, one per family table (registry records): every episode of run main (where eval.py and
    # jobs/paper_tables.sh write) and of the archived runs made with today's default config of its method and env
    text = doc.read_text()
    now: list[dict] = []
    elsewhere = {(r["method"], r["env"]) for r in main_rows + archived_rows}
    shipped: dict[tuple[str, str], str] = {}
    for table in tables().values():
        if f"<!-- report:{table.name} -->" not in text:
            continue
        if table.render:  # a table with its own layout (the visual maze: each line's model and training)
            module, _, fn = table.render.partition(":")
            sections[table.name] = getattr(importlib.import_module(module), fn)(main_rows + archived_rows)
            continue
        hashes, digests = today(list(table.envs), list(table.methods))
        shipped |= digests
        rows, dropped = current_rows([r for r in main_rows + archived_rows if r["env"] in table.envs], hashes)
        if rows:
            now += rows if table.glance else []
            sections[table.name] = paper_table(rows, table, dropped, digests)
        for env in table.envs:  # one plan per env of the table's last method, drawn with what the robot executed
            # committed rows carry no trajectories: an env without fresh rows keeps its figure
            rs = sorted((r for r in main_rows if r["method"] == table.methods[-1] and r["env"] == env
                         and "plan_xy" in r), key=lambda r: (not r["success"], r["task"], r["seed"]))
            if rs:
                hooks_for(env).plot_episode(rs[0], figures / f"plan_{env}.png")
    if "maze" in sections:
        plot_success_vs_time(summarise([r for r in now if r["env"] in tables()["maze"].envs]),
                             figures / "success_vs_time.png")

    # any other family's rows of run main (a family added after the paper's): the table jobs/eval.py prints
    paper_envs = {e for t in tables().values() for e in t.envs}
    if "<!-- report:families -->" in text:
        sections["families"] = markdown_table(summarise([r for r in main_rows if r["env"] not in paper_envs]))

    # the at-a-glance block at the top of the doc: the tables above, one success cell each
    if "<!-- report:glance -->" in text:
        sections["glance"] = glance_table(now, [t for t in tables().values() if t.glance], shipped, elsewhere)
    text = fill_markers(text, sections)
    doc.write_text(text)
    if all_rows:
        keys = [k for k in dict.fromkeys(k for r in all_rows for k in r) if k not in TRAJECTORIES]
        pq.write_table(pa.table({k: [r.get(k) for r in all_rows] for k in keys}), lean_path)  # union of columns
    for name, body in sections.items():
        print(f"## {name}\n{body}\n")
    if doc == resolve_path("docs/results.md"):  # the project's docs, not a copy elsewhere (tests write to tmp)
        print(f"wrote {write_index(hooks_for).relative_to(REPO_ROOT)}")
        if "glance" in sections:  # the README shows the same glance table
            readme = REPO_ROOT / "README.md"
            readme.write_text(fill_markers(readme.read_text(), {"glance": sections["glance"]}))
            print("wrote README.md (its glance block)")
    print(f"{len(all_rows)} rows ({len(fresh)} fresh from {root}, the rest from {lean_path.name}); "
          f"updated {len(sections)} blocks in "
          f"{doc.relative_to(REPO_ROOT) if doc.is_relative_to(REPO_ROOT) else doc}; figures in {figures}")
    return 0


if __name__ == "__main__":
    run(main)
