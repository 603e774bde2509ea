"""Cube play datasets (OGBench ``cube-{single,double,triple}-play-v0``), regenerated offline.

OGBench's ``data_gen_scripts/generate_manipspace.py`` is not in the pip package; this is its
play loop rebuilt from docs/reference.md §13 with the package's own ``CubeEnv`` and ``CubePlanOracle``:
- ``CubeEnv(mode='data_collection', terminate_at_goal=False)``: each reset puts the arm at a
  random pose, every cube at a random table spot with a random yaw, and picks a first target
  (``set_new_target`` with its default p_stack 0.5, as in OGBench);
- ``CubePlanOracle(segment_dt=0.4, noise=data.noise (0.1), noise_smoothing=0.5)``: keyframes
  pick -> clearance -> place -> a random arm pose, linearly interpolated plus smoothed noise;
- after each step, once the oracle's plan has run out: ``set_new_target(p_stack)`` (a random
  free top cube to a random table spot, or onto another cube with probability p_stack) and a new
  plan; p_stack is drawn per episode: 0 single, U(0, 0.25) double, U(0.05, 0.35) triple;
- ``data.episode_steps`` (OGBench 1001) steps per episode, no early end; actions clipped to [-1, 1].

Seeding: episode ``ep`` of split ``s`` draws from ``SeedSequence([data.seed, s, ep])`` only:
its first word seeds ``env.np_random`` (arm pose, cube spots, targets), its second numpy's
global RNG, which OGBench's oracle and p_stack draw from; the global state is set for the
episode and restored after. Any episode can be regenerated alone, and a smaller
``data.episodes`` is a prefix of a larger one (same seed, same episodes).

Layout: ``<data.root>/<env>-play-seed<seed>-<E>x<S>/{train,val}.npz, manifest.json``; arrays
per episode, [E, S, ...]: ``observations`` (OGBench's 19+9N state obs before each action),
``actions`` [5], ``qpos``/``qvel`` (MuJoCo state at that obs), ``terminals``, and two arrays
OGBench's files lack: ``target_block`` (the oracle's current cube) and ``target_pos`` (its
target xyz, obs units). The planner reads only the cubes' xyz columns (:func:`load_cube_dataset`);
windows are drawn lazily from them (``data/windows.py``), never materialised.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import time
import zipfile
from pathlib import Path
from typing import Any, Iterator

import numpy as np
from tqdm.auto import tqdm

from fmctd_dist.config import Config, resolve_path
from fmctd_dist.data.manifest_io import read_manifest_json, split_lines
from fmctd_dist.data.npz import save_npz
from fmctd_dist.data.splits import SPLITS, SplitStates, load_split_states, verify_splits, write_splits
from fmctd_dist.families.cube.env import ACT_DIM, cube_columns, make_cube_env, n_cubes, obs_dim, to_obs_units
from fmctd_dist.errors import DatasetError
from fmctd_dist.registry import env_names, family, require_family

CUBE_GENERATOR_VERSION = 1
SEGMENT_DT = 0.4  # CubePlanOracle: seconds between keyframes (OGBench play)
NOISE_SMOOTHING = 0.5  # CubePlanOracle: Gaussian smoothing sigma of the plan noise, in steps
P_STACK = {"single": (0.0, 0.0), "double": (0.0, 0.25), "triple": (0.05, 0.35)}  # per-episode U(lo, hi)
OGBENCH_EPISODES = {"single": 1000, "double": 1000, "triple": 3000}  # cube-*-play-v0 training episodes
MANIFEST_FIELDS = ("generator_version", "env", "seed", "noise", "episode_steps", "episodes", "sha256",
                   "state_mean", "state_std", "state_dim", "obs_dim")


def cube_type(name: str) -> str:
    return require_family(name, ("cube",), "the cube play data").split("-", 1)[1]


def dataset_dir(cfg: Config) -> Path:
    d = cfg.data
    return resolve_path(d.root) / f"{cfg.env.name}-play-seed{d.seed}-{d.episodes}x{d.episode_steps}"


def parts_dir(cfg: Config) -> Path:
    """Where finished episodes wait until the dataset is written: keyed by everything but the episode count,
    so an interrupted run resumes, and a run of another size reuses the episodes it shares (a prefix)."""
    d = cfg.data
    return resolve_path(d.root) / f"{cfg.env.name}-play-seed{d.seed}-x{d.episode_steps}.parts"


def episode_seeds(seed: int, split: str, ep: int) -> tuple[int, int]:
    """(env seed, oracle seed) of one episode: its own stream, independent of every other episode."""
    env_seed, oracle_seed = np.random.SeedSequence([seed, SPLITS[split], ep]).generate_state(2)
    return int(env_seed), int(oracle_seed)


@contextlib.contextmanager
def global_numpy_seed(seed: int) -> Iterator[None]:
    """Seed numpy's global RNG (OGBench's oracle draws from it) for a block, then restore the caller's state."""
    saved = np.random.get_state()
    np.random.seed(seed)
    try:
        yield
    finally:
        np.random.set_state(saved)


