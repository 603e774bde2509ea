"""Checkpoints: ``model.pt`` (state_dict only) + ``manifest.json`` (+ ``train_state.pt`` to resume).

A plan is a pure function of (config, checkpoint digest, seed), so a checkpoint must say
exactly what it is: the manifest records the config, dataset digest, git sha and the
sha256 of ``model.pt``, and loading checks all of it against the caller's config before
any model is built. Everything loads with ``torch.load(weights_only=True)`` (no pickled
code). Files are written to ``*.tmp`` and ``os.replace``d, so a kill never leaves half a file.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import pickle
import shlex
from functools import lru_cache
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch
from torch import nn

from fmctd_dist.config import REPO_ROOT, Config, ModelConfig, resolve_path
from fmctd_dist.tokens import Normaliser
from fmctd_dist.diffusion.model import DFTransformer
from fmctd_dist.diffusion.models import build_model, diffusion_config_from_dict, model_config_from_dict
from fmctd_dist.errors import CheckpointError
from fmctd_dist.hints import shown, train_command, training_words, word

MODEL_FILE = "model.pt"
MANIFEST_FILE = "manifest.json"
TRAIN_STATE_FILE = "train_state.pt"
FORMAT_VERSION = 1
MODEL_FIELDS = ("kind", "frame_stack", "width", "layers", "heads", "ff", "param", "norm")
UNET_FIELDS = ("unet_channels", "unet_kernel", "unet_padding", "unet_edge_frames")  # checked when kind=diffuser
# fields a state_dict does not depend on: train.init_from may change them
SHAPE_FREE_FIELDS = ("unet_padding", "unet_edge_frames")
# the noise schedule the weights were trained under: a sampler built on another one asks the model about noise
# levels it never saw, with no error of its own
DIFFUSION_FIELDS = ("timesteps", "beta_schedule", "beta_start", "beta_end")


def _model_fields(cfg: Config) -> tuple[str, ...]:
    return MODEL_FIELDS + (UNET_FIELDS if cfg.model.kind == "diffuser" else ())


def _saved_model(manifest: dict[str, Any]) -> dict[str, Any]:
    """A manifest's model config, with the defaults of fields added since it was written (unet_padding, ...)."""
    d = manifest.get("config", {}).get("model", {})
    return {**dataclasses.asdict(ModelConfig()), **d} if d else {}


def sha256_file(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def atomic_torch_save(obj: Any, path: Path) -> None:
    """Write then rename: a reader (or a killed writer) never sees half a file."""
    tmp = path.with_name(path.name + ".tmp")
    torch.save(obj, tmp)
    os.replace(tmp, path)


def write_manifest(manifest: dict[str, Any], path: Path) -> None:
    """Sorted, indented JSON (numpy values as plain numbers), written atomically."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(manifest, indent=2, sort_keys=True, default=_json_default) + "\n")
    os.replace(tmp, path)


def save_weights(out_dir: str | Path, net: nn.Module, fields: dict[str, Any]) -> dict[str, Any]:
    """Write ``net``'s model.pt (atomically), then its manifest: ``fields`` + param_count, model_sha256 and
    digest (its first 16 hex). The one writer behind every kind of checkpoint (planner, policy, expert,
    visual part), so they are all verified the same way."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    atomic_torch_save(module_state(net), out_dir / MODEL_FILE)
    sha = sha256_file(out_dir / MODEL_FILE)
    manifest = {**fields, "param_count": sum(p.numel() for p in net.parameters()), "model_sha256": sha,
                "digest": sha[:16]}
    write_manifest(manifest, out_dir / MANIFEST_FILE)
    return manifest


def save_checkpoint(ckpt_dir: str | Path, model: DFTransformer, manifest_fields: dict[str, Any]) -> dict[str, Any]:
    """Write model.pt then manifest.json; returns the manifest.

    ``manifest_fields`` must hold ``config`` (Config.to_dict()); by convention also
    dataset_digest, data_seed, git_sha, train_steps, wall_time_s, final_losses, normaliser
    ({mean, std}). This adds model_sha256, digest (its first 16 hex), param_count,
    n_tokens, token_dim, model_kind and format.
    """
    if "config" not in manifest_fields:
        raise ValueError("manifest_fields needs 'config' (Config.to_dict())")
    return save_weights(ckpt_dir, model, {**manifest_fields, "format": FORMAT_VERSION, "model_kind": model.kind,
                                          "n_tokens": model.n_tokens, "token_dim": model.token_dim})


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"{type(o).__name__} is not JSON serialisable")


