"""Goal-conditioned BC with hindsight subgoals: the low-level AntMaze policy that walks the ant to plan points.

    action [8] = tanh(MLP(ant state without x, y [27]  ++  clip_norm(subgoal - x, y) [2]))

The planner gives x, y waypoints; the ant needs torques. The input drops the absolute x, y
and sees the subgoal only relative to the torso: walking 1 m north-east takes the same
torques anywhere in the maze, so the policy is translation invariant by construction and
every row of the dataset teaches every place (the walls are the planner's business). The
relative subgoal's norm is clipped at ``max_subgoal_dist`` so a far subgoal (a slow ant, a
plan that jumps) reads as "that way, far" instead of an input never seen in training.

Trained by MSE onto the dataset's noisy expert torques (their mean is the expert's), with
subgoals relabelled in hindsight (:mod:`fmctd_dist.control.policy.ant_data`); deterministic.
Checkpoints follow the expert's: ``model.pt`` (state_dict, input normalisation included)
+ ``manifest.json`` (config, dataset and expert digests, git sha, metrics, sha256), loaded
with ``torch.load(weights_only=True)``; anything wrong is one :class:`CheckpointError`.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from fmctd_dist.diffusion.checkpoint import atomic_torch_save, first_line, module_state, sha256_file, write_manifest
from fmctd_dist.envs.antmaze import ACT_DIM, OBS_DIM
from fmctd_dist.errors import CheckpointError

NAME = "goal-conditioned BC with hindsight subgoals"
KIND = "ant-goal-bc"
FORMAT_VERSION = 1
MODEL_FILE = "model.pt"
MANIFEST_FILE = "manifest.json"
IN_DIM = OBS_DIM - 2 + 2  # proprioception (27) + relative subgoal (2)
INPUT_LAYOUT = (f"act(obs [..., {OBS_DIM}], subgoal [..., 2]): obs is the full OGBench ant observation (qpos 15 + "
                "qvel 14, x and y first; the policy subtracts x, y from the subgoal itself), subgoal is a world x, y")
OTHER_KINDS = {"ant-direction-sac": "the ant expert that makes datasets", "df": "a Diffusion Forcing planner",
               "diffuser": "a Diffuser planner"}


def train_fix(env_name: str = "<antmaze-env>", out: str | Path | None = None) -> str:
    where = f" policy.out={out}" if out is not None else ""
    return f"train one with `python jobs/train_policy.py env={env_name}{where}`"


def policy_input(obs: np.ndarray, subgoal: np.ndarray, max_dist: float) -> np.ndarray:
    """obs [..., 29] + subgoal [..., 2] (world x, y) -> [..., 29] float32 network input."""
    obs = np.asarray(obs, dtype=np.float32)
    rel = np.asarray(subgoal, dtype=np.float32) - obs[..., :2]
    if max_dist > 0:
        norm = np.linalg.norm(rel, axis=-1, keepdims=True)
        rel = rel * np.minimum(1.0, max_dist / np.maximum(norm, 1e-6)).astype(np.float32)
    return np.concatenate([obs[..., 2:], rel], axis=-1)


class GoalPolicyNet(nn.Module):
    """[B, 29] input -> [B, 8] torques in (-1, 1). Input standardised by buffers set from the training data."""

    def __init__(self, hidden: list[int]):
        super().__init__()
        self.register_buffer("in_mean", torch.zeros(IN_DIM))
        self.register_buffer("in_std", torch.ones(IN_DIM))
        layers: list[nn.Module] = []
        width = IN_DIM
        for h in hidden:
            layers += [nn.Linear(width, h), nn.LayerNorm(h), nn.ReLU()]
            width = h
        layers.append(nn.Linear(width, ACT_DIM))
        self.net = nn.Sequential(*layers)

    def set_normaliser(self, x: np.ndarray) -> None:
        """Standardise inputs with the mean / std of training inputs x [N, 29] (std floored at 1e-3)."""
        x = np.asarray(x, dtype=np.float64)
        with torch.no_grad():
            self.in_mean.copy_(torch.as_tensor(x.mean(0), dtype=torch.float32))
            self.in_std.copy_(torch.as_tensor(np.maximum(x.std(0), 1e-3), dtype=torch.float32))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.tanh(self.net((x - self.in_mean) / self.in_std))


def build_net(hidden: list[int], seed: int) -> GoalPolicyNet:
    """Seeded init without touching the caller's global torch RNG."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        return GoalPolicyNet(list(hidden))


def save_policy(out_dir: str | Path, net: GoalPolicyNet, fields: dict[str, Any]) -> dict[str, Any]:
    """Write model.pt then manifest.json; ``fields`` must hold ``config`` (PolicyConfig.to_dict()) and ``env``."""
    if "config" not in fields or "env" not in fields:
        raise ValueError("fields needs 'config' (PolicyConfig.to_dict()) and 'env' (the maze name)")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    atomic_torch_save(module_state(net), out_dir / MODEL_FILE)
    sha = sha256_file(out_dir / MODEL_FILE)
    manifest = {**fields, "kind": KIND, "name": NAME, "format": FORMAT_VERSION, "obs_dim": OBS_DIM,
                "act_dim": ACT_DIM, "in_dim": IN_DIM, "input_layout": INPUT_LAYOUT,
                "param_count": sum(p.numel() for p in net.parameters()), "model_sha256": sha, "digest": sha[:16]}
    write_manifest(manifest, out_dir / MANIFEST_FILE)
    return manifest


