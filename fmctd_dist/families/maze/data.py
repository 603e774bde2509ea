"""Navigate datasets: generate, write .npz + manifest, load and verify.

Layout: ``<data.root>/<env>-navigate-seed<seed>-<episodes>x<steps>/{train,val}.npz, manifest.json``.
Same config -> same bytes (per-episode seeds, deterministic npz). Loading verifies every
manifest field and sha256; a corrupt or mismatched file raises DatasetError and is never
silently regenerated over.

PointMaze data comes from the noisy BFS oracle (:mod:`fmctd_dist.families.maze.point_data`);
AntMaze data from the ant expert steered by the same oracle (:mod:`fmctd_dist.families.maze.ant_data`).
Both share the goal logic and per-episode seeding (:mod:`fmctd_dist.families.maze.navigate`,
below both) and the layout and manifest (here, above both); loading gives the planner x, y
observations [E, S, 2] for either.
"""

from __future__ import annotations

import json
import os
import shlex
import time
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from fmctd_dist.config import Config, is_ant, resolve_path
from fmctd_dist.families.maze.ant_data import ANT_GENERATOR_VERSION, AntSource, check_expert_matches
from fmctd_dist.data.manifest_io import read_manifest_json, split_lines
from fmctd_dist.families.maze.point_data import POINT_GENERATOR_VERSION, PointSource
from fmctd_dist.data.splits import SPLITS, SplitStates, load_split_states, val_episodes, verify_splits, write_splits
from fmctd_dist.errors import DatasetError
from fmctd_dist.families.maze.record import MAZE_KINDS
from fmctd_dist.registry import require_family

__all__ = ["SPLITS", "val_episodes", "dataset_dir", "make_dataset", "load_manifest", "load_dataset",
           "NavigateDataset", "regenerate_fix"]  # SPLITS: re-exported for families/visual/frame_sets.py
MANIFEST_FIELDS = ("generator_version", "env", "seed", "noise", "episode_steps", "episodes",
                   "sha256", "obs_mean", "obs_std")


def dataset_dir(cfg: Config) -> Path:
    d = cfg.data
    return resolve_path(d.root) / f"{cfg.env.name}-navigate-seed{d.seed}-{d.episodes}x{d.episode_steps}"


class DataSource(Protocol):
    """What :func:`make_dataset` needs from a generator; layout, seeding and the common manifest are shared."""

    version: int  # generator_version written to (and required in) the manifest

    def generate(self, split: str, episodes: int, progress: bool) -> dict[str, np.ndarray]:
        """Arrays [E, S, ...] of one split, ``observations`` first dims (E, S), x, y in observations[..., :2]."""
        ...

    def manifest_fields(self) -> dict[str, Any]:
        """Source-specific manifest fields, called after every split is generated."""
        ...


def data_source(cfg: Config) -> DataSource:
    """The generator for ``cfg.env``: the point oracle, or the ant expert (which loads and checks its weights)."""
    if is_ant(cfg.env.name):
        return AntSource(cfg)
    return PointSource(cfg)


def generator_version(env: str) -> int:
    return ANT_GENERATOR_VERSION if is_ant(env) else POINT_GENERATOR_VERSION


def make_dataset(cfg: Config, progress: bool = True) -> tuple[Path, dict[str, Any]]:
    """Generate (or verify an existing) dataset; return its dir and manifest."""
    require_family(cfg.env.name, MAZE_KINDS, "the navigate-data code (families/maze/data.py, used by jobs/train.py)")
    out = dataset_dir(cfg)
    if (out / "manifest.json").exists():
        return out, load_manifest(out, cfg, verify=True)
    if out.exists() and any(out.iterdir()):
        raise DatasetError(f"{out} exists but has no manifest.json (an interrupted run?); {regenerate_fix(out, cfg)}")
    source = data_source(cfg)  # the ant expert is loaded and checked before anything is written
    tmp = out.with_name(out.name + ".tmp")
    t0 = time.time()
    counts, sha, normaliser = write_splits(tmp, cfg, lambda split, n: source.generate(split, n, progress),
                                           slice(None, 2))  # the planner's x, y
    manifest = {
        "generator_version": source.version,
        "env": cfg.env.name,
        "seed": cfg.data.seed,
        "noise": cfg.data.noise,
        "episode_steps": cfg.data.episode_steps,
        "episodes": counts,
        "sha256": sha,
        "obs_mean": normaliser[0],
        "obs_std": normaliser[1],
        **source.manifest_fields(),
    }
    (tmp / "manifest.json").write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")
    os.replace(tmp, out)
    manifest["_generation_s"] = time.time() - t0
    return out, manifest