def first_line(e: BaseException) -> str:
    """An exception as one short line (torch's unpickling errors run to a page of advice)."""
    text = str(e).strip().splitlines()
    return f"{type(e).__name__}: {text[0][:200] if text else ''}"


UNPICKLE_WHY = "not a plain tensor state_dict (torch.load(weights_only=True) refused it: pickled code or objects?)"


Fix = str | Callable[[], str]  # the fix an error names; a callable is built only when the error is raised


def fix_text(fix: Fix) -> str:
    return fix() if callable(fix) else fix


def torch_load_weights(path: Path, where: str, fix: Fix) -> Any:
    """``torch.load(path, weights_only=True)``; anything that does not load is one CheckpointError.

    weights_only=True unpickles tensors and plain containers only, so a file carrying code
    (a ``__reduce__`` payload) is refused before any of it runs.
    """
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as e:
        raise CheckpointError(f"{where}: {path.name} is {UNPICKLE_WHY} ({first_line(e)}); {fix_text(fix)}") from None
    except Exception as e:  # noqa: BLE001 - truncated zip, bad magic, ...: a bad file either way
        raise CheckpointError(f"{where}: {path.name} does not load ({first_line(e)}); {fix_text(fix)}") from None


def read_weights_manifest(ckpt_dir: Path, who: str, missing_fix: str, broken_fix: str) -> dict[str, Any]:
    """The manifest of a dir written by :func:`save_weights` (policies, the ant expert, visual parts).

    The three ways such a dir can be unusable before its kind is even read are worded once:
    ``who: <path> does not exist; missing_fix``, ``who: manifest.json is unreadable (...); broken_fix``
    and ``who: manifest.json is not a JSON object; broken_fix``. Callers check their own fields after.
    """
    for path in (ckpt_dir, ckpt_dir / MODEL_FILE, ckpt_dir / MANIFEST_FILE):
        if not path.exists():
            raise CheckpointError(f"{who}: {path} does not exist; {missing_fix}")
    path = ckpt_dir / MANIFEST_FILE
    try:
        manifest = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise CheckpointError(f"{who}: {path} is unreadable ({first_line(e)}); {broken_fix}") from None
    if not isinstance(manifest, dict):
        raise CheckpointError(f"{who}: {path} is not a JSON object; {broken_fix}")
    return manifest


def _fresh_dir(cfg: Config) -> Path:
    """A new checkpoint dir for cfg's model when the expected one holds another model (never overwritten)."""
    tag = hashlib.sha256(" ".join(training_words(cfg)).encode()).hexdigest()[:8]
    return REPO_ROOT / "runs" / f"{cfg.run_name}-{tag}"


def _tracked(path: Path) -> bool:
    """True when ``path`` is a checkpoint shipped in git (then `git checkout` restores it)."""
    import subprocess

    try:
        out = subprocess.run(["git", "ls-files", "--error-unmatch", str(path / MODEL_FILE), str(path / MANIFEST_FILE)],
                             cwd=REPO_ROOT, capture_output=True, text=True, timeout=10)
        return out.returncode == 0
    except (OSError, subprocess.SubprocessError):
        return False


def _train_fix(cfg: Config | None, where: str | Path | None = None, broken: bool = False) -> str:
    """The command that makes what loading cfg's model from ``where`` (default cfg.checkpoint_dir()) needs.

    ``broken``: ``where`` exists but holds a corrupt, partial or unreadable checkpoint. jobs/train.py
    continues what its train.out dir holds, so the broken one is restored from git (a shipped
    checkpoint) or moved aside first.
    """
    if cfg is None:
        return "train one with `python jobs/train.py env=<env> jump=<H> train.out=<dir>`"
    out = Path(where) if where is not None else cfg.checkpoint_dir()
    train = train_command(cfg, out)
    if not broken:
        return f"train one with `{train}`"
    aside = f"mv {shlex.quote(shown(out))} {shlex.quote(shown(out) + '.broken')} && {train}"
    if _tracked(out):
        return f"restore the shipped one with `git checkout -- {shown(out)}`, or train one with `{aside}`"
    return f"train one with `{aside}`"


