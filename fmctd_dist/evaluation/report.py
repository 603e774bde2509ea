"""The paper-format report: every table in docs/results.md that comes from evaluation rows.

Rows are read from ``<results>/<run>/<method>/<env>/task=<k>/seed=<s>.parquet`` (the
ResultStore layout; a run name may contain ``/``, e.g. ``ablate-k/10``). The maze table uses
the run ``main``; each ablation reads the runs under its prefix and groups them by the search
knob its rows record (``parallel``, ``virtual_weight``, ...), so a row can never be filed
under the wrong setting. Tables are written between ``<!-- report:NAME -->`` markers, so the
prose around them stays hand-written and the numbers stay generated.
"""

from __future__ import annotations

import json
import re
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq

from fmctd_dist.records import Table
from fmctd_dist.registry import env_names
from fmctd_dist.evaluation.paper import paper_cell
from fmctd_dist.evaluation.identity import row_identity
from fmctd_dist.evaluation.results import label, summarise

def manifest_digest(checkpoint_dir: Path) -> str:
    """The digest a checkpoint directory's manifest records ("" when it is not on this machine): what a table
    compares a row's ``checkpoint_digest`` with to tell today's shipped weights from replaced ones."""
    path = Path(checkpoint_dir) / "manifest.json"
    return json.loads(path.read_text()).get("digest", "") if path.is_file() else ""


@dataclass(frozen=True)
class Ablation:
    """One ablation table: the runs ``<name>/*``, grouped by the row field ``knob``; ``name`` is
    also its marker in docs/results.md and its figure's file name."""

    name: str
    knob: str
    default: Any  # Fast-MCTD's setting: the row the "time / default" column divides by
    paper: dict[Any, str]  # knob value -> the paper's cell (P-MCTD, PointMaze-giant)


ABLATIONS = [
    Ablation("ablate-w", "virtual_weight", 1.0,
             {0.0: "221.3 ± 109.6 s", 0.1: "14.0 ± 2.5 s", 1.0: "12.8 ± 2.3 s", 5.0: "12.5 ± 2.1 s"}),
    Ablation("ablate-ras", "redundancy_aware", True,
             {True: "12.8 ± 2.5 s", False: "18.4 ± 0.9 s"}),
    Ablation("ablate-leaf", "leaf_parallel", False,
             {False: "100 ± 0 / 12.8 ± 2.5 s", True: "100 ± 0 / 17.0 ± 2.8 s"}),
    Ablation("ablate-k", "parallel", 200, {}),  # paper: a figure, no numbers
    Ablation("ablate-h", "jump", 5, {}),
]


def load_rows(root: str | Path, prefix: str = "") -> list[dict[str, Any]]:
    """Every row under ``root`` whose run name starts with ``prefix``; adds ``run`` to each."""
    root = Path(root)
    out = []
    for f in sorted(root.glob("**/task=*/seed=*.parquet")):
        run = "/".join(f.relative_to(root).parts[:-4])
        if _in_run(run, prefix):
            for r in pq.read_table(f).to_pylist():
                out.append({**r, "run": run})
    return out


def _in_run(run: str, prefix: str) -> bool:
    return not prefix or run == prefix or run.startswith(prefix + "/")


def row_key(r: dict[str, Any]) -> tuple:
    """An episode's identity across files: (run, method, env, task, seed)."""
    return r["run"], r["method"], r["env"], int(r["task"]), int(r["seed"])


def merge_rows(committed: list[dict[str, Any]], fresh: list[dict[str, Any]], prefix: str = "") -> list[dict[str, Any]]:
    """The committed rows (``docs/eval_rows.parquet``) under ``prefix``, each episode with a fresh row in
    ``results/`` (not in git: a fresh machine has only its own) replaced by it."""
    merged = {row_key(r): r for r in committed if _in_run(r["run"], prefix)}
    merged.update((row_key(r), r) for r in fresh if _in_run(r["run"], prefix))
    return [merged[k] for k in sorted(merged)]