def regenerate_fix(path: Path, cfg: Config | None) -> str:
    """The command that replaces a broken dataset dir with the one cfg names (deterministic: same bytes)."""
    if cfg is None:
        return f"delete {path} and regenerate it with jobs/make_dataset.py"
    from fmctd_dist.hints import dataset_command, shown

    fix = f"regenerate it with `rm -r {shlex.quote(shown(path))} && {dataset_command(cfg)}`"
    if Path(path).resolve() != dataset_dir(cfg).resolve():
        fix += f" (that writes {dataset_dir(cfg)}; point the loader there)"
    return fix


def _int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _manifest_type_error(m: dict[str, Any]) -> str:
    """'' if the fields loaders index into have their JSON types, else what is wrong with the first bad one."""
    splits = ("train", "val")
    checks = [
        ("episode_steps", _int(m["episode_steps"]) and m["episode_steps"] > 1, "an integer > 1"),
        ("episodes", isinstance(m["episodes"], dict) and all(_int(m["episodes"].get(k)) and m["episodes"][k] > 0
                                                              for k in splits),
         "an object {train: int, val: int} of positive counts"),
        ("sha256", isinstance(m["sha256"], dict) and all(isinstance(m["sha256"].get(k), str) for k in splits),
         "an object {train: hex, val: hex}"),
        ("obs_mean", isinstance(m["obs_mean"], list) and len(m["obs_mean"]) > 0
         and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in m["obs_mean"]), "a list of numbers"),
        ("obs_std", isinstance(m["obs_std"], list) and len(m["obs_std"]) > 0
         and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in m["obs_std"]), "a list of numbers"),
    ]
    if "obs_dim" in m:
        checks.append(("obs_dim", _int(m["obs_dim"]) and m["obs_dim"] >= 2, "an integer >= 2"))
    for key, ok, want in checks:
        if not ok:
            return f"{key} is {json.dumps(m[key])[:60]} but must be {want}"
    return ""


def _create_fix(path: Path, cfg: Config | None) -> str:
    """The command that makes the dataset a loader found missing at ``path``."""
    if cfg is None:
        return "create it with `python jobs/make_dataset.py env=<env> data.root=<root>`"
    from fmctd_dist.hints import dataset_command

    fix = f"create it with `{dataset_command(cfg)}`"
    if path.resolve() != dataset_dir(cfg).resolve():
        fix += f" (that writes {dataset_dir(cfg)}; point the loader there)"
    return fix