def read_manifest(ckpt_dir: str | Path, cfg: Config | None = None) -> dict[str, Any]:
    """The manifest of a checkpoint dir; CheckpointError if the dir or its files are missing."""
    ckpt_dir = Path(ckpt_dir)
    if not ckpt_dir.exists():
        raise CheckpointError(f"checkpoint: {ckpt_dir} does not exist; {_train_fix(cfg, ckpt_dir)} "
                              "or set checkpoint=<dir>")
    for path in (ckpt_dir / MODEL_FILE, ckpt_dir / MANIFEST_FILE):
        if not path.exists():
            raise CheckpointError(f"checkpoint: {path} does not exist (an incomplete checkpoint dir); "
                                  f"{_train_fix(cfg, ckpt_dir, broken=True)} or set checkpoint=<dir>")
    path = ckpt_dir / MANIFEST_FILE
    try:
        manifest = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise CheckpointError(f"checkpoint: {path} is unreadable ({first_line(e)}); "
                              f"{_train_fix(cfg, ckpt_dir, broken=True)}") from None
    bad = manifest_type_error(manifest)
    if bad:
        raise CheckpointError(f"checkpoint: {path} is malformed: {bad}; it was not written by jobs/train.py "
                              f"(or was edited since); {_train_fix(cfg, ckpt_dir, broken=True)}")
    return manifest


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _numbers(v: Any) -> bool:
    return isinstance(v, list) and len(v) > 0 and all(_is_num(x) for x in v)


# What every load path reads from a manifest, and the JSON type it must have there.
MANIFEST_TYPES: dict[str, tuple[Callable[[Any], bool], str]] = {
    "config": (lambda v: isinstance(v, dict), "an object (Config.to_dict())"),
    "config.env": (lambda v: isinstance(v, dict), "an object"),
    "config.env.name": (lambda v: isinstance(v, str), "a string"),
    "config.model": (lambda v: isinstance(v, dict), "an object"),
    "config.jump": (lambda v: _is_int(v) and v > 0, "a positive integer"),
    "n_tokens": (lambda v: _is_int(v) and v > 0, "a positive integer"),
    "token_dim": (lambda v: _is_int(v) and v > 0, "a positive integer"),
    "model_sha256": (lambda v: isinstance(v, str) and len(v) == 64, "a 64-character sha256 hex string"),
    "digest": (lambda v: isinstance(v, str) and len(v) == 16, "a 16-character hex string"),
    "normaliser": (lambda v: isinstance(v, dict), "an object {mean, std}"),
    "normaliser.mean": (_numbers, "a list of numbers"),
    "normaliser.std": (_numbers, "a list of numbers"),
}
OPTIONAL_TYPES: dict[str, tuple[Callable[[Any], bool], str]] = {
    "train_steps": (lambda v: _is_int(v) and v >= 0, "a non-negative integer"),
    "wall_time_s": (_is_num, "a number"),
    "dataset_digest": (lambda v: isinstance(v, str), "a string"),
}


