"""Walk a run's recorded first plans again, with the controller of another ``env.wall_clearance``.

    python jobs/probes/rewalk.py results/wall-s42/fast-mctd/antmaze-large
    python jobs/probes/rewalk.py results/wall-s42/fast-mctd/antmaze-large 'clearances=[0,1,1.5,2]'
    python jobs/probes/rewalk.py results/wall-s43-w1c2/fast-mctd/antmaze-giant --episodes

An open-loop maze episode (one plan, walked to the end: Fast-MCTD, MCTD, P-MCTD, S-MCTD, Diffuser,
Diffusion Forcing) is a pure function of (first plan, task, seed): the row's ``plan_xy`` handed to the row's
controller, stepped from ``env.reset(task, seed)`` for ``env.max_steps``, gives the row's outcome again. So
the controller can be changed without planning again. Per clearance this prints how many ants (or points)
reached the goal, how many outcomes agree with the rows (all of them at the rows' own clearance: the check
that the walk is the episode), and, on AntMaze, how many failed walks ended with the ant on its back
(``antmaze.upright``; the rows do not record it, and ``why_failed`` reads a fallen ant as one that stood
still). ``--episodes`` adds a line per failed walk. Every other field (the policy, ``env.max_steps``) is the
rows' recorded config (:func:`identity.recorded_config`). Writes nothing.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from fmctd_dist.cli import run
from fmctd_dist.config import Config, is_ant
from fmctd_dist.config.checks import validate
from fmctd_dist.errors import ConfigError, ResultsError
from fmctd_dist.evaluation.identity import config_hash, recorded_config
from fmctd_dist.evaluation.results import ResultStore
from fmctd_dist.families.maze.antmaze import upright
from fmctd_dist.families.maze.episode import stood_still
from fmctd_dist.families.maze.make import make_env
from fmctd_dist.families.maze.robots import controller_factory
from fmctd_dist.registry import require_family


def read_rows(directory: Path) -> list[dict[str, Any]]:
    """The rows of one ``<run>/<method>/<env>`` directory, in (task, seed) order; one plan each, one config."""
    rows = sorted(ResultStore.directory_rows(directory), key=lambda r: (r["task"], r["seed"]))
    if not rows:
        raise ConfigError(f"{directory}: no result rows (give a results/<run>/<method>/<env> directory)")
    replanned = [r for r in rows if int(r.get("plans") or 1) > 1]
    if replanned:
        raise ConfigError(f"{directory}: {len(replanned)} rows replanned (plans > 1); only open-loop episodes, "
                          "one plan each, can be walked again from their first plan")
    hashes = {r.get("config_hash") for r in rows}
    if len(hashes) > 1:
        raise ConfigError(f"{directory}: rows of {len(hashes)} configs ({sorted(map(str, hashes))}); "
                          "give one run's directory")
    return rows


def row_config(row: dict[str, Any], clearance: float | None = None) -> Config:
    """The config the row was made with (its controller: the policy, ``env.max_steps``, the clearance), or the
    same at another clearance."""
    cfg = recorded_config(row)
    if config_hash(cfg) != row.get("config_hash"):
        raise ResultsError(f"{row['method']} {row['env']}: its recorded config does not rebuild to its config hash "
                           f"({config_hash(cfg)} against {row.get('config_hash')}): a default changed meaning since")
    if clearance is None:
        return cfg
    cfg = dataclasses.replace(cfg, env=dataclasses.replace(cfg.env, wall_clearance=float(clearance)))
    validate(cfg)  # the schema's range for env.wall_clearance: one error naming it, before any walk
    return cfg


def walk(env: Any, controller: Any, row: dict[str, Any], max_steps: int) -> tuple[bool, int, np.ndarray, bool]:
    """Step the row's episode with ``controller``: (reached, steps, trajectory [T, 2], ended upright)."""
    obs = env.reset(row["task"], row["seed"]).obs
    traj, reached, steps = [obs[:2]], False, 0
    while steps < max_steps and not reached:
        obs, reached = env.step(controller.act(obs))
        traj.append(obs[:2])
        steps += 1
    return reached, steps, np.asarray(traj), bool(upright(obs)) if is_ant(row["env"]) else True


def main(argv: list[str]) -> int:
    dirs = [Path(a) for a in argv if not a.startswith("clearances=") and not a.startswith("--")]
    clearances = [a.split("=", 1)[1] for a in argv if a.startswith("clearances=")]
    flags = [a for a in argv if a.startswith("--") and a != "--episodes"]
    if flags:
        raise ConfigError(f"unknown flag {flags[0]}; rewalk.py takes a directory, clearances=[...] and --episodes")
    if len(dirs) != 1:
        raise ConfigError(f"give one results/<run>/<method>/<env> directory, got {[str(d) for d in dirs]}")
    rows = read_rows(dirs[0])
    name = rows[0]["env"]
    require_family(name, ("pointmaze", "antmaze"), "jobs/probes/rewalk.py")
    base = row_config(rows[0])
    try:
        values = ([float(c) for c in clearances[0].strip("[]").split(",") if c.strip()] if clearances
                  else [base.env.wall_clearance])
    except ValueError:
        raise ConfigError(f"clearances={clearances[0]}: give numbers, e.g. clearances=[0,1.5,2]") from None
    configs = [row_config(rows[0], c) for c in values]  # every clearance checked before the first walk
    env = make_env(name)
    print(f"{dirs[0]}: {len(rows)} rows ({sum(r['success'] for r in rows)} reached the goal), "
          f"recorded at clearance {base.env.wall_clearance}")
    for clearance, cfg in zip(values, configs):
        make = controller_factory(cfg)
        reached = agree = fallen = 0
        lines = []
        for row in rows:
            ok, steps, traj, up = walk(env, make(np.asarray(row["plan_xy"]).reshape(-1, 2)), row, cfg.env.max_steps)
            reached, agree = reached + ok, agree + (ok == bool(row["success"]))
            fallen += not ok and not up
            if not ok:
                how = "on its back" if not up else "stood still" if stood_still(traj) else "still moving"
                lines.append(f"    task {row['task']} seed {row['seed']}: failed after {steps} steps, {how} "
                             f"(row: {'success' if row['success'] else 'failed'})")
        print(f"  clearance {clearance}: {reached} of {len(rows)} reached the goal, {agree} agree with the rows"
              + (f", {fallen} of {len(rows) - reached} failures on its back" if is_ant(name) else ""), flush=True)
        if "--episodes" in argv:
            print("\n".join(lines))
    return 0


if __name__ == "__main__":
    run(main)