def load_manifest(path: Path, cfg: Config | None = None, verify: bool = True) -> dict[str, Any]:
    """Read and check a manifest (fields, config agreement, file sha256)."""
    mf = path / "manifest.json"
    manifest = read_manifest_json(path, _create_fix(path, cfg), regenerate_fix(path, cfg))
    if cfg is not None and isinstance(manifest, dict) and manifest.get("env") != cfg.env.name:  # before any field
        raise DatasetError(f"{path} holds data of env={manifest.get('env')!r}, but the config asks for "
                           f"env.name={cfg.env.name}; point the loader at a {cfg.env.name} dataset")
    for key in MANIFEST_FIELDS:
        if key not in manifest:
            raise DatasetError(f"{mf} lacks the field {key!r}; {regenerate_fix(path, cfg)}")
    bad = _manifest_type_error(manifest)
    if bad:
        raise DatasetError(f"{mf} is malformed: {bad}; {regenerate_fix(path, cfg)}")
    version = generator_version(str(manifest["env"]))
    if manifest["generator_version"] != version:
        raise DatasetError(
            f"{mf}: generator_version={manifest['generator_version']} but this code writes {version}; "
            f"{regenerate_fix(path, cfg)}"
        )
    if cfg is not None:
        expect = {"env": cfg.env.name, "seed": cfg.data.seed, "noise": cfg.data.noise,
                  "episode_steps": cfg.data.episode_steps}
        for key, want in expect.items():
            if manifest[key] != want:
                raise DatasetError(f"{mf}: {key}={manifest[key]!r} but the config asks for {want!r}; "
                                   f"{regenerate_fix(path, cfg)}, or fix data.{key if key != 'env' else 'env.name'}")
        if is_ant(cfg.env.name):
            check_expert_matches(manifest, cfg, path)
    if verify:
        verify_splits(path, manifest["sha256"], regenerate_fix(path, cfg))
    return manifest


class NavigateDataset(SplitStates):
    """x, y observations [E, S, 2] per split (what the planner models) plus the manifest (digest, normaliser)."""

    def position_readout(self, cfg: Config) -> tuple[Any, dict[str, Any]]:
        """A frame is its normalised (x, y): the readout is the frame itself (train.boundary_space=position
        then equals token, and train.position_weight weighs the token loss's end frames again)."""
        return _frame_xy, {"readout": "the frames' normalised x, y"}

    def wall_depth(self, cfg: Config) -> tuple[Any, dict[str, Any]]:
        """Frames -> their depth inside this maze's walls (train.wall_weight; ``maze/wall_loss.py``)."""
        from fmctd_dist.families.maze.wall_loss import GRID_STEP, wall_depth

        norm = self.normaliser
        return (wall_depth(cfg.env.name, norm.mean.tolist(), norm.std.tolist()),
                {"maze": cfg.env.name, "grid_step": GRID_STEP})


def _frame_xy(frames):
    """Normalised frames [..., 2] -> the same positions (torch or numpy)."""
    return frames[..., :2]


def load_dataset(cfg: Config, path: Path | None = None) -> NavigateDataset:
    require_family(cfg.env.name, MAZE_KINDS, "the navigate-data code (families/maze/data.py, used by jobs/train.py)")
    path = path or dataset_dir(cfg)
    manifest = load_manifest(path, cfg, verify=True)
    splits = load_split_states(path, manifest, slice(None, 2), regenerate_fix(path, cfg))  # ant: x, y of its state
    return NavigateDataset(path, manifest, splits["train"], splits["val"])


def describe(manifest: dict[str, Any]) -> list[str]:
    """What ``jobs/make_dataset.py`` prints about a navigate dataset: digests, normalisation, the ant data's stats."""
    lines = split_lines(manifest)
    lines.append(f"  x, y mean {manifest['obs_mean']}  std {manifest['obs_std']}")
    if "expert" in manifest:
        expert = manifest["expert"]
        lines.append(f"  expert {expert['path']} (digest {expert['digest']}), noise {manifest['noise']}")
        for split, s in manifest["stats"].items():
            lines.append(f"  {split}: {s['goals_per_1000_steps']} goals / 1000 steps, "
                         f"unhealthy {s['unhealthy_fraction']:.2%}, upside down {s['upside_down_fraction']:.2%}, "
                         f"{s['episodes_fallen']} episodes fell, {s['mean_speed_m_per_s']} m/s")
        g = manifest["generation"]
        lines.append(f"  generation {g['wall_s']}s, {g['env_steps_per_s']} env steps/s")
    return lines


make, load = make_dataset, load_dataset  # the family's data protocol (fmctd_dist.registry.Family.data)