def manifest_type_error(manifest: Any) -> str:
    """'' if every field the loaders read has its JSON type, else what is wrong with the first bad one."""
    if not isinstance(manifest, dict):
        return f"the top level is a JSON {type(manifest).__name__}, not an object"
    missing = object()

    def get(dotted: str) -> Any:
        node: Any = manifest
        for part in dotted.split("."):
            node = node.get(part, missing) if isinstance(node, dict) else missing
        return node

    for table, required in ((MANIFEST_TYPES, True), (OPTIONAL_TYPES, False)):
        for key, (ok, want) in table.items():
            v = get(key)
            if v is missing:
                if required:
                    return f"the field {key!r} is missing"
                continue
            if not ok(v):
                return f"{key} is {json.dumps(v)[:60]} ({type(v).__name__}) but must be {want}"
    saved = manifest["config"]["model"]
    for f in dataclasses.fields(ModelConfig):
        if f.name not in saved:
            continue  # older manifests lack newer fields (their defaults apply)
        v, default = saved[f.name], getattr(ModelConfig(), f.name)
        if isinstance(default, list):
            good = isinstance(v, list) and all(_is_int(x) for x in v)
        elif _is_int(default):
            good = _is_int(v)
        else:
            good = isinstance(v, type(default))
        if not good:
            return (f"config.model.{f.name} is {json.dumps(v)[:60]} ({type(v).__name__}) but must be "
                    f"{type(default).__name__} like the default {default!r}")
    return ""


def _mismatch(manifest: dict[str, Any], cfg: Config) -> tuple[str, Any, Any] | None:
    """The first (field, checkpoint's value, config's value) where they disagree, or None."""
    saved = manifest.get("config", {})
    saved_model = _saved_model(manifest)
    pairs = [("env.name", saved.get("env", {}).get("name"), cfg.env.name), ("jump", saved.get("jump"), cfg.jump)]
    pairs += [(f"model.{f}", saved_model.get(f), getattr(cfg.model, f)) for f in _model_fields(cfg)]
    pairs += [("n_tokens", manifest.get("n_tokens"), cfg.n_tokens)]
    schedule = saved.get("diffusion") or {}  # absent from manifests of models that do not denoise
    pairs += [(f"diffusion.{f}", schedule[f], getattr(cfg.diffusion, f)) for f in DIFFUSION_FIELDS if f in schedule]
    return next(((name, have, want) for name, have, want in pairs if have != want), None)


def _use_it(name: str, have: Any, cfg: Config) -> str:
    """The words that make the config agree with the checkpoint on ``name``."""
    if name == "n_tokens" and isinstance(have, int):
        h = (have - 1) * cfg.jump * cfg.model.frame_stack
        return f"set env.horizon={h} data.train_window={h}"
    if name == "env.name":
        return f"set env={have}"
    if name == "model.kind":
        return "use it with method=diffuser" if have == "diffuser" else "use it with a Diffusion Forcing method"
    return f"set {word(name, have)}"


def _model_elsewhere(cfg: Config, where: Path) -> str:
    """How to get a model for cfg without overwriting the (intact, other) checkpoint at ``where``."""
    default = resolve_path(f"checkpoints/{cfg.run_name}")
    candidates = [(default, "drop checkpoint=")] if where.resolve() != default.resolve() else []
    fresh = _fresh_dir(cfg)
    candidates.append((fresh, f"set checkpoint={shlex.quote(shown(fresh))}"))
    for path, use in candidates:
        if not path.exists():
            return f"train one with `{train_command(cfg, path)}` and {use}"
        try:
            if _mismatch(read_manifest(path), cfg) is None:
                return f"{shown(path)} holds one: {use}"
        except CheckpointError:
            pass
    return f"train one with `{train_command(cfg, fresh)}` and {candidates[-1][1]}"


def check_compatible(manifest: dict[str, Any], cfg: Config, where: str | Path) -> None:
    """Raise one CheckpointError naming the first field where checkpoint and config disagree.

    The fix offers both ways out: the words that make the config fit this checkpoint, and a
    model of the config's own shape (the expected dir if it holds one, else the command that
    trains one into a dir that does not overwrite this checkpoint).
    """
    bad = _mismatch(manifest, cfg)
    if bad is None:
        return
    name, have, want = bad
    hint = " (n_tokens = env.horizon / jump / model.frame_stack + 1)" if name == "n_tokens" else ""
    raise CheckpointError(
        f"checkpoint {where} was trained with {name}={have!r} but the config has {name}={want!r}{hint}; "
        f"to plan with this checkpoint {_use_it(name, have, cfg)}; for a model with {name}={want!r}, "
        f"{_model_elsewhere(cfg, Path(where))}"
    )


