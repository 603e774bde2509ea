"""Goal-conditioned policy checkpoints, for every family: write, read the manifest, verify and load.

Like the expert's: ``model.pt`` (state_dict, input normalisation included) + ``manifest.json``
(kind, env, config, dataset digests, git sha, metrics, sha256), loaded with
``torch.load(weights_only=True)``. The caller names the family's
:class:`~fmctd_dist.control.policy.spec.PolicySpec` it expects (the family that drives the robot knows
its own; jobs ask :func:`fmctd_dist.families.policy_hooks`); the manifest's ``kind`` must be that spec's.
Anything wrong (missing, another kind, another env, corrupt, shapes) is one :class:`CheckpointError`
that says what to do.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch

from fmctd_dist.control.policy.network import GoalPolicyNet
from fmctd_dist.control.policy.spec import PolicySpec, require_policy
from fmctd_dist.artifacts import load_weights, read_weights_manifest, save_weights, verify_weights
from fmctd_dist.errors import CheckpointError
from fmctd_dist.registry import env_specs, family

FORMAT_VERSION = 1
OTHER_KINDS = {"ant-direction-sac": "the ant expert that makes datasets", "df": "a Diffusion Forcing planner",
               "diffuser": "a Diffuser planner"}


def label(kind: str) -> str:
    """How errors name the policy of a family kind: 'ant policy', 'cube policy' (else 'policy')."""
    return {"antmaze": "ant policy", "cube": "cube policy"}.get(kind, "policy")


def train_fix(env_name: str = "<env>", out: str | Path | None = None) -> str:
    where = f" policy.out={out}" if out is not None else ""
    return f"train one with `python jobs/train_policy.py env={env_name}{where}`"


def save_policy(out_dir: str | Path, net: GoalPolicyNet, spec: PolicySpec, fields: dict[str, Any]) -> dict[str, Any]:
    """Write model.pt then manifest.json; ``fields`` must hold ``config`` (PolicyConfig.to_dict()) and ``env``."""
    if "config" not in fields or "env" not in fields:
        raise ValueError("fields needs 'config' (PolicyConfig.to_dict()) and 'env' (the env name)")
    return save_weights(out_dir, net, {**fields, "kind": spec.kind, "name": spec.name, "format": FORMAT_VERSION,
                                       "obs_dim": spec.obs_dim, "act_dim": spec.act_dim, "in_dim": spec.in_dim,
                                       "input_layout": spec.input_layout})


def read_policy_manifest(ckpt_dir: str | Path, spec: PolicySpec, env_name: str | None = None) -> dict[str, Any]:
    """The manifest of a policy dir; CheckpointError if missing, not of ``spec``'s kind, or trained for another env.

    With ``env_name`` the policy must have been trained on that very env, unless the family's policy
    serves all its envs (cubes) and it was trained on one of them.
    """
    if env_name is not None:
        require_policy(env_name)  # a point maze: one ConfigError (it has the PD controller)
    ckpt_dir = Path(ckpt_dir)
    who = label(spec.family)
    fix = train_fix(env_name or "<env>", ckpt_dir)
    manifest = read_weights_manifest(ckpt_dir, who, f"{fix} (or point policy.out to its dir)", fix)
    kind = manifest.get("kind")
    if kind != spec.kind:
        what = kind or manifest.get("model_kind") or "unknown"
        # another family's policy (save_policy writes an input layout) is named by the env it was trained on
        other = label(env_specs()[manifest["env"]].family) if "input_layout" in manifest and \
            manifest.get("env") in env_specs() else "policy"
        desc = f" ({OTHER_KINDS[what]})" if what in OTHER_KINDS else f" (the {other})" if other != "policy" else ""
        for_env = f" for {env_name}" if env_name else ""
        raise CheckpointError(
            f"{who}: {ckpt_dir} holds a checkpoint of kind {what!r}{desc}, not a goal-conditioned {who} "
            f"(kind={spec.kind!r}); point policy.out to a dir written by jobs/train_policy.py{for_env}, or "
            f"{train_fix(env_name or '<env>')}"
        )
    trained_on = manifest.get("env")
    if env_name is not None and trained_on != env_name and not (
            spec.any_env_of_family and isinstance(trained_on, str) and family(trained_on) == spec.family):
        raise CheckpointError(
            f"{who} {ckpt_dir} was trained on {trained_on} data but the env is {env_name}; point "
            f"policy.out to a policy trained on {env_name}, or {train_fix(env_name)}"
        )
    return manifest


class GoalPolicy:
    """A loaded policy: ``act(obs [..., obs_dim], subgoal [..., goal_dim]) -> action [..., act_dim]``, deterministic."""

    def __init__(self, net: GoalPolicyNet, spec: PolicySpec, manifest: dict[str, Any], where: Path):
        self.net, self.spec, self.manifest, self.where = net.eval(), spec, manifest, where
        self.env = str(manifest["env"])
        self.max_dist = float(manifest["config"]["policy"]["max_subgoal_dist"])

    def act(self, obs: np.ndarray, subgoal: np.ndarray) -> np.ndarray:
        obs, subgoal = np.asarray(obs), np.asarray(subgoal)
        if obs.shape[-1:] != (self.spec.obs_dim,) or subgoal.shape[-1:] != (self.spec.goal_dim,):
            raise ValueError(f"{label(self.spec.family)} {self.where}: got obs {obs.shape} and subgoal "
                             f"{subgoal.shape}; {self.spec.input_layout}")
        x = torch.from_numpy(self.spec.make_input(obs, subgoal, self.max_dist))
        with torch.no_grad():
            return self.net(x).numpy().astype(np.float64)

    __call__ = act


def load_policy(ckpt_dir: str | Path, spec: PolicySpec, env_name: str | None = None,
                obs_dim: int | None = None) -> GoalPolicy:
    """Verify and load a policy of ``spec``. ``env_name``: the env it will drive; ``obs_dim``: what the caller
    feeds."""
    from fmctd_dist.control.policy.config import policy_config_from_dict  # deferred: omegaconf

    ckpt_dir = Path(ckpt_dir)
    manifest = read_policy_manifest(ckpt_dir, spec, env_name)
    who = label(spec.family)
    fix = train_fix(str(manifest.get("env")), ckpt_dir)
    verify_weights(ckpt_dir, manifest, f"{who} {ckpt_dir}", fix)
    feeds = spec.obs_dim if obs_dim is None else obs_dim
    if manifest.get("obs_dim") != feeds:
        raise CheckpointError(
            f"{who} {ckpt_dir} takes obs_dim={manifest.get('obs_dim')} but the caller feeds obs_dim={feeds}; "
            f"{spec.input_layout}"
        )
    def build() -> GoalPolicyNet:  # inside load_weights: a config that does not parse is a bad checkpoint too
        return GoalPolicyNet(list(policy_config_from_dict(manifest["config"]).policy.hidden), spec.in_dim, spec.act_dim)

    return GoalPolicy(load_weights(ckpt_dir, build, f"{who} {ckpt_dir}", fix), spec, manifest, ckpt_dir)
