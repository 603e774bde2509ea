"""Per-episode Parquet rows, resumable by key, and the paper-style summary table.

``<out>/<run>/<method>/<env>/task=<k>/seed=<s>.parquet``, written to ``*.tmp`` then
``os.replace``d, so a killed job leaves either a whole row or none, and a rerun skips the
keys that exist: nothing lost, nothing duplicated. Only the job process writes here.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from fmctd_dist.config import resolve_path


class ResultStore:
    def __init__(self, out: str | Path, run: str):
        self.root = resolve_path(out) / run

    def path(self, method: str, env: str, task: int, seed: int) -> Path:
        return self.root / method / env / f"task={task}" / f"seed={seed}.parquet"

    def has(self, method: str, env: str, task: int, seed: int) -> bool:
        return self.path(method, env, task, seed).is_file()

    def write(self, row: dict[str, Any]) -> Path:
        path = self.path(row["method"], row["env"], row["task"], row["seed"])
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".parquet.tmp")
        pq.write_table(pa.Table.from_pylist([row]), tmp)
        os.replace(tmp, path)
        return path

    def rows(self, method: str | None = None, env: str | None = None) -> list[dict[str, Any]]:
        pattern = f"{method or '*'}/{env or '*'}/task=*/seed=*.parquet"
        out = []
        for f in sorted(self.root.glob(pattern)):
            out.extend(pq.read_table(f).to_pylist())
        return out


def summarise(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (method, env): mean success % and planning time s, each ± std over seeds.

    As in the paper: a seed's score is its mean over the tasks, and the std is taken over
    seeds (so 100/0/100/100/100 per task at every seed reads 80 ± 0, not 80 ± 40).
    """
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["method"], r["env"]), []).append(r)
    out = []
    for (method, env), rs in sorted(groups.items()):
        seeds = sorted({r["seed"] for r in rs})
        succ = np.array([100.0 * np.mean([r["success"] for r in rs if r["seed"] == s]) for s in seeds])
        t = np.array([np.mean([r["plan_time_s"] for r in rs if r["seed"] == s]) for s in seeds])
        share = np.array([r["denoise_share"] for r in rs])
        out.append({
            "method": method, "env": env, "episodes": len(rs), "seeds": len(seeds),
            "success": succ.mean(), "success_std": succ.std(),
            "plan_time_s": t.mean(), "plan_time_std": t.std(),
            "denoise_share": share.mean(),
            "call_share": float(np.mean([r.get("call_share", np.nan) for r in rs])),
            "timed_out": int(sum(r.get("timed_out", False) for r in rs)),
            "per_task": {k: 100.0 * np.mean([r["success"] for r in rs if r["task"] == k])
                         for k in sorted({r["task"] for r in rs})},
        })
    return out


def markdown_table(summary: list[dict[str, Any]]) -> str:
    """The paper's format (success % ± std, planning time s ± std) with the paper's cell beside ours."""
    from fmctd_dist.evaluation.paper import paper_cell

    lines = ["| method | env | episodes | success (%) | planning time (s) | in denoiser | success per task | "
             "paper: success / time (GPU) |",
             "|---|---|---|---|---|---|---|---|"]
    for s in summary:
        per_task = "/".join(f"{v:.0f}" for v in s["per_task"].values())
        timed_out = f" ({s['timed_out']} timed out)" if s["timed_out"] else ""
        lines.append(f"| {s['method']} | {s['env']} | {s['episodes']} | {s['success']:.0f} ± {s['success_std']:.0f}"
                     f"{timed_out} | {s['plan_time_s']:.2f} ± {s['plan_time_std']:.2f} | "
                     f"{100 * s['denoise_share']:.0f}% | {per_task} | {paper_cell(s['method'], s['env'])} |")
    return "\n".join(lines)
