"""Per-episode Parquet rows, resumable by key, and the paper-style summary table.

``<out>/<run>/<method>/<env>/task=<k>/seed=<s>.parquet``, written to ``*.tmp`` then
``os.replace``d, so a killed job leaves either a whole row or none, and a rerun skips the
keys that exist: nothing lost, nothing duplicated. Only the job process writes here.
"""

from __future__ import annotations

import os
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from fmctd_dist.config import resolve_path
from fmctd_dist.errors import ResultsError
from fmctd_dist.evaluation.identity import row_identity


# Columns without which a Parquet file under a run dir is not one of our rows.
REQUIRED_COLUMNS = ("method", "env", "task", "seed", "success")


class ResultStore:
    """One Parquet file per episode under ``<out>/<run>``; unreadable files are reported, then re-run.

    A truncated or otherwise unreadable row file (a kill mid-copy, a full disk) counts as
    missing, so the episode is run again and the file replaced; it is listed in
    ``unreadable`` (and told by :meth:`report`) rather than skipped in silence. A readable
    file that lacks our columns is somebody else's data: one ResultsError, nothing touched.
    """

    def __init__(self, out: str | Path, run: str):
        self.root = resolve_path(out) / run
        self.unreadable: dict[Path, str] = {}

    def path(self, method: str, env: str, task: int, seed: int) -> Path:
        return self.root / method / env / f"task={task}" / f"seed={seed}.parquet"

    def read(self, path: Path) -> list[dict[str, Any]] | None:
        """The rows of one file; None (and noted in ``unreadable``) if it cannot be read."""
        try:
            table = pq.read_table(path)
        except (pa.ArrowException, OSError) as e:
            self.unreadable[path] = str(e).splitlines()[0] if str(e) else type(e).__name__
            return None
        lacking = [c for c in REQUIRED_COLUMNS if c not in table.column_names]
        if lacking:
            raise ResultsError(f"{path} is not a result row of this project (no column {', '.join(lacking)}); "
                               f"move it out of {self.root}, or write to another run with eval.run=<new name>")
        self.unreadable.pop(path, None)
        return table.to_pylist()

    def has(self, method: str, env: str, task: int, seed: int) -> bool:
        path = self.path(method, env, task, seed)
        return path.is_file() and self.read(path) is not None

    def write(self, row: dict[str, Any]) -> Path:
        path = self.path(row["method"], row["env"], row["task"], row["seed"])
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".parquet.tmp")
        pq.write_table(pa.Table.from_pylist([row]), tmp)
        os.replace(tmp, path)
        self.unreadable.pop(path, None)
        return path

    def rows(self, method: str | None = None, env: str | None = None) -> list[dict[str, Any]]:
        pattern = f"{method or '*'}/{env or '*'}/task=*/seed=*.parquet"
        out = []
        for f in sorted(self.root.glob(pattern)):
            out.extend(self.read(f) or [])
        return out

    @classmethod
    def directory_rows(cls, directory: str | Path) -> list[dict[str, Any]]:
        """The rows of one ``<out>/<run>/<method>/<env>`` directory (what the probes take); [] for a shorter path."""
        full = Path(directory).resolve()
        if len(full.parents) <= 2:
            return []
        return cls(full.parents[2], full.parents[1].name).rows(full.parent.name, full.name)

    def report(self) -> list[str]:
        """One line per unreadable row file (what a job prints before re-running those episodes)."""
        return [f"warning: {p} is unreadable ({why}); its episode is re-run and the file replaced"
                for p, why in sorted(self.unreadable.items())]


def summarise(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (method, env, identity): mean success % and planning time s, each ± std over seeds.

    As in the paper: a seed's score is its mean over the tasks, and the std is taken over
    seeds (so 100/0/100/100/100 per task at every seed reads 80 ± 0, not 80 ± 40). Rows of
    different configs or checkpoints (``identity.row_identity``) are never averaged together:
    each gets its own entry, and ``variant`` names it when a (method, env) has more than one.
    """
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["method"], r["env"], row_identity(r)), []).append(r)
    variants = Counter((method, env) for method, env, _ in groups)
    out = []
    for (method, env, ident), rs in sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1], -len(kv[1]),
                                                                           str(kv[0][2]))):
        chash, digest, limit = ident
        variant = ""
        if variants[(method, env)] > 1:
            variant = f"config {str(chash)[:8]}, ckpt {str(digest)[:8]}" + (f", limit {limit:g} s" if limit else "")
        seeds = sorted({r["seed"] for r in rs})
        succ = np.array([100.0 * np.mean([r["success"] for r in rs if r["seed"] == s]) for s in seeds])
        t = np.array([np.mean([r["plan_time_s"] for r in rs if r["seed"] == s]) for s in seeds])
        share = np.array([r["denoise_share"] for r in rs])
        out.append({
            "method": method, "env": env, "episodes": len(rs), "seeds": len(seeds), "variant": variant,
            "config_hash": chash, "checkpoint_digest": digest, "identity": ident,
            "success": succ.mean(), "success_std": succ.std(),
            "plan_time_s": t.mean(), "plan_time_std": t.std(),
            "denoise_share": share.mean(),
            "call_share": float(np.mean([r.get("call_share", np.nan) for r in rs])),
            "timed_out": int(sum(r.get("timed_out", False) for r in rs)),
            "per_task": {k: 100.0 * np.mean([r["success"] for r in rs if r["task"] == k])
                         for k in sorted({r["task"] for r in rs})},
        })
    return out


def label(s: dict[str, Any]) -> str:
    """A summary line's method cell: the method, and which config/checkpoint when there are several."""
    return f"{s['method']} [{s['variant']}]" if s.get("variant") else s["method"]


def markdown_table(summary: list[dict[str, Any]]) -> str:
    """The paper's format (success % ± std, planning time s ± std) with the paper's cell beside ours."""
    from fmctd_dist.evaluation.paper import paper_cell

    lines = ["| method | env | episodes | success (%) | planning time (s) | in denoiser | success per task | "
             "paper: success / time (GPU) |",
             "|---|---|---|---|---|---|---|---|"]
    for s in summary:
        per_task = "/".join(f"{v:.0f}" for v in s["per_task"].values())
        timed_out = f" ({s['timed_out']} timed out)" if s["timed_out"] else ""
        lines.append(f"| {label(s)} | {s['env']} | {s['episodes']} | {s['success']:.0f} ± {s['success_std']:.0f}"
                     f"{timed_out} | {s['plan_time_s']:.2f} ± {s['plan_time_std']:.2f} | "
                     f"{100 * s['denoise_share']:.0f}% | {per_task} | {paper_cell(s['method'], s['env'])} |")
    return "\n".join(lines)


def describe(row: dict[str, Any]) -> str:
    """One line per episode for logs: outcome, planning time and the share inside the denoiser."""
    outcome = "success" if row["success"] else ("TIMED OUT" if row["timed_out"] else "failure")
    return (f"{row['method']} {row['env']} task {row['task']} seed {row['seed']}: {outcome} after "
            f"{row['env_steps']} steps; planning {row['plan_time_s']:.2f}s "
            f"({100 * row['denoise_share']:.1f}% in denoiser), {row['expansions']} expansions, "
            f"{row['iterations']} iterations")
