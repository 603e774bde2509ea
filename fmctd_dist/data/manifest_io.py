"""Reading a data directory's manifest.json: one DatasetError for a missing, non-JSON or non-object file.

Navigate, cube and visual-frame stores each check their own fields after this; the three
ways a manifest can be unreadable are worded once, each with the fix the caller gives.
The sha256 every manifest records for its files is :func:`fmctd_dist.artifacts.sha256_file`.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from fmctd_dist.errors import DatasetError


def read_manifest_json(path: Path, missing_fix: str, broken_fix: str, what: str = "dataset") -> dict[str, Any]:
    """``path/manifest.json`` as a dict. ``missing_fix`` / ``broken_fix`` end the error when it is
    absent / unreadable; ``what`` names the store ("dataset", "frames")."""
    mf = path / "manifest.json"
    if not mf.is_file():
        raise DatasetError(f"no {what} at {path} (manifest.json missing); {missing_fix}")
    try:
        manifest = json.loads(mf.read_text())
    except json.JSONDecodeError as e:
        raise DatasetError(f"{mf} is not valid JSON ({e}); {broken_fix}") from None
    if not isinstance(manifest, dict):
        raise DatasetError(f"{mf} holds a JSON {type(manifest).__name__}, not an object; {broken_fix}")
    return manifest


def split_lines(manifest: dict[str, Any]) -> list[str]:
    """One line per split of a dataset manifest (episodes x steps, sha256): how every data ``describe`` begins."""
    return [f"  {split}: {manifest['episodes'][split]} episodes x {manifest['episode_steps']} steps  sha256={digest}"
            for split, digest in manifest["sha256"].items()]