def generate_episode(env, steps: int, noise: float, seeds: tuple[int, int]) -> tuple[dict[str, np.ndarray], dict]:
    """One play episode of ``steps`` steps (OGBench's loop, seeded); returns arrays [S, ...] and counters."""
    from ogbench.manipspace.oracles.plan.cube_plan import CubePlanOracle

    env_seed, oracle_seed = seeds
    lo, hi = P_STACK[env._env_type]
    with global_numpy_seed(oracle_seed):
        ob, info = env.reset(seed=env_seed)
        obs = np.empty((steps, len(ob)), np.float32)
        act = np.empty((steps, ACT_DIM), np.float32)
        qpos = np.empty((steps, env._model.nq), np.float32)
        qvel = np.empty((steps, env._model.nv), np.float32)
        target_block = np.empty(steps, np.int8)
        target_pos = np.empty((steps, 3), np.float32)
        p_stack = np.random.uniform(lo, hi) if hi > 0 else 0.0
        agent = CubePlanOracle(env=env, segment_dt=SEGMENT_DT, noise=noise, noise_smoothing=NOISE_SMOOTHING)
        agent.reset(ob, info)
        targets = placed = stacked = 0
        for t in range(steps):
            target_block[t] = env._target_block
            target_pos[t] = to_obs_units(env._data.mocap_pos[env._cube_target_mocap_ids[env._target_block]])
            action = np.clip(np.asarray(agent.select_action(ob, info)), -1.0, 1.0)
            next_ob, _, _, _, info = env.step(action)
            obs[t], act[t], qpos[t], qvel[t] = ob, action, info["prev_qpos"], info["prev_qvel"]
            if agent.done:
                targets += 1
                placed += bool(info["success"])
                agent_ob, agent_info = env.set_new_target(p_stack=p_stack)
                stacked += bool(agent_info["privileged/target_block_pos"][2] > 0.03)
                agent.reset(agent_ob, agent_info)
            ob = next_ob
    terminals = np.zeros(steps, dtype=bool)
    terminals[-1] = True
    arrays = {"observations": obs, "actions": act, "qpos": qpos, "qvel": qvel, "terminals": terminals,
              "target_block": target_block, "target_pos": target_pos}
    return arrays, {"targets": targets, "placed": placed, "stacked": stacked, "p_stack": float(p_stack)}


STATS = ("targets", "placed", "stacked")  # per-episode counters, kept in each episode's part file


