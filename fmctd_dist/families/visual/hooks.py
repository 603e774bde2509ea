"""Visual maze hooks (docs/reference.md §14): maze guidance scales and value on estimated positions; image episodes.

- Plan rules: the tree's children are the maze's guidance scales (``method.guidance_scales``), the
  guidance reads the position estimator's (x, y) of the latent plan, or with ``visual.plan_xy`` the
  plan's own (x, y) (:func:`guide_map`, used by the denoiser; :func:`plan_frames`), and the value is
  the maze rule on those positions (:class:`VisualValue`; our
  reading, the paper gives no visual value rule).
- Episodes: the env renders the chase camera's 64x64 frame, the VAE encodes it, the planner plans
  latents, the inverse dynamics acts toward them (``families/visual/episode.py``).

Parts: ``checkpoints/<env>-{vae,estimator,invdyn}``. :func:`check_episodes` checks, in the job
process before any actor starts, that the planner checkpoint fits the config (a maze model given to
the visual env is refused there), that it was trained on latents of the VAE loaded here, and that
the estimator and inverse dynamics read that VAE's latents of the planner's size: one
CheckpointError each, naming the field, the value and the fix.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fmctd_dist.config import Config
from fmctd_dist.errors import CheckpointError
from fmctd_dist.registry import state_dim
from fmctd_dist.family import warp_threshold
from fmctd_dist.families.maze.hooks import MazeRules
from fmctd_dist.planners.base import Planner
from fmctd_dist.search.value_rule import MazeValue
from fmctd_dist.families.visual.plan_value import VisualValue


@dataclass(frozen=True)
class VisualParts:
    """The checked manifests of the planner and the three parts it works with."""

    planner: dict[str, Any]
    vae: dict[str, Any]
    estimator: dict[str, Any]
    invdyn: dict[str, Any]


def check_parts(cfg: Config) -> VisualParts:
    """Planner, VAE, estimator and inverse dynamics agree (env, latent size, VAE digest, sha256); else one error."""
    from fmctd_dist.diffusion.checkpoint import read_manifest, verify_checkpoint
    from fmctd_dist.families.visual.checkpoint import read_part_manifest
    from fmctd_dist.families.visual.config import LATENT_KEY, part_dir
    from fmctd_dist.families.visual.guide import latent_provenance

    ckpt = cfg.checkpoint_dir()
    manifest = read_manifest(ckpt, cfg)
    saved = manifest.get(LATENT_KEY)
    if isinstance(saved, dict) and bool(saved.get("plan_xy")) != cfg.visual.plan_xy:  # before the shape checks
        was = "[z, x, y] frames (visual.plan_xy=true)" if saved.get("plan_xy") else "latent frames"
        raise CheckpointError(f"checkpoint {ckpt} plans {was} but the config has visual.plan_xy="
                              f"{str(cfg.visual.plan_xy).lower()}; set visual.plan_xy="
                              f"{str(bool(saved.get('plan_xy'))).lower()} or pick a checkpoint trained for this one")
    planner = verify_checkpoint(ckpt, cfg, manifest)  # env, jump, model, n_tokens: a maze model stops here (env.name)
    prov = latent_provenance(planner, ckpt)
    vae_dir = part_dir(cfg, "", "vae")
    vae = read_part_manifest(vae_dir, "vae", cfg.env.name)
    latent_dim = state_dim(cfg.env.name)
    if int(vae["latent_dim"]) != latent_dim or int(prov.get("latent_dim", -1)) != latent_dim:
        raise CheckpointError(f"latent size: the VAE {vae_dir} makes {vae['latent_dim']}-D latents and the planner "
                              f"{ckpt} models {prov.get('latent_dim')}-D ones, but env.name={cfg.env.name} plans "
                              f"{latent_dim}-D latents; train the VAE with vae.latent_dim={latent_dim} and the "
                              f"planner on its latents (python jobs/train.py env={cfg.env.name} jump={cfg.jump})")
    if prov["vae_digest"] != vae["digest"]:
        raise CheckpointError(f"checkpoint {ckpt}: latents.vae_digest={prov['vae_digest']!r} but the VAE in {vae_dir} "
                              f"has digest {vae['digest']!r}: the planner models another VAE's latents; retrain it "
                              f"on this VAE's latent store (python jobs/train.py env={cfg.env.name} jump={cfg.jump} "
                              f"train.out=<new dir>) or restore the VAE it was trained with ({prov.get('vae_path')})")
    heads = {part: read_part_manifest(part_dir(cfg, "", part), part, cfg.env.name, latent_dim, vae["digest"])
             for part in ("estimator", "invdyn")}
    if prov.get("plan_xy") and prov.get("estimator_digest") != heads["estimator"]["digest"]:
        raise CheckpointError(f"checkpoint {ckpt} plans the (x, y) of estimator {prov.get('estimator_digest')!r} but "
                              f"{part_dir(cfg, '', 'estimator')} has digest {heads['estimator']['digest']!r}: its "
                              f"start and goal positions would be read by another estimator; retrain the planner "
                              f"with visual.plan_xy=true on this estimator, or restore the one it was trained with")
    return VisualParts(planner, vae, heads["estimator"], heads["invdyn"])


def plan_frames(cfg: Config, manifest: dict[str, Any] | None = None):
    """Latents <-> the checkpoint's planner frames, and their world (x, y) (``visual/frames_xy.py``).

    ``manifest``: the planner's, when the caller has read (and checked) it already."""
    from fmctd_dist.diffusion.checkpoint import read_manifest
    from fmctd_dist.families.visual.frames_xy import PlanFrames
    from fmctd_dist.families.visual.guide import latent_provenance, load_positions

    manifest = read_manifest(cfg.checkpoint_dir(), cfg) if manifest is None else manifest
    prov = latent_provenance(manifest, cfg.checkpoint_dir())
    positions, _ = load_positions(cfg, prov["vae_digest"], int(prov["latent_dim"]))
    return PlanFrames(positions, int(prov["latent_dim"]), bool(prov.get("plan_xy")))