def verify_checkpoint(ckpt_dir: str | Path, cfg: Config, manifest: dict[str, Any] | None = None) -> dict[str, Any]:
    """Everything a load of cfg's model from ckpt_dir checks short of unpickling it -> the manifest.

    Present and complete, manifest well-typed, trained for cfg (env, jump, model, n_tokens),
    model.pt's sha256 the manifest's. Jobs call this before any actor starts. ``manifest``: the
    one :func:`read_manifest` gave for this dir, when the caller has read it already.
    """
    ckpt_dir = Path(ckpt_dir)
    manifest = read_manifest(ckpt_dir, cfg) if manifest is None else manifest
    check_compatible(manifest, cfg, ckpt_dir)
    _verified_sha(ckpt_dir, manifest, f"checkpoint {ckpt_dir}", lambda: _train_fix(cfg, ckpt_dir, broken=True))
    return manifest


def _verified_sha(ckpt_dir: Path, manifest: dict[str, Any], where: str, fix: Fix) -> str:
    """sha256 of ``model.pt``, or one CheckpointError if the manifest records another."""
    sha = sha256_file(ckpt_dir / MODEL_FILE)
    if sha != manifest.get("model_sha256"):
        raise CheckpointError(
            f"{where}: {MODEL_FILE} has sha256 {sha[:16]}... but manifest.json records "
            f"{str(manifest.get('model_sha256'))[:16]}... (corrupt or overwritten); {fix_text(fix)}"
        )
    return sha


def load_checkpoint(ckpt_dir: str | Path, cfg: Config | None = None,
                    expect_digest: str | None = None) -> tuple[DFTransformer, dict[str, Any]]:
    """Verify and load a checkpoint -> (model on CPU in eval mode, manifest).

    Checks: files exist, sha256 of model.pt matches the manifest, ``expect_digest`` (16-hex
    digest or full sha256) matches, and when ``cfg`` is given env.name, jump, model.* and
    n_tokens agree with it.
    """
    ckpt_dir = Path(ckpt_dir)
    manifest = read_manifest(ckpt_dir, cfg)
    if cfg is not None:  # before the sha: a checkpoint of another shape is named as such, corrupt or not
        check_compatible(manifest, cfg, ckpt_dir)
    sha = _verified_sha(ckpt_dir, manifest, f"checkpoint {ckpt_dir}", lambda: _train_fix(cfg, ckpt_dir, broken=True))
    if expect_digest is not None and expect_digest not in (manifest["digest"], sha):
        raise CheckpointError(
            f"checkpoint {ckpt_dir}: digest {manifest['digest']} differs from the expected {expect_digest}; "
            "the checkpoint changed since the run started; point checkpoint= at the original one"
        )
    model = model_from_manifest(manifest)
    state = torch_load_weights(ckpt_dir / MODEL_FILE, f"checkpoint {ckpt_dir}",
                               lambda: _train_fix(cfg, ckpt_dir, broken=True))
    try:
        model.load_state_dict(state, strict=True)
    except Exception as e:  # noqa: BLE001 - a state_dict of another shape (or not a state_dict) is a bad checkpoint
        raise CheckpointError(f"checkpoint {ckpt_dir}: {MODEL_FILE} does not fit the model its manifest describes "
                              f"({first_line(e)}); {_train_fix(cfg, ckpt_dir, broken=True)}") from None
    return model.eval(), manifest


