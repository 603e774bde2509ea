"""Planner checkpoints: what a planner's manifest holds, its agreement with a config, fine-tuning lineage.

A plan is a pure function of (config, checkpoint digest, seed), so a checkpoint must say
exactly what it is: the manifest records the config, dataset digest, git sha and the
sha256 of ``model.pt``, and loading checks all of it against the caller's config before
any model is built. The files themselves are written, read and verified by
:mod:`fmctd_dist.artifacts`, as every trained part's are.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import shlex
from functools import lru_cache
from pathlib import Path
from typing import Any

from fmctd_dist.artifacts import (
    MANIFEST_FILE, MODEL_FILE, Types, load_weights, read_weights_manifest, save_weights, type_error, verify_weights,
)
from fmctd_dist.config import REPO_ROOT, Config, ModelConfig, resolve_path
from fmctd_dist.config.repo import git
from fmctd_dist.tokens import Normaliser
from fmctd_dist.diffusion.model import DFTransformer
from fmctd_dist.diffusion.models import build_model, diffusion_config_from_dict, model_config_from_dict
from fmctd_dist.errors import CheckpointError
from fmctd_dist.hints import shown, train_command, training_words, word

FORMAT_VERSION = 1
MODEL_FIELDS = ("kind", "frame_stack", "width", "layers", "heads", "ff", "param", "norm")
UNET_FIELDS = ("unet_channels", "unet_kernel", "unet_padding", "unet_edge_frames")  # checked when kind=diffuser
# fields a state_dict does not depend on: train.init_from may change them
SHAPE_FREE_FIELDS = ("unet_padding", "unet_edge_frames")
# the noise schedule the weights were trained under: a sampler built on another one asks the model about noise
# levels it never saw, with no error of its own
DIFFUSION_FIELDS = ("timesteps", "beta_schedule", "beta_start", "beta_end")


def model_fields(cfg: Config) -> tuple[str, ...]:
    return MODEL_FIELDS + (UNET_FIELDS if cfg.model.kind == "diffuser" else ())


def saved_model(manifest: dict[str, Any]) -> dict[str, Any]:
    """A manifest's model config, with the defaults of fields added since it was written (unet_padding, ...)."""
    d = manifest.get("config", {}).get("model", {})
    return {**dataclasses.asdict(ModelConfig()), **d} if d else {}


def save_checkpoint(ckpt_dir: str | Path, model: DFTransformer, manifest_fields: dict[str, Any]) -> dict[str, Any]:
    """Write model.pt then manifest.json (``manifest_fields`` + format, model_kind, n_tokens, token_dim and
    what :func:`~fmctd_dist.artifacts.save_weights` adds); returns the manifest."""
    if "config" not in manifest_fields:
        raise ValueError("manifest_fields needs 'config' (Config.to_dict())")
    return save_weights(ckpt_dir, model, {**manifest_fields, "format": FORMAT_VERSION, "model_kind": model.kind,
                                          "n_tokens": model.n_tokens, "token_dim": model.token_dim})


def _fresh_dir(cfg: Config) -> Path:
    """A new checkpoint dir for cfg's model when the expected one holds another model (never overwritten)."""
    tag = hashlib.sha256(" ".join(training_words(cfg)).encode()).hexdigest()[:8]
    return REPO_ROOT / "runs" / f"{cfg.run_name}-{tag}"


def _tracked(path: Path) -> bool:
    """True when ``path`` is a checkpoint shipped in git (then `git checkout` restores it)."""
    return git("ls-files", "--error-unmatch", str(path / MODEL_FILE), str(path / MANIFEST_FILE)) is not None


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
    """The well-typed manifest of a checkpoint dir; CheckpointError if the dir or its files are missing."""
    ckpt_dir = Path(ckpt_dir)
    return read_weights_manifest(ckpt_dir, "checkpoint", lambda: f"{_train_fix(cfg, ckpt_dir)} or set checkpoint=<dir>",
                                 lambda: f"{_train_fix(cfg, ckpt_dir, broken=True)} or set checkpoint=<dir>",
                                 manifest_type_error)


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _numbers(v: Any) -> bool:
    return isinstance(v, list) and len(v) > 0 and all(_is_num(x) for x in v)