def superseded(committed: list[dict[str, Any]], fresh: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The committed rows that a fresh row of the same episode replaces with another identity (new weights
    at the same path, another config or time limit), renamed to run ``superseded/<run>@<config>-<ckpt>``, so
    the archive (``docs/eval_rows.parquet``) keeps the episodes earlier text quotes, out of today's tables."""
    fresh_ids = {row_key(r): row_identity(r) for r in fresh}
    out = []
    for r in committed:
        if row_key(r) in fresh_ids and fresh_ids[row_key(r)] != row_identity(r):
            tag = f"{str(r.get('config_hash'))[:8]}-{str(r.get('checkpoint_digest'))[:8]}"
            out.append({**r, "run": f"superseded/{r['run']}@{tag}"})
    return out


def _pm(mean: float, std: float, fmt: str = ".0f") -> str:
    return f"{mean:{fmt}} ± {std:{fmt}}"


def _shares(s: dict[str, Any]) -> str:
    calls = "–" if np.isnan(s.get("call_share", np.nan)) else f"{100 * s['call_share']:.1f}%"
    return f"{100 * s['denoise_share']:.1f}% / {calls}"


def current_rows(rows: list[dict[str, Any]],
                 hashes: dict[tuple[str, str], str]) -> tuple[list[dict[str, Any]], dict[tuple, int]]:
    """The rows made with today's default config of their (method, env) (``hashes``: its config hash), from
    any run, one per episode and checkpoint, and per (method, env, identity) how many episodes were left out.

    An episode held by several runs is taken from the run holding the most episodes of its group, so a
    line's planning times come from as few runs as possible (and the choice is fixed where re-runs differ:
    docs/results.md 12.8.2). A seed counts only with every task of its group, so a grid stopped part-way
    weighs no task more in the per-seed means.
    """
    mine = [(r, (r["method"], r["env"], row_identity(r))) for r in rows
            if r.get("config_hash") and hashes.get((r["method"], r["env"])) == r["config_hash"]]
    runs = Counter((group, r["run"]) for r, group in mine)  # episodes per (group, run)
    best: dict[tuple, tuple[tuple[int, str], dict[str, Any]]] = {}
    for r, group in mine:
        key, rank = (group, int(r["task"]), int(r["seed"])), (runs[(group, r["run"])], r["run"])
        if key not in best or rank > best[key][0]:
            best[key] = (rank, r)
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for key in sorted(best, key=str):
        groups.setdefault(key[0], []).append(best[key][1])
    out, dropped = [], {}
    for group, rs in groups.items():
        tasks = {int(r["task"]) for r in rs}
        full = {s for s in {int(r["seed"]) for r in rs} if {int(r["task"]) for r in rs if int(r["seed"]) == s} == tasks}
        out += [r for r in rs if int(r["seed"]) in full]
        dropped[group] = sum(int(r["seed"]) not in full for r in rs)
    return out, dropped


def _lines(rows: list[dict[str, Any]]) -> dict[tuple[str, str], list[dict[str, Any]]]:
    """Per (method, env): its table lines, one summary per config/checkpoint (:func:`summarise`)."""
    key: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for s in summarise(rows):
        key.setdefault((s["method"], s["env"]), []).append(s)
    return key


def _method_cell(s: dict[str, Any], shipped: dict[tuple[str, str], str] | None) -> str:
    """The line's method cell; lines whose weights are not the checkpoint shipped today say so.

    A config names its checkpoint by path, so rows made before the weights at that path were replaced
    keep today's config hash: only the recorded digest tells them apart."""
    now = (shipped or {}).get((s["method"], s["env"]))
    if not now or str(s.get("checkpoint_digest")) == now:
        return label(s)
    which = "" if s.get("variant") else f" {str(s['checkpoint_digest'])[:8]}"  # a variant's label names its digest
    return f"{label(s)} (older weights{which}; shipped: {now[:8]})"


def paper_table(rows: list[dict[str, Any]], table: Table, dropped: dict[tuple, int] | None = None,
                shipped: dict[tuple[str, str], str] | None = None) -> str:
    """One of the paper's tables (a family record's :class:`~fmctd_dist.records.Table`): one line per (method,
    env) in the paper's order, ``dropped`` from :func:`current_rows`, said in the episodes cell, and
    ``shipped``: the digest of each (method, env)'s default checkpoint today, so that a line on older weights is
    marked. A (method, env) shows its lines on today's weights, else its largest on replaced ones."""
    shown = {s["identity"] for (m, env), ls in _lines(rows).items() for s in _shown(ls, (shipped or {}).get((m, env)))}
    key = _lines([r for r in rows if row_identity(r) in shown])  # a label names its config where shown lines differ
    # "in denoiser": share of planning time spent computing inside denoiser actors / inside denoiser calls
    # (the latter adds queueing behind other env actors and Ray transport; "–" for rows recorded before it existed)
    lines = ["| method | env | episodes (tasks x seeds) | success (%) | planning time (s) | "
             "in denoiser: compute / calls | success per task | paper: success / time (GPU) |",
             "|---|---|---|---|---|---|---|---|"]
    for env in table.envs:
        for m in table.methods:
            if (m, env) not in key:
                lines.append(f"| {m} | {env} | not run | | | | | {paper_cell(m, env)} |")
            for s in key.get((m, env), []):  # one line per config/checkpoint: never averaged together
                n_tasks = len(s["per_task"])
                timed_out = f" ({s['timed_out']} timed out)" if s["timed_out"] else ""
                partial = (dropped or {}).get((m, env, s["identity"]), 0)
                more = f"; {partial} more of unfinished seeds not counted" if partial else ""
                lines.append(
                    f"| {_method_cell(s, shipped)} | {env} | {s['episodes']} ({n_tasks} x {s['seeds']}{more}) | "
                    f"{_pm(s['success'], s['success_std'])}{timed_out} | "
                    f"{_pm(s['plan_time_s'], s['plan_time_std'], '.2f')} | "
                    f"{_shares(s)} | {'/'.join(f'{v:.0f}' for v in s['per_task'].values())} | "
                    f"{paper_cell(m, env)} |")
    return "\n".join(lines)


def _shown(lines: list[dict[str, Any]], shipped: str | None) -> list[dict[str, Any]]:
    """A table's lines of one (method, env): those on today's weights (several only where the identity differs
    in more than the weights), else its largest line on replaced weights, marked; all when nothing is known of
    what is shipped. The replaced lines stay in the rows (docs/eval_rows.parquet) and the notebook."""
    if not shipped:
        return lines
    today = [s for s in lines if str(s.get("checkpoint_digest")) == shipped]
    return today or [max(lines, key=lambda s: s["episodes"])] if lines else []


def _glance_line(lines: list[dict[str, Any]], shipped: str | None) -> tuple[dict[str, Any], bool]:
    """The line a cell shows: on today's weights if any is, then the one with the most episodes; and
    whether it is on today's weights."""
    today = [s for s in lines if not shipped or str(s.get("checkpoint_digest")) == shipped]
    pool = today or lines
    return max(pool, key=lambda s: s["episodes"]), bool(today)


def glance_table(rows: list[dict[str, Any]], tables: list[Table],
                 shipped: dict[tuple[str, str], str] | None = None,
                 elsewhere: set[tuple[str, str]] | None = None) -> str:
    """One cell per (method, env) of ``rows`` (:func:`current_rows`): our success % against the paper's, e.g.
    ``84 / 100``, from the line :func:`_glance_line` picks; row i holds each table's i-th method. ``†`` marks
    a cell whose lines are all on replaced weights, ``(n)`` a line of fewer than 50 episodes, ``‡`` a (method,
    env) in ``elsewhere``: run only at other settings."""
    key = _lines(rows)
    columns = {env: t.methods for t in tables for env in t.envs}
    short = [name for t in tables for name in (t.columns or t.envs)]
    lines = ["| method | " + " | ".join(short) + " |", "|---" * (len(columns) + 1) + "|"]
    for i in range(max(len(ms) for ms in columns.values())):
        cells = []
        for env, methods in columns.items():
            m = methods[i] if i < len(methods) else ""
            paper = paper_cell(m, env).split(" ", 1)[0]
            if (m, env) not in key:
                cells.append(f"{'‡' if (m, env) in (elsewhere or set()) else '–'} / {paper}")
                continue
            s, today = _glance_line(key[(m, env)], (shipped or {}).get((m, env)))
            few = f" ({s['episodes']})" if s["episodes"] < 50 else ""
            cells.append(f"{s['success']:.0f}{few}{'' if today else ' †'} / {paper}")
        names = list(dict.fromkeys(ms[i] for ms in columns.values() if i < len(ms)))
        lines.append(f"| {' / '.join(names)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _env_rank(env: str) -> tuple[int, str]:
    names = env_names()
    return (names.index(env) if env in names else len(names), env)


def ablation_summary(rows: list[dict[str, Any]], knob: str) -> list[dict[str, Any]]:
    """Per (env, knob value), mazes in the paper's order: success and planning time (± std over
    seeds), expansions, iterations. Settings are compared within a maze, never across."""
    out = []
    for env in sorted({r["env"] for r in rows}, key=_env_rank):
        env_rows = [r for r in rows if r["env"] == env and knob in r]
        for v in sorted({r[knob] for r in env_rows}):
            rs = [r for r in env_rows if r[knob] == v]
            for s in summarise([{**r, "method": "x"} for r in rs]):  # one entry per config/checkpoint
                mine = [r for r in rs if row_identity(r) == s["identity"]]
                out.append({**s, "value": v, "method": sorted({r["method"] for r in mine}),
                            "expansions": float(np.mean([r["expansions"] for r in mine])),
                            "iterations": float(np.mean([r["iterations"] for r in mine]))})
    return out


def ablation_table(ab: Ablation, rows: list[dict[str, Any]], shipped: set[str] | None = None) -> str:
    """``shipped``: the digest of every checkpoint shipped today; a line whose weights are none of them
    (replaced since: an ablation's checkpoint depends on its knob, e.g. one per jump) says "older weights"."""
    summary = ablation_summary(rows, ab.knob)
    refs = {s["env"]: s for s in summary if s["value"] == ab.default and type(s["value"]) is type(ab.default)}
    lines = [f"| {ab.knob} | method / env | episodes (tasks x seeds) | success (%) | planning time (s) | "
             f"time / default | expansions | iterations | in denoiser: compute / calls | "
             f"paper (P-MCTD, PointMaze-giant) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for s in summary:
        ref = refs.get(s["env"])
        ratio = f"{s['plan_time_s'] / ref['plan_time_s']:.2f}x" if ref else "–"
        timed_out = f" ({s['timed_out']} timed out)" if s["timed_out"] else ""
        variant = f" [{s['variant']}]" if s.get("variant") else ""
        digest = s.get("checkpoint_digest")
        older = f" (older weights {str(digest)[:8]})" if shipped is not None and digest not in shipped else ""
        lines.append(
            f"| {s['value']} | {','.join(s['method'])} / {s['env'].replace('pointmaze-', '')}{variant}{older} | "
            f"{s['episodes']} ({len(s['per_task'])} x {s['seeds']}) | "
            f"{_pm(s['success'], s['success_std'])}{timed_out} | "
            f"{_pm(s['plan_time_s'], s['plan_time_std'], '.2f')} | {ratio} | {s['expansions']:.0f} | "
            f"{s['iterations']:.1f} | {_shares(s)} | {ab.paper.get(s['value'], '–')} |")
    return "\n".join(lines)


def fill_markers(text: str, sections: dict[str, str]) -> str:
    """Replace the body between ``<!-- report:NAME -->`` and ``<!-- /report:NAME -->`` for each NAME."""
    for name, body in sections.items():
        pattern = re.compile(rf"(<!-- report:{re.escape(name)} -->\n).*?(<!-- /report:{re.escape(name)} -->)", re.S)
        if not pattern.search(text):
            raise KeyError(f"docs/results.md has no '<!-- report:{name} -->' ... '<!-- /report:{name} -->' block")
        text = pattern.sub(lambda m: m.group(1) + body.rstrip() + "\n" + m.group(2), text)
    return text