def plan_rules(cfg: Config) -> MazeRules:
    m = cfg.method
    value = VisualValue(plan_frames(cfg), MazeValue(warp_threshold(cfg), float(m.goal_radius)))
    return MazeRules(tuple(float(s) for s in m.guidance_scales), float(m.guidance_scale), value)


def guide_map(cfg: Config, manifest: dict[str, Any]):
    """The denoiser's guidance space: normalised latent -> normalised estimated (x, y) (``visual/guide.py``)."""
    from fmctd_dist.families.visual.guide import guide_map as estimator_guide

    return estimator_guide(cfg, manifest)


def check_episodes(cfg: Config) -> str:
    """Every part checked (see :func:`check_parts`); the inverse dynamics' digest keys the rows as a policy's."""
    return str(check_parts(cfg).invdyn["digest"])


class VisualEpisodes:
    """The visual env, the VAE and the inverse dynamics, built once; :func:`run_visual_episode` per episode."""

    def __init__(self, cfg: Config):
        from fmctd_dist.families.visual.env import VisualPointMaze
        from fmctd_dist.families.visual.config import part_dir
        from fmctd_dist.families.visual.load import load_invdyn, load_vae

        self.cfg = cfg
        parts = check_parts(cfg)
        self.vae = load_vae(part_dir(cfg, "", "vae"), cfg.env.name, state_dim(cfg.env.name))
        self.invdyn = load_invdyn(part_dir(cfg, "", "invdyn"), cfg.env.name, self.vae)
        self.frames = plan_frames(cfg, parts.planner)  # latents <-> planner frames -> world (x, y)
        self.policy_digest = str(parts.invdyn["digest"])
        self.env = VisualPointMaze(cfg.env.name, cfg.env.protocol, shadowsize=cfg.visual.shadowsize)

    def run(self, planner: Planner, task: int, seed: int) -> dict[str, Any]:
        from fmctd_dist.families.visual.episode import run_visual_episode

        return run_visual_episode(self.cfg, self.env, self.vae.encode, self.invdyn, self.frames, planner, task, seed)


def episodes(cfg: Config) -> VisualEpisodes:
    return VisualEpisodes(cfg)


def plot_episode(row: dict[str, Any], path: Path) -> Path:
    """The first plan as the estimator reads it and the executed trajectory, on the point maze's map."""
    from fmctd_dist.families.maze.geometry import maze_geometry
    from fmctd_dist.families.visual.env import point_env_name
    from fmctd_dist.families.maze.plots import plot_episode as plot_maze_episode

    return plot_maze_episode(row, maze_geometry(point_env_name(row["env"])), path)