# What every load path reads from a manifest, and the JSON type it must have there.
MANIFEST_TYPES: Types = {
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
OPTIONAL_TYPES: Types = {
    "train_steps": (lambda v: _is_int(v) and v >= 0, "a non-negative integer"),
    "wall_time_s": (_is_num, "a number"),
    "dataset_digest": (lambda v: isinstance(v, str), "a string"),
}


def manifest_type_error(manifest: Any) -> str:
    """'' if every field the loaders read has its JSON type, else what is wrong with the first bad one."""
    bad = type_error(manifest, MANIFEST_TYPES, OPTIONAL_TYPES)
    if bad:
        return bad
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
    model = saved_model(manifest)
    pairs = [("env.name", saved.get("env", {}).get("name"), cfg.env.name), ("jump", saved.get("jump"), cfg.jump)]
    pairs += [(f"model.{f}", model.get(f), getattr(cfg.model, f)) for f in model_fields(cfg)]
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
    """Raise one CheckpointError naming the first field where checkpoint and config disagree, with both ways
    out: the words that fit the config to this checkpoint, and a model of the config's shape elsewhere."""
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
    """Everything a load of cfg's model from ckpt_dir checks short of unpickling it -> the manifest (jobs call
    it before any actor starts); ``manifest``: the one :func:`read_manifest` gave, when the caller has it."""
    ckpt_dir = Path(ckpt_dir)
    manifest = read_manifest(ckpt_dir, cfg) if manifest is None else manifest
    check_compatible(manifest, cfg, ckpt_dir)
    verify_weights(ckpt_dir, manifest, f"checkpoint {ckpt_dir}", lambda: _train_fix(cfg, ckpt_dir, broken=True))
    return manifest


def load_checkpoint(ckpt_dir: str | Path, cfg: Config | None = None,
                    expect_digest: str | None = None) -> tuple[DFTransformer, dict[str, Any]]:
    """Verify (as :func:`verify_checkpoint`, ``cfg`` optional) and load a checkpoint -> (model on CPU in eval
    mode, manifest); ``expect_digest``: its 16-hex digest or full sha256, when known."""
    ckpt_dir = Path(ckpt_dir)
    manifest = read_manifest(ckpt_dir, cfg)
    if cfg is not None:  # before the sha: a checkpoint of another shape is named as such, corrupt or not
        check_compatible(manifest, cfg, ckpt_dir)
    where, fix = f"checkpoint {ckpt_dir}", lambda: _train_fix(cfg, ckpt_dir, broken=True)
    sha = verify_weights(ckpt_dir, manifest, where, fix)
    if expect_digest is not None and expect_digest not in (manifest["digest"], sha):
        raise CheckpointError(
            f"checkpoint {ckpt_dir}: digest {manifest['digest']} differs from the expected {expect_digest}; "
            "the checkpoint changed since the run started; point checkpoint= at the original one"
        )
    return load_weights(ckpt_dir, model_from_manifest(manifest), where, fix), manifest


def lineage(manifest: dict[str, Any], _seen: frozenset[Path] = frozenset()) -> dict[str, Any]:
    """Training behind a model's weights (steps, CPU seconds, samples = steps x batch), summed through every
    ``train.init_from`` ancestor: a continued model's own ``train_steps`` start at zero. An ancestor still on
    disk is read again, so an old record cannot undercount; a total is None where an ancestor lacks it."""
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
    """The manifest on disk of an ``init_from`` record's weights: at its recorded path if that still holds its
    digest, else any ``checkpoints/*`` or ``runs/**`` manifest with that digest (the path's weights replaced)."""
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


def model_from_manifest(manifest: dict[str, Any]) -> DFTransformer:
    """An untrained model of the architecture a manifest describes (any model.kind)."""
    saved = manifest["config"]
    return build_model(model_config_from_dict(saved["model"]), manifest["n_tokens"], manifest["token_dim"],
                       diffusion_config_from_dict(saved.get("diffusion", {})))


def normaliser_from_manifest(manifest: dict[str, Any]) -> Normaliser:
    """The normaliser the model was trained with (the planner must use the same one)."""
    n = manifest["normaliser"]
    return Normaliser.from_lists(n["mean"], n["std"])
