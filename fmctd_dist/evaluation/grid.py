"""The evaluation grid (tasks x seeds) for one (method, env): validate, resume, run, record.

``prepare`` does every check a user can fail (config, device, checkpoint and its agreement
with the config) in the job process, before any actor or episode starts; the runners then
only skip keys that already have a row and write one Parquet file per finished episode.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from tqdm.auto import tqdm

from fmctd_dist.config import Config, git_sha
from fmctd_dist.device import resolve_device, set_threads
from fmctd_dist.diffusion.checkpoint import read_manifest, sha256_file
from fmctd_dist.errors import CheckpointError
from fmctd_dist.evaluation.controllers import check_controller, controller_factory
from fmctd_dist.evaluation.episode import describe, run_episode
from fmctd_dist.evaluation.results import ResultStore


@dataclass(frozen=True)
class Prepared:
    """Everything validated up front; small and picklable so it can be shipped to actors."""

    cfg: Config
    checkpoint: Path
    checkpoint_digest: str
    device: str
    config_hash: str
    git_sha: str


def config_hash(cfg: Config) -> str:
    """Hash of what determines a plan: everything but where/how the grid is run."""
    d = cfg.to_dict()
    for key in ("eval", "ray"):
        d.pop(key)
    return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:16]


def prepare(cfg: Config) -> Prepared:
    check_controller(cfg)  # AntMaze: the low-level policy exists and was trained for this maze
    device = str(resolve_device(cfg.device))
    ckpt = cfg.checkpoint_dir()
    manifest = read_manifest(ckpt, cfg)  # exists, parses, agrees with env/jump/model/n_tokens
    if sha256_file(ckpt / "model.pt") != manifest.get("model_sha256"):
        raise CheckpointError(f"checkpoint {ckpt}: model.pt does not match its manifest (corrupt); "
                              f"retrain with `python jobs/train.py env={cfg.env.name} jump={cfg.jump}`")
    return Prepared(cfg, ckpt, manifest["digest"], device, config_hash(cfg), git_sha())


def grid(cfg: Config) -> list[tuple[int, int]]:
    return [(t, s) for t in cfg.eval.tasks for s in cfg.eval.seeds]


def missing(cfg: Config, store: ResultStore) -> list[tuple[int, int]]:
    """The (task, seed) keys of the grid that have no row yet: what a (re)run still has to do."""
    return [(t, s) for t, s in grid(cfg) if not store.has(cfg.method.name, cfg.env.name, t, s)]


def provenance(p: Prepared, n_actors: int) -> dict[str, Any]:
    """Run-level fields of a row: where it ran, and the search knobs the ablation tables group by."""
    m = p.cfg.method
    return {"n_denoiser_actors": n_actors, "device": p.device, "git_sha": p.git_sha,
            "checkpoint_digest": p.checkpoint_digest, "config_hash": p.config_hash,
            "parallel": m.parallel, "virtual_weight": m.virtual_weight, "redundancy_aware": m.redundancy_aware,
            "leaf_parallel": m.leaf_parallel, "jump": p.cfg.jump, "budget": m.budget,
            "episode_time_limit": p.cfg.eval.episode_time_limit}


def run_local(p: Prepared, store: ResultStore, progress: bool = True,
              log: Callable[[str], None] = print) -> list[dict[str, Any]]:
    """All missing episodes of the grid in this process (LocalDenoiser, no Ray)."""
    from fmctd_dist.denoiser.local import LocalDenoiser
    from fmctd_dist.diffusion.checkpoint import normaliser_from_manifest
    from fmctd_dist.envs import make_env
    from fmctd_dist.planners import make_planner

    cfg = p.cfg
    todo = missing(cfg, store)
    if not todo:
        return []
    set_threads(cfg.eval.threads)
    denoiser = LocalDenoiser.from_checkpoint(p.checkpoint, cfg, expect_digest=p.checkpoint_digest)
    manifest = read_manifest(p.checkpoint)
    planner = make_planner(cfg, denoiser, normaliser_from_manifest(manifest), cfg.eval.episode_time_limit)
    env = make_env(cfg.env.name, cfg.env.protocol)
    make_controller = controller_factory(cfg)
    rows = []
    bar = tqdm(todo, desc=f"{cfg.method.name} {cfg.env.name}", unit="ep", disable=not progress)
    for task, seed in bar:
        row = {**run_episode(cfg, env, planner, task, seed, make_controller=make_controller), **provenance(p, 0)}
        store.write(row)
        rows.append(row)
        bar.set_postfix(success=f"{sum(r['success'] for r in rows)}/{len(rows)}")
        log(describe(row))
    return rows
