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
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from fmctd_dist.config import REPO_ROOT, Config, ModelConfig
from fmctd_dist.data.tokens import Normaliser
from fmctd_dist.diffusion.model import DFTransformer
from fmctd_dist.diffusion.models import build_model, diffusion_config_from_dict, model_config_from_dict
from fmctd_dist.errors import CheckpointError

MODEL_FILE = "model.pt"
MANIFEST_FILE = "manifest.json"
TRAIN_STATE_FILE = "train_state.pt"
FORMAT_VERSION = 1
MODEL_FIELDS = ("kind", "frame_stack", "width", "layers", "heads", "ff", "param", "norm")
UNET_FIELDS = ("unet_channels", "unet_kernel", "unet_padding", "unet_edge_frames")  # checked when kind=diffuser
SHAPE_FREE_FIELDS = ("unet_padding", "unet_edge_frames")  # fields a state_dict does not depend on: train.init_from may change them


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


def save_checkpoint(ckpt_dir: str | Path, model: DFTransformer, manifest_fields: dict[str, Any]) -> dict[str, Any]:
    """Write model.pt then manifest.json; returns the manifest.

    ``manifest_fields`` must hold ``config`` (Config.to_dict()); by convention also
    dataset_digest, data_seed, git_sha, train_steps, wall_time_s, final_losses, normaliser
    ({mean, std}). This adds model_sha256, digest (its first 16 hex), param_count,
    n_tokens, token_dim, model_kind and format.
    """
    if "config" not in manifest_fields:
        raise ValueError("manifest_fields needs 'config' (Config.to_dict())")
    ckpt_dir = Path(ckpt_dir)
    ckpt_dir.mkdir(parents=True, exist_ok=True)
    atomic_torch_save(module_state(model), ckpt_dir / MODEL_FILE)
    sha = sha256_file(ckpt_dir / MODEL_FILE)
    manifest = {
        **manifest_fields,
        "format": FORMAT_VERSION,
        "model_kind": model.kind,
        "n_tokens": model.n_tokens,
        "token_dim": model.token_dim,
        "param_count": model.num_params(),
        "model_sha256": sha,
        "digest": sha[:16],
    }
    write_manifest(manifest, ckpt_dir / MANIFEST_FILE)
    return manifest


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"{type(o).__name__} is not JSON serialisable")


def _train_fix(cfg: Config | None) -> str:
    if cfg is None:
        return "train one with `python jobs/train.py env=<env> jump=<H>`"
    default = ModelConfig()
    extra = "".join(f" model.{f}={str(getattr(cfg.model, f)).replace(' ', '')}" for f in _model_fields(cfg)
                    if getattr(cfg.model, f) != getattr(default, f))
    out = cfg.checkpoint_dir()
    try:
        out = out.relative_to(REPO_ROOT)
    except ValueError:
        pass
    return f"train one with `python jobs/train.py env={cfg.env.name} jump={cfg.jump}{extra} train.out={out}`"


def read_manifest(ckpt_dir: str | Path, cfg: Config | None = None) -> dict[str, Any]:
    """The manifest of a checkpoint dir; CheckpointError if the dir or its files are missing."""
    ckpt_dir = Path(ckpt_dir)
    for path in (ckpt_dir, ckpt_dir / MODEL_FILE, ckpt_dir / MANIFEST_FILE):
        if not path.exists():
            raise CheckpointError(f"checkpoint: {path} does not exist; {_train_fix(cfg)} or set checkpoint=<dir>")
    try:
        return json.loads((ckpt_dir / MANIFEST_FILE).read_text())
    except (OSError, json.JSONDecodeError) as e:
        path = ckpt_dir / MANIFEST_FILE
        raise CheckpointError(f"checkpoint: {path} is unreadable ({e}); {_train_fix(cfg)}") from None


def check_compatible(manifest: dict[str, Any], cfg: Config, where: str | Path) -> None:
    """Raise one CheckpointError naming the first field where checkpoint and config disagree."""
    saved = manifest.get("config", {})
    saved_model = _saved_model(manifest)
    pairs = [("env.name", saved.get("env", {}).get("name"), cfg.env.name), ("jump", saved.get("jump"), cfg.jump)]
    pairs += [(f"model.{f}", saved_model.get(f), getattr(cfg.model, f)) for f in _model_fields(cfg)]
    pairs += [("n_tokens", manifest.get("n_tokens"), cfg.n_tokens)]
    for name, have, want in pairs:
        if have != want:
            hint = " (n_tokens = env.horizon / jump / model.frame_stack + 1)" if name == "n_tokens" else ""
            raise CheckpointError(
                f"checkpoint {where} was trained with {name}={have!r} but the config has {name}={want!r}{hint}; "
                f"{_train_fix(cfg)}, or set {name}={have!r} to use this checkpoint"
            )


def _verified_sha(ckpt_dir: Path, manifest: dict[str, Any], where: str, fix: str) -> str:
    """sha256 of ``model.pt``, or one CheckpointError if the manifest records another."""
    sha = sha256_file(ckpt_dir / MODEL_FILE)
    if sha != manifest.get("model_sha256"):
        raise CheckpointError(
            f"{where}: {MODEL_FILE} has sha256 {sha[:16]}... but manifest.json records "
            f"{str(manifest.get('model_sha256'))[:16]}... (corrupt or overwritten); {fix}"
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
    sha = _verified_sha(ckpt_dir, manifest, f"checkpoint {ckpt_dir}", _train_fix(cfg))
    if expect_digest is not None and expect_digest not in (manifest["digest"], sha):
        raise CheckpointError(
            f"checkpoint {ckpt_dir}: digest {manifest['digest']} differs from the expected {expect_digest}; "
            "the checkpoint changed since the run started; point checkpoint= at the original one"
        )
    if cfg is not None:
        check_compatible(manifest, cfg, ckpt_dir)
    model = model_from_manifest(manifest)
    try:
        state = torch.load(ckpt_dir / MODEL_FILE, map_location="cpu", weights_only=True)
        model.load_state_dict(state, strict=True)
    except Exception as e:  # noqa: BLE001 - any unpickling/shape failure means a bad checkpoint
        raise CheckpointError(f"checkpoint {ckpt_dir}: {MODEL_FILE} does not load ({e}); {_train_fix(cfg)}") from None
    return model.eval(), manifest


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
    state = torch.load(ckpt_dir / MODEL_FILE, map_location="cpu", weights_only=True)
    provenance = {"path": str(ckpt_dir.relative_to(REPO_ROOT) if ckpt_dir.is_relative_to(REPO_ROOT) else ckpt_dir),
                  "digest": manifest["digest"], "env": manifest.get("config", {}).get("env", {}).get("name"),
                  "jump": manifest.get("config", {}).get("jump"), "train_steps": manifest.get("train_steps")}
    return state, provenance


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
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # noqa: BLE001
        raise CheckpointError(
            f"checkpoint {path} is unreadable ({e}); delete it to restart training from scratch"
        ) from None


def module_state(model: nn.Module) -> dict[str, torch.Tensor]:
    """state_dict copied to CPU (what every file here stores)."""
    return {k: v.detach().to("cpu").clone() for k, v in model.state_dict().items()}
