"""The visual maze table (issue 21): the paper's Table "Visual maze results", generated from archived rows.

The maze tables take one run (``main``) on today's default configs. The visual lines cannot: each cell
was run on the model and settings docs/results.md section 13 chose for it (the paper's latent planner, or
our [z, x, y] frames; the maze rule's warp threshold, or a wider one), over many sessions. So
:data:`VISUAL_LINES` names the run of each line, and every line prints what its rows' config changes
against the method's default (``load_config([env, method])``) and which weights made it, so no cell
hides its settings and a line is never averaged with another config or checkpoint (one line per
identity, :func:`fmctd_dist.evaluation.results.summarise`).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

from fmctd_dist.config import Config, load_config
from fmctd_dist.evaluation.identity import changed_fields, row_identity
from fmctd_dist.evaluation.paper import paper_cell
from fmctd_dist.evaluation.plan_tally import plan_statuses
from fmctd_dist.evaluation.results import summarise
from fmctd_dist.families.visual.record import VISUAL_ENVS, VISUAL_METHODS

# config keys that say what a row is, not how it differs (the method and env name themselves)
_NAMES = ("env.name", "method.name")


@dataclass(frozen=True)
class VisualLine:
    """One line of the table: a method on a maze, read from one run (section 13 cites the command)."""

    method: str
    env: str
    run: str
    note: str = ""  # why this line is in the table (e.g. "the paper's latent planner")
    episodes: int = 0  # the grid its run is meant to fill, for a run still going (0: the tasks x seeds its rows cover)


# The lines of today's table, in the paper's order. A method x maze may have several (the paper's own
# setting beside our best one); a pair with none prints "not run".
VISUAL_LINES: tuple[VisualLine, ...] = (
    VisualLine("diffuser", "visual-pointmaze-medium", "visual-methods-s14"),
    VisualLine("diffuser-replan", "visual-pointmaze-medium", "visual-methods-s14"),
    VisualLine("diffusion-forcing", "visual-pointmaze-medium", "visual-s29-default", "latent, H=5"),
    VisualLine("diffusion-forcing", "visual-pointmaze-medium", "visual-s31-xy-dense", "[z, x, y], H=1"),
    VisualLine("mctd", "visual-pointmaze-medium", "visual-s30-side", "latent"),
    VisualLine("p-mctd", "visual-pointmaze-medium", "visual-s33-default", "latent"),
    VisualLine("s-mctd", "visual-pointmaze-medium", "visual-s29-default-warp8", "latent, warp 8"),
    VisualLine("fast-mctd", "visual-pointmaze-medium", "visual-s29-default", "latent, the maze rule"),
    VisualLine("fast-mctd", "visual-pointmaze-medium", "visual-s32-bg8", "[z, x, y] + boundary guidance"),
    VisualLine("mctd-replan", "visual-pointmaze-medium", "visual-replan-medium-xy", "[z, x, y]", episodes=10),
    VisualLine("fast-mctd-replan", "visual-pointmaze-medium", "visual-s29-default-warp8", "latent, warp 8"),
    VisualLine("diffuser", "visual-pointmaze-large", "visual-methods-s14"),
    VisualLine("diffuser-replan", "visual-pointmaze-large", "visual-methods-s14"),
    VisualLine("diffusion-forcing", "visual-pointmaze-large", "visual-s35-large-xy-h5", "[z, x, y], H=5"),
    VisualLine("diffusion-forcing", "visual-pointmaze-large", "visual-s35-large-xy", "[z, x, y], H=1"),
    VisualLine("mctd", "visual-pointmaze-large", "visual-s35-large-xy", "[z, x, y]"),
    VisualLine("p-mctd", "visual-pointmaze-large", "visual-s35-large-xy", "[z, x, y]"),
    VisualLine("s-mctd", "visual-pointmaze-large", "visual-s35-large-xy-bg8", "[z, x, y] + boundary guidance"),
    VisualLine("fast-mctd", "visual-pointmaze-large", "visual-s33-large-xy-bg8", "[z, x, y] + boundary guidance"),
    VisualLine("mctd-replan", "visual-pointmaze-large", "visual-replan-large-xy", "[z, x, y]", episodes=10),
    VisualLine("fast-mctd-replan", "visual-pointmaze-large", "visual-s35-large-xy-bg8",
               "[z, x, y] + boundary guidance"),
)


@lru_cache(maxsize=None)
def _default_config(method: str, env: str) -> Config:
    return load_config([f"env={env}", f"method={method}"])


def settings(row: dict[str, Any]) -> str:
    """What the row's config changes against its method's default on its env, e.g.
    ``visual.plan_xy=True, diffusion.boundary_guidance=8.0`` ("default" when nothing)."""
    diff = changed_fields(row, _default_config(row["method"], row["env"]))
    return ", ".join(f"{k}={a}" for k, (a, _) in diff.items() if k not in _NAMES) or "default"


def search_statuses(rows: list[dict[str, Any]]) -> str:
    """How a line's plans ended, counted over all its plans (``stay 10``, ``not_reached 9, stay 1``): a 0% search
    line that only ever returned "stay" (every candidate warped) reads differently from one that planned and
    missed. Planners without a search report every plan as "plan": "no search"."""
    counts = sum((plan_statuses(r) for r in rows), Counter())
    if set(counts) <= {"plan"}:
        return "no search"
    return ", ".join(f"{k} {v}" for k, v in counts.most_common())


def visual_table(rows: list[dict[str, Any]], lines: tuple[VisualLine, ...] = VISUAL_LINES) -> str:
    """Markdown: per maze, the paper's methods in its order, each :data:`VISUAL_LINES` line summarised from
    the rows of its run, with its settings, weights and run beside the paper's cell."""
    out = ["| method | maze | episodes (tasks x seeds) | success (%) | per task | planning s per episode | "
           "searches' status | model: digest, jump | settings against the method's default | run | "
           "paper: success / time (GPU) |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    for env in VISUAL_ENVS:
        maze = env.rsplit("-", 1)[1]
        for method in VISUAL_METHODS:
            mine = [ln for ln in lines if ln.method == method and ln.env == env]
            paper = paper_cell(method, env)
            if not mine:
                out.append(f"| {method} | {maze} | not run | | | | | | | | {paper} |")
            for ln in mine:
                rs = [r for r in rows if r["run"] == ln.run and r["method"] == method and r["env"] == env]
                if not rs:
                    out.append(f"| {method} | {maze} | no rows yet | | | | | | | `{ln.run}` | {paper} |")
                    continue
                for s in summarise(rs):  # one line per config / checkpoint, never averaged together
                    line_rows = [r for r in rs if row_identity(r) == s["identity"]]
                    one = line_rows[0]
                    name = f"{method} ({ln.note})" if ln.note else method
                    per_task = "/".join(f"{v:.0f}" for v in s["per_task"].values())
                    grid = max(ln.episodes, len(s["per_task"]) * s["seeds"])  # a run still going fills part of it
                    partial = f", partial: {s['episodes']} of {grid}" if s["episodes"] < grid else ""
                    out.append(
                        f"| {name} | {maze} | {s['episodes']} ({len(s['per_task'])} x {s['seeds']}{partial}) | "
                        f"{s['success']:.0f} ± {s['success_std']:.0f} | {per_task} | "
                        f"{s['plan_time_s']:.1f} ± {s['plan_time_std']:.1f} | {search_statuses(line_rows)} | "
                        f"`{str(s['checkpoint_digest'])[:8]}`, H={one.get('jump')} | {settings(one)} | "
                        f"`{ln.run}` | {paper} |")
    return "\n".join(out)