def read_policy_manifest(ckpt_dir: str | Path, env_name: str | None = None) -> dict[str, Any]:
    """The manifest of a policy dir; CheckpointError if missing, another kind, or trained for another env."""
    ckpt_dir = Path(ckpt_dir)
    fix = train_fix(env_name or "<antmaze-env>", ckpt_dir)
    for path in (ckpt_dir, ckpt_dir / MODEL_FILE, ckpt_dir / MANIFEST_FILE):
        if not path.exists():
            raise CheckpointError(f"ant policy: {path} does not exist; {fix} (or point policy.out to its dir)")
    try:
        manifest = json.loads((ckpt_dir / MANIFEST_FILE).read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise CheckpointError(f"ant policy: {ckpt_dir / MANIFEST_FILE} is unreadable ({e}); {fix}") from None
    if manifest.get("kind") != KIND:
        what = manifest.get("kind") or manifest.get("model_kind") or "unknown"
        desc = f" ({OTHER_KINDS[what]})" if what in OTHER_KINDS else ""
        raise CheckpointError(
            f"ant policy: {ckpt_dir} holds a checkpoint of kind {what!r}{desc}, not a goal-conditioned ant policy "
            f"(kind={KIND!r}); point policy.out to a dir written by jobs/train_policy.py, or "
            f"{train_fix(env_name or '<antmaze-env>')}"
        )
    if env_name is not None and manifest.get("env") != env_name:
        raise CheckpointError(
            f"ant policy {ckpt_dir} was trained on {manifest.get('env')} data but the env is {env_name}; point "
            f"policy.out to a policy trained on {env_name}, or {train_fix(env_name)}"
        )
    return manifest


class AntPolicy:
    """A loaded policy: ``act(obs [..., 29], subgoal [..., 2]) -> torques [..., 8]`` in (-1, 1), deterministic."""

    def __init__(self, net: GoalPolicyNet, manifest: dict[str, Any], where: Path):
        self.net, self.manifest, self.where = net.eval(), manifest, where
        self.env = str(manifest["env"])
        self.max_dist = float(manifest["config"]["policy"]["max_subgoal_dist"])

    def act(self, obs: np.ndarray, subgoal: np.ndarray) -> np.ndarray:
        obs, subgoal = np.asarray(obs), np.asarray(subgoal)
        if obs.shape[-1:] != (OBS_DIM,) or subgoal.shape[-1:] != (2,):
            raise ValueError(f"ant policy {self.where}: got obs {obs.shape} and subgoal {subgoal.shape}; "
                             f"{INPUT_LAYOUT}")
        x = torch.from_numpy(policy_input(obs, subgoal, self.max_dist))
        with torch.no_grad():
            return self.net(x).numpy().astype(np.float64)

    __call__ = act


def load_policy(ckpt_dir: str | Path, env_name: str | None = None, obs_dim: int = OBS_DIM) -> AntPolicy:
    """Verify and load a policy. ``env_name``: the maze it will drive; ``obs_dim``: what the caller feeds."""
    from fmctd_dist.control.policy.config import policy_config_from_dict  # deferred: omegaconf

    ckpt_dir = Path(ckpt_dir)
    manifest = read_policy_manifest(ckpt_dir, env_name)
    fix = train_fix(str(manifest.get("env")), ckpt_dir)
    sha = sha256_file(ckpt_dir / MODEL_FILE)
    if sha != manifest.get("model_sha256"):
        raise CheckpointError(
            f"ant policy {ckpt_dir}: {MODEL_FILE} has sha256 {sha[:16]}... but manifest.json records "
            f"{str(manifest.get('model_sha256'))[:16]}... (corrupt or overwritten); {fix}"
        )
    if manifest.get("obs_dim") != obs_dim:
        raise CheckpointError(
            f"ant policy {ckpt_dir} takes obs_dim={manifest.get('obs_dim')} but the caller feeds obs_dim={obs_dim}; "
            f"{INPUT_LAYOUT}"
        )
    try:
        cfg = policy_config_from_dict(manifest["config"])
        net = GoalPolicyNet(list(cfg.policy.hidden))
        net.load_state_dict(torch.load(ckpt_dir / MODEL_FILE, map_location="cpu", weights_only=True), strict=True)
    except Exception as e:  # noqa: BLE001 - any unpickling/shape/config failure means a bad checkpoint
        raise CheckpointError(f"ant policy {ckpt_dir}: {MODEL_FILE} does not load ({first_line(e)}); {fix}") from None
    return AntPolicy(net, manifest, ckpt_dir)