def lineage(manifest: dict[str, Any], _seen: frozenset[Path] = frozenset()) -> dict[str, Any]:
    """Training behind a model's weights, through every ``train.init_from`` ancestor.

    Why: a continued model's ``train_steps`` and ``cpu_time_s`` count only its own run, so a
    quality-against-hours curve would start each continuation at zero. ``lineage_cpu_s`` is None
    where an ancestor predates this field and its CPU time is unknown (its steps are known: the
    provenance always kept them). An ancestor still on disk (under its recorded path, or any
    checkpoint or run dir holding its digest) is read again, so a record written before this field
    (or from such a record) cannot undercount. ``lineage_samples`` (steps x batch, summed over the
    ancestors) is what a curve should be read against when batch sizes differ along the way (a CPU run
    at 128 continued on a GPU at 1024); None where a record lacks its batch size.
    """
    parent = manifest.get("init_from") or {}
    on_disk = _ancestor_manifest(parent)
    if on_disk is not None and on_disk not in _seen:  # the same weights: their own record is the truth
        parent = {**parent, **lineage(json.loads(on_disk.read_text()), _seen | {on_disk})}
    cpu = manifest.get("cpu_time_s", manifest.get("wall_time_s"))
    steps = int(manifest.get("train_steps") or 0)
    batch = manifest.get("config", {}).get("train", {}).get("batch_size")
    parent_steps = parent.get("lineage_steps", parent.get("train_steps")) or 0
    parent_cpu = parent.get("lineage_cpu_s") if parent else 0.0
    parent_samples = parent.get("lineage_samples") if parent else 0
    return {"lineage_steps": steps + int(parent_steps),
            "lineage_cpu_s": None if cpu is None or parent_cpu is None else float(cpu) + float(parent_cpu),
            "lineage_samples": None if batch is None or parent_samples is None
                               else steps * int(batch) + int(parent_samples)}


def _ancestor_manifest(parent: dict[str, Any]) -> Path | None:
    """The manifest on disk of an ``init_from`` record's weights: at its recorded path if that still
    holds its digest, else any ``checkpoints/*`` or ``runs/**`` manifest with that digest (a path
    whose weights were replaced since, e.g. a shipped checkpoint swapped for its continuation).
    The tree is scanned only when the recorded path misses."""
    digest = parent.get("digest")
    if not digest:
        return None

    def holds(path: Path) -> bool:
        return path.is_file() and json.loads(path.read_text()).get("digest") == digest

    if parent.get("path") and holds(recorded := resolve_path(parent["path"]) / MANIFEST_FILE):
        return recorded
    return next((path for path in _manifests_by_digest().get(digest, ()) if holds(path)), None)


@lru_cache(maxsize=1)
def _manifests_by_digest() -> dict[str, list[Path]]:
    """digest -> manifest paths under checkpoints/ and runs/ (read once per process)."""
    index: dict[str, list[Path]] = {}
    for root, pattern in ((REPO_ROOT / "checkpoints", f"*/{MANIFEST_FILE}"),
                          (REPO_ROOT / "runs", f"**/{MANIFEST_FILE}")):
        for path in sorted(root.glob(pattern)) if root.is_dir() else []:
            try:
                digest = json.loads(path.read_text()).get("digest")
            except (OSError, ValueError):
                continue
            if digest:
                index.setdefault(digest, []).append(path)
    return index


def load_init_weights(ckpt_dir: str | Path, cfg: Config) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
    """Weights to start a run from (``train.init_from``) -> (state_dict, provenance for the manifest).

    Unlike :func:`load_checkpoint` the env, jump and horizon may differ (positions are
    sinusoidal, so a transformer runs at any token count); the architecture must not.
    """
    ckpt_dir = Path(ckpt_dir)
    manifest = read_manifest(ckpt_dir)
    _verified_sha(ckpt_dir, manifest, f"train.init_from={ckpt_dir}", "point train.init_from at an intact checkpoint")
    saved = _saved_model(manifest)
    for f in _model_fields(cfg):
        if f not in SHAPE_FREE_FIELDS and saved.get(f) != getattr(cfg.model, f):
            raise CheckpointError(f"train.init_from={ckpt_dir} has model.{f}={saved.get(f)!r} but the config has "
                                  f"model.{f}={getattr(cfg.model, f)!r}; set model.{f}={saved.get(f)!r} or start "
                                  "from scratch (train.init_from=)")
    state = torch_load_weights(ckpt_dir / MODEL_FILE, f"train.init_from={ckpt_dir}",
                               "point train.init_from at an intact checkpoint")
    widened = {}
    saved_td, fs = int(manifest.get("token_dim", cfg.token_dim)), cfg.model.frame_stack
    if saved_td != cfg.token_dim:
        old = saved_td // fs
        if cfg.model.kind != "df" or saved_td % fs or old >= cfg.frame_dim:
            raise CheckpointError(f"train.init_from={ckpt_dir} models {saved_td} numbers per token but this config "
                                  f"has {cfg.token_dim} ({cfg.frame_dim} per frame x model.frame_stack={fs}); a DF "
                                  "model can only be widened to frames that add numbers after its own (e.g. "
                                  "visual.plan_xy=true from a latent model): start from such a checkpoint, or from "
                                  "scratch (train.init_from=)")
        state = widen_frames(state, old, cfg.frame_dim, fs)
        widened = {"widened_frames": {"from": old, "to": cfg.frame_dim}}
    provenance = {"path": str(ckpt_dir.relative_to(REPO_ROOT) if ckpt_dir.is_relative_to(REPO_ROOT) else ckpt_dir),
                  "digest": manifest["digest"], "env": manifest.get("config", {}).get("env", {}).get("name"),
                  "jump": manifest.get("config", {}).get("jump"), "train_steps": manifest.get("train_steps"),
                  **lineage(manifest), **widened}
    return state, provenance


