"""Checkpoints of the visual maze's three parts: the VAE, the position estimator, the inverse dynamics.

Each is a dir with ``model.pt`` (state_dict, loaded with ``weights_only=True``) and
``manifest.json`` (kind, env, latent size, config, data digests, steps, wall time, metrics,
sha256), as the planner's checkpoints. The estimator and the inverse dynamics read latents, so
their manifests name the VAE (its digest) whose latents they were trained on: a head is only
ever loaded beside that VAE. Anything wrong (missing, corrupt, another kind such as a point
maze planner, another env, another latent size, another VAE) is one :class:`CheckpointError`
naming the field, the value and the fix.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from torch import nn

from fmctd_dist.artifacts import load_weights, read_weights_manifest, save_weights, verify_weights
from fmctd_dist.errors import CheckpointError

FORMAT_VERSION = 1
KINDS = {"vae": "visual-vae", "estimator": "visual-estimator", "invdyn": "visual-invdyn"}
WHAT = {"visual-vae": "the visual maze's VAE", "visual-estimator": "the visual maze's position estimator",
        "visual-invdyn": "the visual maze's inverse dynamics", "df": "a Diffusion Forcing planner (state space)",
        "diffuser": "a Diffuser planner (state space)", "ant-goal-bc": "an AntMaze low-level policy",
        "ant-direction-sac": "the ant expert that makes datasets"}


def train_fix(part: str, env: str, out: str | Path | None = None) -> str:
    where = f" {part}.out={out}" if out is not None else ""
    return f"train one with `python jobs/train_visual.py part={part} env={env}{where}`"


def save_part(out_dir: str | Path, part: str, net: nn.Module, fields: dict[str, Any]) -> dict[str, Any]:
    """Write model.pt then manifest.json; ``fields`` must hold ``env`` and ``latent_dim``."""
    for key in ("env", "latent_dim"):
        if key not in fields:
            raise ValueError(f"fields needs {key!r}")
    return save_weights(out_dir, net, {**fields, "kind": KINDS[part], "format": FORMAT_VERSION})


def read_part_manifest(ckpt_dir: str | Path, part: str, env: str, latent_dim: int | None = None,
                       vae_digest: str | None = None) -> dict[str, Any]:
    """The manifest of a ``part`` checkpoint for ``env``, checked (kind, env, latent size, VAE, sha256)."""
    ckpt_dir = Path(ckpt_dir)
    fix = train_fix(part, env, ckpt_dir)
    name = f"visual {part} checkpoint {ckpt_dir}"
    m = read_weights_manifest(ckpt_dir, name, f"{fix} (or point {part}.out to its dir)", fix)
    kind = m.get("kind") or m.get("model_kind") or "unknown"
    if kind != KINDS[part]:
        cfg = m.get("config") if isinstance(m.get("config"), dict) else {}
        trained = m.get("env") or (cfg.get("env") if isinstance(cfg.get("env"), dict) else {}).get("name", "?")
        raise CheckpointError(f"{name} holds kind={kind!r} ({WHAT.get(kind, 'not a visual-maze part')}, env "
                              f"{trained}), not {WHAT[KINDS[part]]} (kind={KINDS[part]!r}); point {part}.out to a "
                              f"dir written by jobs/train_visual.py part={part}, or {train_fix(part, env)}")
    if m.get("env") != env:
        raise CheckpointError(f"{name}: env={m.get('env')!r} but this run's env is {env!r}; point {part}.out to "
                              f"a {part} trained on {env}, or {train_fix(part, env)}")
    if latent_dim is not None and m.get("latent_dim") != latent_dim:
        raise CheckpointError(f"{name}: latent_dim={m.get('latent_dim')!r} but the latents here are {latent_dim}-D; "
                              f"use the {part} trained on this VAE's latents, or {train_fix(part, env)}")
    if vae_digest is not None and m.get("vae", {}).get("digest") != vae_digest:
        raise CheckpointError(f"{name}: vae.digest={m.get('vae', {}).get('digest')!r} but the VAE given is "
                              f"{vae_digest!r}; its latents mean something else: use the {part} trained on this "
                              f"VAE, or {train_fix(part, env)}")
    verify_weights(ckpt_dir, m, name, fix)
    return m


def load_state(ckpt_dir: Path, net: nn.Module, part: str, env: str) -> nn.Module:
    """Load model.pt into ``net`` (strict); a shape or unpickling failure is one CheckpointError."""
    return load_weights(ckpt_dir, net, f"visual {part} checkpoint {ckpt_dir}", train_fix(part, env, ckpt_dir))
