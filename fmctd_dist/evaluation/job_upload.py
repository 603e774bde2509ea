"""What a ``ray job submit`` of the eval job uploads: the code, the configs and only the checkpoints it reads.

Ray refuses a working directory over 100 MiB, and the repository ships far more weights than one job
reads. The checkpoints a job reads are found by running the job's own up-front checks
(:func:`fmctd_dist.evaluation.grid.check_inputs`: the planner, the robot's policy, the visual parts, each
manifest and sha256) and recording, with an audit hook, which checkpoint folders they open. So the
upload follows the job's inputs for every env family without a list kept by hand, and a config whose
inputs are broken fails here, with the job's own error, before anything is uploaded.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from fmctd_dist.config import REPO_ROOT, Config
from fmctd_dist.family import HooksFor

CHECKPOINTS = REPO_ROOT / "checkpoints"
# never part of a job: git's objects, and the local outputs .gitignore also names (Ray reads .gitignore too)
ALWAYS_LEFT_OUT = ["/.git/", "/data/", "/results/", "/runs/", "/logs/"]

_opened: list[Path] | None = None  # set while checkpoints_read runs; audit hooks cannot be removed


def _record_open(event: str, args: tuple[Any, ...]) -> None:
    if event == "open" and _opened is not None and isinstance(args[0], (str, Path)):
        _opened.append(Path(args[0]))


_hooked = False


def checkpoints_read(cfg: Config, hooks_for: HooksFor) -> list[str]:
    """The checkpoint folders (``checkpoints/<name>``, sorted) that the eval job's checks open for ``cfg``
    (``hooks_for``: ``fmctd_dist.families.hooks_for``)."""
    global _opened, _hooked
    from fmctd_dist.evaluation.grid import check_inputs

    if not _hooked:
        sys.addaudithook(_record_open)
        _hooked = True
    _opened = []
    try:
        check_inputs(cfg, hooks_for)
        opened = list(_opened)
    finally:
        _opened = None
    names = set()
    for p in opened:
        try:
            rel = p.resolve().relative_to(CHECKPOINTS.resolve())
        except ValueError:
            continue  # outside checkpoints/ (a checkpoint elsewhere is read from its own path on every node)
        if rel.parts:
            names.add(rel.parts[0])
    return [f"checkpoints/{n}" for n in sorted(names)]


def runtime_env(cfg: Config, hooks_for: HooksFor) -> dict[str, Any]:
    """``--runtime-env-json`` for ``ray job submit --working-dir .``: every checkpoint folder left out but
    the ones ``cfg``'s job reads (gitignore-style patterns: the last match wins, ``!`` re-includes)."""
    keep = checkpoints_read(cfg, hooks_for)
    return {"excludes": [*ALWAYS_LEFT_OUT, "/checkpoints/*", *(f"!/{d}" for d in keep)]}


def upload_bytes(repo: Path, env: dict[str, Any]) -> int:
    """Bytes Ray would upload from ``repo`` with ``env`` (its own matcher; .gitignore files respected)."""
    from ray._private.runtime_env.packaging import _dir_travel, _get_excludes

    total = 0

    def add(p: Path) -> None:
        nonlocal total
        if p.is_file():
            total += p.stat().st_size

    _dir_travel(repo, [_get_excludes(repo, env["excludes"])], add, include_gitignore=True)
    return total