def widen_frames(state: dict[str, torch.Tensor], old: int, new: int, frame_stack: int) -> dict[str, torch.Tensor]:
    """A DF model's weights on frames of ``old`` numbers, for frames of ``new`` > ``old`` whose first ``old``
    numbers are the old ones (e.g. a visual latent model -> [z, x, y] frames).

    Why: a widened model starts as the trained one instead of from scratch. The added numbers enter
    with zero input weights and leave with zero output weights (x0_hat = 0, their normalised mean),
    so at step 0 the old numbers' predictions are exactly the old model's; training then learns the rest.
    """
    cols = torch.as_tensor([f * new + j for f in range(frame_stack) for j in range(old)])  # old token -> new token
    out = dict(state)
    w_in = state["init_mlp.0.weight"]  # [width, token_dim + t_embed]: the token's numbers first
    extra = w_in.shape[1] - old * frame_stack
    wide = torch.zeros(w_in.shape[0], new * frame_stack + extra, dtype=w_in.dtype)
    wide[:, cols] = w_in[:, :old * frame_stack]
    wide[:, new * frame_stack:] = w_in[:, old * frame_stack:]
    out["init_mlp.0.weight"] = wide
    for key in ("out.weight", "out.bias"):
        w = state[key]
        o = torch.zeros((new * frame_stack, *w.shape[1:]), dtype=w.dtype)
        o[cols] = w
        out[key] = o
    return out


def model_from_manifest(manifest: dict[str, Any]) -> DFTransformer:
    """An untrained model of the architecture a manifest describes (any model.kind)."""
    saved = manifest["config"]
    return build_model(model_config_from_dict(saved["model"]), manifest["n_tokens"], manifest["token_dim"],
                       diffusion_config_from_dict(saved.get("diffusion", {})))


def normaliser_from_manifest(manifest: dict[str, Any]) -> Normaliser:
    """The normaliser the model was trained with (the planner must use the same one)."""
    n = manifest["normaliser"]
    return Normaliser.from_lists(n["mean"], n["std"])


def save_train_state(ckpt_dir: str | Path, state: dict[str, Any]) -> None:
    """Write train_state.pt (model + optimiser state, step, RNG states as tensors/plain types)."""
    ckpt_dir = Path(ckpt_dir)
    ckpt_dir.mkdir(parents=True, exist_ok=True)
    atomic_torch_save(state, ckpt_dir / TRAIN_STATE_FILE)


def load_train_state(ckpt_dir: str | Path) -> dict[str, Any] | None:
    """The resumable state in ckpt_dir, or None if there is none."""
    path = Path(ckpt_dir) / TRAIN_STATE_FILE
    if not path.exists():
        return None
    state = torch_load_weights(path, f"checkpoint {path.parent}", f"delete {path} to restart training from scratch")
    if not isinstance(state, dict):
        raise CheckpointError(f"checkpoint {path.parent}: {path.name} is not a training state (a "
                              f"{type(state).__name__}, not a dict); delete {path} to restart training from scratch")
    return state


def module_state(model: nn.Module) -> dict[str, torch.Tensor]:
    """state_dict copied to CPU (what every file here stores)."""
    return {k: v.detach().to("cpu").clone() for k, v in model.state_dict().items()}
