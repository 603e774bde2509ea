"""The visual maze table (issue 21): the paper's Table "Visual maze results", one line per method and maze.

Like the maze tables, a cell holds only episodes made with today's default config of its (method, env)
(``configs/env/visual-pointmaze-*.yaml``, its ``methods:`` section included) on today's shipped planner and
inverse dynamics, from any archived run (:func:`fmctd_dist.evaluation.report.current_rows`). One rule is
the visual table's own, for rows made before these defaults existed: a row whose config names the shipped
planner's directory (or another copy of the same weights) in ``checkpoint=`` counts as a default row when its
weights' digest is the shipped one, because a path only says where the weights were read and the digest says
what they are. Every other difference keeps a row out of the table: its run stays in the archive and in the
notebook (docs/notebook/visual-maze.md).
"""

from __future__ import annotations

import json
from collections import Counter
from functools import lru_cache
from typing import Any

from fmctd_dist.config import Config, load_config
from fmctd_dist.evaluation.identity import changed_fields, config_hash
from fmctd_dist.evaluation.paper import paper_cell
from fmctd_dist.evaluation.plan_tally import plan_statuses
from fmctd_dist.evaluation.report import current_rows, manifest_digest
from fmctd_dist.evaluation.results import summarise
from fmctd_dist.families.visual.record import VISUAL_ENVS, VISUAL_METHODS

# config keys that say what a row is, not how it differs (the method and env name themselves)
_NAMES = ("env.name", "method.name")


@lru_cache(maxsize=None)
def default_config(method: str, env: str) -> Config:
    return load_config([f"env={env}", f"method={method}"])


@lru_cache(maxsize=None)
def shipped(method: str, env: str) -> tuple[str, str]:
    """(planner digest, inverse dynamics digest) of the default config's checkpoints today ("" when absent)."""
    from fmctd_dist.families.visual.config import part_dir

    cfg = default_config(method, env)
    return manifest_digest(cfg.checkpoint_dir()), manifest_digest(part_dir(cfg, "", "invdyn"))


def at_default(row: dict[str, Any]) -> bool:
    """Was ``row`` made with its (method, env)'s default config on today's shipped weights (module docstring)?"""
    planner, invdyn = shipped(row["method"], row["env"])
    if row.get("checkpoint_digest") != planner or (row.get("policy_digest") or "") != invdyn:
        return False
    diff = changed_fields(row, default_config(row["method"], row["env"]))
    return not set(diff) - {*_NAMES, "checkpoint"}


def default_rows(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The visual rows at their default (:func:`at_default`), each carrying its default's config hash, so the
    rows of one (method, env) form one identity whichever way their run named the shipped checkpoint."""
    return [{**r, "config_hash": config_hash(default_config(r["method"], r["env"]))}
            for r in rows if r["env"] in VISUAL_ENVS and r["method"] in VISUAL_METHODS and at_default(r)]


def training(cfg: Config) -> str:
    """What the default planner saw against the paper's training: windows (steps x batch over its whole lineage of
    continued runs) and train episodes in its latent store, e.g. ``9.4 M windows (4.6%), 100 episodes``."""
    from fmctd_dist.diffusion.train import PAPER_TRAINING

    path = cfg.checkpoint_dir() / "manifest.json"
    if not path.is_file():
        return "not on this machine"
    m = json.loads(path.read_text())
    paper = PAPER_TRAINING[m.get("model_kind", "df")]
    seen = m.get("lineage_samples") or int(m["train_steps"]) * int(m["config"]["train"]["batch_size"])
    episodes = m.get("latents", {}).get("episodes") or []
    return (f"{seen / 1e6:.1f} M windows ({100 * seen / (paper['steps'] * paper['batch_size']):.1f}%), "
            f"{len(episodes)} episodes")


def deviations(cfg: Config) -> str:
    """What the default plans differently from the paper's visual planners (latent frames, no extra guidance)."""
    out = ["[z, x, y] frames" if cfg.visual.plan_xy else "latent frames (the paper's)"]
    if cfg.diffusion.boundary_guidance > 0:
        out.append(f"boundary guidance {cfg.diffusion.boundary_guidance:g}")
    if cfg.env.warp_dense or cfg.env.warp_sparse:
        out.append(f"warp threshold {cfg.env.warp_dense if cfg.jump == 1 else cfg.env.warp_sparse:g}")
    return ", ".join(out)


def search_statuses(rows: list[dict[str, Any]]) -> str:
    """How a line's plans ended, counted over all its plans (``stay 10``, ``not_reached 9, stay 1``): a 0% search
    line that only ever returned "stay" (every candidate warped) reads differently from one that planned and
    missed. Planners without a search report every plan as "plan": "no search"."""
    counts = sum((plan_statuses(r) for r in rows), Counter())
    if set(counts) <= {"plan"}:
        return "no search"
    return ", ".join(f"{k} {v}" for k, v in counts.most_common())


def visual_table(rows: list[dict[str, Any]]) -> str:
    """Markdown: per maze, the paper's methods in its order, each summarised from its default rows (any run),
    with its model, what its default changes against the paper, its runs and the paper's cell."""
    hashes = {(m, e): config_hash(default_config(m, e)) for e in VISUAL_ENVS for m in VISUAL_METHODS}
    mine, _ = current_rows(default_rows(rows), hashes)
    out = ["| method | maze | episodes (tasks x seeds) | success (%) | per task | planning s per episode | "
           "searches' status | model: digest, jump | its training (of the paper's) | ours against the paper | runs | "
           "paper: success / time (GPU) |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for env in VISUAL_ENVS:
        maze = env.rsplit("-", 1)[1]
        for method in VISUAL_METHODS:
            cfg, paper = default_config(method, env), paper_cell(method, env)
            rs = [r for r in mine if r["method"] == method and r["env"] == env]
            if not rs:
                out.append(f"| {method} | {maze} | no episodes at the default yet | | | | | | {training(cfg)} | "
                           f"{deviations(cfg)} | | {paper} |")
                continue
            s = summarise(rs)[0]  # one identity by construction (default_rows)
            per_task = "/".join(f"{v:.0f}" for v in s["per_task"].values())
            runs = ", ".join(f"`{run}`" for run in sorted({r["run"] for r in rs}))
            tasks = len(s["per_task"])
            partial = f", {tasks} of {len(cfg.eval.tasks)} tasks so far" if tasks < len(cfg.eval.tasks) else ""
            out.append(
                f"| {method} | {maze} | {s['episodes']} ({tasks} x {s['seeds']}{partial}) | "
                f"{s['success']:.0f} ± {s['success_std']:.0f} | {per_task} | "
                f"{s['plan_time_s']:.1f} ± {s['plan_time_std']:.1f} | {search_statuses(rs)} | "
                f"`{str(s['checkpoint_digest'])[:8]}`, H={cfg.jump} | {training(cfg)} | {deviations(cfg)} | {runs} | "
                f"{paper} |")
    return "\n".join(out)
