"""Artifact I/O for every trained part (planners, low-level policies, the ant expert, the visual VAE and heads).

A part is a dir with ``model.pt`` (a tensor state_dict, loaded with ``torch.load(weights_only=True)``: no
pickled code) and ``manifest.json`` (what it is, what made it, the sha256 of ``model.pt`` and its first 16
hex, the digest results are keyed by). Files are written to ``*.tmp`` and ``os.replace``d, so a kill never
leaves half a file. Every way a dir can be unusable (missing, unreadable, mistyped, weights that are not the
manifest's) is one CheckpointError: who, the path or field, what is wrong, and the fix the caller names.
torch is imported where weights are read or written, so the data stores' sha256 costs no torch import.
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from fmctd_dist.errors import CheckpointError

if TYPE_CHECKING:
    import torch
    from torch import nn

MODEL_FILE = "model.pt"
MANIFEST_FILE = "manifest.json"
UNPICKLE_WHY = "not a plain tensor state_dict (torch.load(weights_only=True) refused it: pickled code or objects?)"

Fix = str | Callable[[], str]  # the fix an error names; a callable is built only when the error is raised
Types = dict[str, tuple[Callable[[Any], bool], str]]  # dotted field -> (check, what it must be)


def fix_text(fix: Fix) -> str:
    return fix() if callable(fix) else fix


def sha256_file(path: str | Path) -> str:
    """Hex sha256 of a file, read in 1 MiB blocks (datasets are hundreds of MB)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def first_line(e: BaseException) -> str:
    """An exception as one short line (torch's unpickling errors run to a page of advice)."""
    text = str(e).strip().splitlines()
    return f"{type(e).__name__}: {text[0][:200] if text else ''}"


def atomic_torch_save(obj: Any, path: Path) -> None:
    """Write then rename: a reader (or a killed writer) never sees half a file."""
    import torch

    tmp = path.with_name(path.name + ".tmp")
    torch.save(obj, tmp)
    os.replace(tmp, path)


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"{type(o).__name__} is not JSON serialisable")


def write_manifest(manifest: dict[str, Any], path: Path) -> None:
    """Sorted, indented JSON (numpy values as plain numbers), written atomically."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(manifest, indent=2, sort_keys=True, default=_json_default) + "\n")
    os.replace(tmp, path)


def module_state(model: nn.Module) -> dict[str, torch.Tensor]:
    """state_dict copied to CPU (what every model.pt stores)."""
    return {k: v.detach().to("cpu").clone() for k, v in model.state_dict().items()}


def save_weights(out_dir: str | Path, net: nn.Module, fields: dict[str, Any]) -> dict[str, Any]:
    """Write ``net``'s model.pt (atomically), then its manifest: ``fields`` + param_count, model_sha256 and
    digest (its first 16 hex). The one writer behind every kind of part, so they are all verified alike."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    atomic_torch_save(module_state(net), out_dir / MODEL_FILE)
    sha = sha256_file(out_dir / MODEL_FILE)
    manifest = {**fields, "param_count": sum(p.numel() for p in net.parameters()), "model_sha256": sha,
                "digest": sha[:16]}
    write_manifest(manifest, out_dir / MANIFEST_FILE)
    return manifest


def type_error(manifest: Any, required: Types, optional: Types | None = None) -> str:
    """'' if ``manifest`` is an object whose dotted fields have their types, else what is wrong with the first."""
    if not isinstance(manifest, dict):
        return f"the top level is a JSON {type(manifest).__name__}, not an object"
    missing = object()

    def get(dotted: str) -> Any:
        node: Any = manifest
        for part in dotted.split("."):
            node = node.get(part, missing) if isinstance(node, dict) else missing
        return node

    for table, needed in ((required, True), (optional or {}, False)):
        for key, (ok, want) in table.items():
            v = get(key)
            if v is missing:
                if needed:
                    return f"the field {key!r} is missing"
                continue
            if not ok(v):
                return f"{key} is {json.dumps(v)[:60]} ({type(v).__name__}) but must be {want}"
    return ""


def read_weights_manifest(ckpt_dir: str | Path, who: str, missing_fix: Fix, broken_fix: Fix,
                          check: Callable[[Any], str] | None = None) -> dict[str, Any]:
    """The manifest of a dir written by :func:`save_weights`. ``missing_fix`` ends the error for a dir that does
    not exist, ``broken_fix`` the one for a file missing, an unreadable manifest or one ``check`` finds malformed
    (its words name the field; default: anything but a JSON object)."""
    ckpt_dir = Path(ckpt_dir)
    if not ckpt_dir.exists():
        raise CheckpointError(f"{who}: {ckpt_dir} does not exist; {fix_text(missing_fix)}")
    for path in (ckpt_dir / MODEL_FILE, ckpt_dir / MANIFEST_FILE):
        if not path.exists():
            raise CheckpointError(f"{who}: {path} does not exist (an incomplete checkpoint dir); "
                                  f"{fix_text(broken_fix)}")
    try:
        manifest = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise CheckpointError(f"{who}: {path} is unreadable ({first_line(e)}); {fix_text(broken_fix)}") from None
    bad = check(manifest) if check is not None else type_error(manifest, {})
    if bad:
        raise CheckpointError(f"{who}: {path} is malformed: {bad}; {fix_text(broken_fix)}")
    return manifest


def verify_weights(ckpt_dir: str | Path, manifest: dict[str, Any], where: str, fix: Fix) -> str:
    """sha256 of ``model.pt``, or one CheckpointError if the manifest records another."""
    sha = sha256_file(Path(ckpt_dir) / MODEL_FILE)
    if sha != manifest.get("model_sha256"):
        raise CheckpointError(
            f"{where}: {MODEL_FILE} has sha256 {sha[:16]}... but manifest.json records "
            f"{str(manifest.get('model_sha256'))[:16]}... (corrupt or overwritten); {fix_text(fix)}"
        )
    return sha


def torch_load_weights(path: Path, where: str, fix: Fix) -> Any:
    """``torch.load(path, weights_only=True)`` (a file carrying code is refused before any of it runs); anything
    that does not load is one CheckpointError."""
    import torch

    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as e:
        raise CheckpointError(f"{where}: {path.name} is {UNPICKLE_WHY} ({first_line(e)}); {fix_text(fix)}") from None
    except Exception as e:  # noqa: BLE001 - truncated zip, bad magic, ...: a bad file either way
        raise CheckpointError(f"{where}: {path.name} does not load ({first_line(e)}); {fix_text(fix)}") from None


def load_weights(ckpt_dir: str | Path, net: nn.Module | Callable[[], nn.Module], where: str, fix: Fix) -> nn.Module:
    """model.pt loaded (strict) into ``net`` (or what ``net()`` builds from the manifest) -> it, in eval mode;
    weights that do not load or fit are one CheckpointError."""
    from torch import nn

    state = torch_load_weights(Path(ckpt_dir) / MODEL_FILE, where, fix)
    try:
        net = net if isinstance(net, nn.Module) else net()
        net.load_state_dict(state, strict=True)
    except Exception as e:  # noqa: BLE001 - missing keys, shapes, a config of another version: a bad checkpoint
        raise CheckpointError(f"{where}: {MODEL_FILE} does not fit the network its manifest describes "
                              f"({first_line(e)}); {fix_text(fix)}") from None
    return net.eval()
