"""Ant expert checkpoints: ``model.pt`` (actor state_dict) + ``manifest.json`` (+ ``train_state.pt``).

The expert will generate AntMaze datasets, and a dataset is only as reproducible as the
policy behind it, so the manifest records the full config, env steps, git sha, metrics
and the sha256 of ``model.pt``; loading checks all of it and loads with
``torch.load(weights_only=True)``. Anything wrong (missing dir, other kind of checkpoint,
corrupt weights, an input of the wrong size) is one :class:`CheckpointError` naming the
field and the fix.
"""

from __future__ import annotations

import shlex
from pathlib import Path
from typing import Any

import numpy as np
import torch

from fmctd_dist.families.maze.expert.config import DEFAULT_OUT, expert_config_from_dict
from fmctd_dist.families.maze.expert.direction_env import ACT_DIM, OBS_DIM, PROPRIO_DIM
from fmctd_dist.families.maze.expert.sac import Actor
from fmctd_dist.artifacts import load_weights, read_weights_manifest, save_weights, verify_weights
from fmctd_dist.errors import CheckpointError

KIND = "ant-direction-sac"
FORMAT_VERSION = 1
OBS_LAYOUT = (f"[{OBS_DIM}] = OGBench ant qpos[2:] + qvel ({PROPRIO_DIM}, the 29-D ant observation without x, y) "
              "+ unit direction (2); build it with "
               "fmctd_dist.families.maze.expert.direction_env.expert_input(ob, direction)")
TRAIN_FIX = f"train one with `python jobs/train_expert.py expert.out={DEFAULT_OUT}`"


def train_fix(ckpt_dir: str | Path, broken: bool = False) -> str:
    """The command that writes an expert where the caller looked (a broken dir is moved aside first)."""
    from fmctd_dist.hints import shown, word

    cmd = f"python jobs/train_expert.py {word('expert.out', shown(ckpt_dir))}"
    if broken:
        cmd = f"mv {shlex.quote(shown(ckpt_dir))} {shlex.quote(shown(ckpt_dir) + '.broken')} && {cmd}"
    return f"train one with `{cmd}`"


def save_expert(out_dir: str | Path, actor: Actor, fields: dict[str, Any]) -> dict[str, Any]:
    """Write model.pt then manifest.json; ``fields`` must hold ``config`` (AntExpertConfig.to_dict())."""
    if "config" not in fields:
        raise ValueError("fields needs 'config' (AntExpertConfig.to_dict())")
    return save_weights(out_dir, actor, {**fields, "kind": KIND, "format": FORMAT_VERSION, "obs_dim": actor.obs_dim,
                                         "act_dim": actor.act_dim, "obs_layout": OBS_LAYOUT})


def read_expert_manifest(ckpt_dir: str | Path) -> dict[str, Any]:
    """The manifest of an expert dir; CheckpointError if anything is missing or it is another kind."""
    ckpt_dir = Path(ckpt_dir)
    manifest = read_weights_manifest(ckpt_dir, "ant expert", f"{train_fix(ckpt_dir)} (or point to its dir)",
                                     train_fix(ckpt_dir, broken=True))
    if manifest.get("kind") != KIND:
        what = manifest.get("kind") or manifest.get("model_kind") or "unknown"
        raise CheckpointError(
            f"ant expert: {ckpt_dir} holds a {what!r} checkpoint (manifest kind={what!r}), not an ant direction "
            f"expert (kind={KIND!r}); point to the dir written by jobs/train_expert.py, or "
            f"{train_fix(ckpt_dir, broken=True)}"
        )
    return manifest


class AntExpert:
    """A loaded expert: ``act(obs [..., 29]) -> action [..., 8]`` in [-1, 1], deterministic."""

    def __init__(self, actor: Actor, manifest: dict[str, Any], where: Path):
        self.actor, self.manifest, self.where = actor.eval(), manifest, where
        self.obs_dim, self.act_dim = actor.obs_dim, actor.act_dim

    def act(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float32)
        if obs.shape[-1:] != (self.obs_dim,):
            raise CheckpointError(
                f"ant expert {self.where}: input has shape {obs.shape} but the expert takes obs_dim={self.obs_dim}: "
                f"{OBS_LAYOUT}"
            )
        with torch.no_grad():
            return self.actor.act(torch.from_numpy(obs)).numpy().astype(np.float64)

    __call__ = act


def load_expert(ckpt_dir: str | Path, obs_dim: int = OBS_DIM, act_dim: int = ACT_DIM) -> AntExpert:
    """Verify and load an expert. ``obs_dim``/``act_dim``: what the caller will feed and expects back."""
    ckpt_dir = Path(ckpt_dir)
    manifest = read_expert_manifest(ckpt_dir)
    where, fix = f"ant expert {ckpt_dir}", train_fix(ckpt_dir, broken=True)
    verify_weights(ckpt_dir, manifest, where, fix)
    for name, have, want in (("obs_dim", manifest.get("obs_dim"), obs_dim),
                             ("act_dim", manifest.get("act_dim"), act_dim)):
        if have != want:
            raise CheckpointError(
                f"ant expert {ckpt_dir} was trained with {name}={have} but the caller asks for {name}={want}; "
                f"the expert's input is {OBS_LAYOUT}"
            )

    def build() -> Actor:  # inside load_weights: a config that does not parse is a bad checkpoint too
        hidden = list(expert_config_from_dict(manifest["config"]).sac.hidden)
        return Actor(manifest["obs_dim"], manifest["act_dim"], hidden)

    return AntExpert(load_weights(ckpt_dir, build, where, fix), manifest, ckpt_dir)