def _read_part(part: Path) -> dict[str, np.ndarray] | None:
    """A finished episode's arrays, or None when it is not there or unreadable (it is then made again)."""
    if not part.is_file():
        return None
    try:
        with np.load(part, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except (ValueError, OSError, EOFError, zipfile.BadZipFile):
        return None


def generate_split(cfg: Config, split: str, episodes: int, parts: Path,
                   progress: bool = True) -> tuple[dict[str, np.ndarray], dict]:
    """Episodes 0..episodes-1 of ``split``, stacked to [E, S, ...]; plus quality counters.

    Each episode is written to ``parts/<split>-<ep>.npz`` as soon as it is made, and an episode
    whose part file is already there is read back instead of generated, so an interrupted run
    continues where it stopped when rerun with the same command (same bytes either way).
    """
    env = None
    out: dict[str, list[np.ndarray]] = {}
    counts = dict.fromkeys(STATS, 0)
    t0, made = time.time(), 0
    bar = tqdm(range(episodes), desc=f"{cfg.env.name} {split}", unit="ep", disable=not progress, mininterval=10)
    for ep in bar:
        part = parts / f"{split}-{ep:05d}.npz"
        arrays = _read_part(part)
        if arrays is None:
            env = env or make_cube_env(cfg.env.name, mode="data_collection")
            arrays, c = generate_episode(env, cfg.data.episode_steps, cfg.data.noise,
                                         episode_seeds(cfg.data.seed, split, ep))
            arrays.update({f"stat_{k}": np.asarray([c[k]], np.int64) for k in STATS})  # [1]
            save_npz(part.with_suffix(".tmp"), arrays)
            os.replace(part.with_suffix(".tmp"), part)
            made += 1
            bar.set_postfix(steps_per_s=f"{made * cfg.data.episode_steps / (time.time() - t0):.0f}", refresh=False)
        for k, v in arrays.items():
            if k.startswith("stat_"):
                counts[k[5:]] += int(v.reshape(-1)[0])
            else:
                out.setdefault(k, []).append(v)
    if env is not None:
        env.close()
    wall = time.time() - t0
    steps = episodes * cfg.data.episode_steps
    stats = {"targets_per_1000_steps": round(1000 * counts["targets"] / steps, 2),
             "placed_fraction": round(counts["placed"] / max(counts["targets"], 1), 4),
             "stacked_target_fraction": round(counts["stacked"] / max(counts["targets"], 1), 4),
             "episodes_generated_in_last_run": made,
             "wall_s_last_run": round(wall, 1),
             "env_steps_per_s": round(made * cfg.data.episode_steps / wall, 1) if made else None}
    return {k: np.stack(v) for k, v in out.items()}, stats


def make_cube_dataset(cfg: Config, progress: bool = True) -> tuple[Path, dict[str, Any]]:
    """Generate (or verify an existing) cube play dataset; return its dir and manifest."""
    kind = cube_type(cfg.env.name)
    out = dataset_dir(cfg)
    if (out / "manifest.json").exists():
        return out, load_cube_manifest(out, cfg, verify=True)
    if out.exists() and any(out.iterdir()):
        raise DatasetError(f"{out} exists but has no manifest.json; delete the directory and rerun")
    parts = parts_dir(cfg)  # one file per finished episode, shared by runs of any size, removed at the end
    params = {"generator_version": CUBE_GENERATOR_VERSION, "env": cfg.env.name, "seed": cfg.data.seed,
              "noise": cfg.data.noise, "episode_steps": cfg.data.episode_steps}
    if not (parts / "params.json").is_file() or json.loads((parts / "params.json").read_text()) != params:
        shutil.rmtree(parts, ignore_errors=True)  # parts of other settings (or none): start over
        parts.mkdir(parents=True)
        (parts / "params.json").write_text(json.dumps(params, sort_keys=True) + "\n")
    tmp = out.with_name(out.name + ".tmp")
    t0 = time.time()
    stats: dict[str, dict] = {}
    cols = cube_columns(n_cubes(cfg.env.name))

    def generate(split: str, n: int) -> dict[str, np.ndarray]:
        arrays, stats[split] = generate_split(cfg, split, n, parts, progress)
        return arrays

    splits, sha, (mean, std) = write_splits(tmp, cfg, generate, cols)
    ogbench = OGBENCH_EPISODES[kind]
    manifest = {
        **params,  # what the parts were made with
        "episodes": splits,
        "ogbench_episodes": {"train": ogbench, "val": ogbench // 10},
        "fraction_of_ogbench": round(cfg.data.episodes / ogbench, 4),
        "sha256": sha,
        "state_mean": mean,
        "state_std": std,
        "state_dim": len(cols),
        "state_columns": cols.tolist(),
        "obs_dim": obs_dim(cfg.env.name),
        "oracle": {"class": "ogbench.manipspace.oracles.plan.cube_plan.CubePlanOracle", "segment_dt": SEGMENT_DT,
                   "noise": cfg.data.noise, "noise_smoothing": NOISE_SMOOTHING,
                   "p_stack_per_episode": list(P_STACK[kind]), "env_mode": "data_collection"},
        "keys": ["observations", "actions", "qpos", "qvel", "terminals", "target_block", "target_pos"],
        "stats": stats,
        "generation": {"wall_s_last_run": round(time.time() - t0, 1),
                       "episodes_generated_in_last_run": sum(s["episodes_generated_in_last_run"]
                                                             for s in stats.values())},
    }
    (tmp / "manifest.json").write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")
    os.replace(tmp, out)
    shutil.rmtree(parts)
    manifest["_generation_s"] = time.time() - t0
    return out, manifest


def load_cube_manifest(path: Path, cfg: Config | None = None, verify: bool = True) -> dict[str, Any]:
    """Read and check a cube manifest: env first (another env's data is one clear error), fields, config, sha256."""
    mf = path / "manifest.json"
    env = cfg.env.name if cfg is not None else "cube-single"
    manifest = read_manifest_json(path, f"create it with `python jobs/make_dataset.py env={env}`",
                                  f"delete {path} and regenerate")
    env = manifest.get("env")
    if cfg is not None and env != cfg.env.name:
        what = f"a {family(env)} dataset (env={env})" if isinstance(env, str) and env in env_names() \
            else f"a dataset of env={env!r}"
        raise DatasetError(f"{path} is {what}, but the config asks for env.name={cfg.env.name}; point the loader "
                           f"at a {cfg.env.name} dataset (python jobs/make_dataset.py env={cfg.env.name})")
    for key in MANIFEST_FIELDS:
        if key not in manifest:
            raise DatasetError(f"{mf} lacks the field {key!r}: not a cube play dataset of this code; "
                               f"delete {path} and regenerate it")
    if manifest["generator_version"] != CUBE_GENERATOR_VERSION:
        raise DatasetError(f"{mf}: generator_version={manifest['generator_version']} but this code writes "
                           f"{CUBE_GENERATOR_VERSION}; delete {path} and regenerate")
    if cfg is not None:
        expect = {"seed": cfg.data.seed, "noise": cfg.data.noise, "episode_steps": cfg.data.episode_steps,
                  "state_dim": 3 * n_cubes(cfg.env.name)}
        for key, want in expect.items():
            if manifest[key] != want:
                raise DatasetError(f"{mf}: {key}={manifest[key]!r} but the config asks for {want!r}; "
                                   f"regenerate or fix data.{key}")
    if verify:
        verify_splits(path, manifest["sha256"], f"delete {path} and regenerate")
    return manifest


class CubeDataset(SplitStates):
    """Cube xyz in obs units [E, S, 3N] per split (the planner state) plus the manifest (digest, normaliser)."""

    MOMENTS = ("state_mean", "state_std")


def load_cube_dataset(cfg: Config, path: Path | None = None) -> CubeDataset:
    """The cube xyz columns of a checked play dataset (the other arrays stay on disk)."""
    path = path or dataset_dir(cfg)
    cube_type(cfg.env.name)
    manifest = load_cube_manifest(path, cfg, verify=True)
    splits = load_split_states(path, manifest, cube_columns(n_cubes(cfg.env.name)), f"delete {path} and regenerate")
    return CubeDataset(path, manifest, splits["train"], splits["val"])


__all__ = ["make_cube_dataset", "load_cube_dataset", "load_cube_manifest", "CubeDataset"]


def describe(manifest: dict[str, Any]) -> list[str]:
    """What ``jobs/make_dataset.py`` prints about a cube play dataset."""
    lines = split_lines(manifest)
    lines.append(f"  {manifest['fraction_of_ogbench']:.0%} of OGBench's {manifest['ogbench_episodes']['train']} "
                 f"episodes; cube xyz mean {[round(x, 3) for x in manifest['state_mean']]}  "
                 f"std {[round(x, 3) for x in manifest['state_std']]}")
    for split, s in manifest["stats"].items():
        lines.append(f"  {split}: {s['targets_per_1000_steps']} targets / 1000 steps, placed "
                     f"{s['placed_fraction']:.1%}, stacking targets {s['stacked_target_fraction']:.1%}, "
                     f"{s['env_steps_per_s']} env steps/s ({s['episodes_generated_in_last_run']} episodes "
                     "generated by the last run)")
    lines.append(f"  last run {manifest['generation']['wall_s_last_run']}s")
    return lines


make, load = make_cube_dataset, load_cube_dataset  # the family's data protocol (fmctd_dist.registry.Family.data)
