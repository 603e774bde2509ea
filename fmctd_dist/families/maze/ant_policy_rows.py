"""Rows of an AntMaze navigate dataset for the goal-conditioned policy, and their hindsight subgoals.

A row t is (29-D ant state before step t, the noisy expert torque applied at t). Its
subgoal is where the ant actually was ``k`` steps later: whatever the data's goal was, the
torque at t moved the ant towards x, y(t + k), so regressing it onto (state, that point) is
a goal-conditioned behaviour clone with hindsight relabelling.

``k`` is the sum of ``draws`` Geometric(p) draws (each >= 1; mean draws / p;
:mod:`fmctd_dist.control.policy.hindsight`, shared with the cube). The authors'
low-level policy used "a geometric window p=0.2 x 10 steps" (docs/reference.md §7); we keep p=0.2
and take two draws: mean 10 steps (~1.1 m at the data's 1.25 m/s, the controller's
subgoal interval), mode 5-6, 90% within 2..19 steps. One draw (mean 5) puts 20% of the
mass on k=1, a subgoal 0.13 m away whose direction is mostly noise; the controller asks for
points 1-2.5 m away. Two draws keep short offsets (needed to stop on the final goal) and
cover the 10-20 steps the controller uses.

Offsets are cut at the end of the row's *run*: the episode's last row, or the last row
before the ant falls (``drop_fallen``: rows where it is down are not trained on, and no
subgoal is taken from them). A row with no future in its run (an episode's last row) is
never sampled.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fmctd_dist.config import Config
from fmctd_dist.families.maze.ant_policy import policy_input
from fmctd_dist.families.maze.data import dataset_dir, load_manifest, regenerate_fix
from fmctd_dist.data.npz import load_npz
from fmctd_dist.families.maze.antmaze import ACT_DIM, OBS_DIM, healthy, upright
from fmctd_dist.errors import DatasetError


@dataclass
class PolicyRows:
    """One split, episodes flattened to rows; ``end[i] >= i`` is the last row of i's run."""

    obs: np.ndarray  # [N, 29] float32, state before the step
    actions: np.ndarray  # [N, 8] float32, torque applied
    goals: np.ndarray  # [N, 2] float32, the data's goal (only for the expert's noise floor)
    end: np.ndarray  # [N] int64
    valid: np.ndarray  # [M] int64, rows that may be sampled: in a run (upright) and end > i
    stats: dict[str, int]

    @property
    def xy(self) -> np.ndarray:
        return self.obs[:, :2]

    def inputs(self, i: np.ndarray, j: np.ndarray, max_dist: float) -> np.ndarray:
        """Network inputs [B, 29] of rows i with the ant's x, y at rows j as subgoal."""
        return policy_input(self.obs[i], self.obs[j, :2], max_dist)


def run_ends(ok: np.ndarray) -> np.ndarray:
    """ok [E, S] bool -> [E*S] flat index of the last row of each row's run of ok rows (in its episode).

    For rows that are not ok the value is meaningless (they are never sampled).
    """
    e, s = ok.shape
    last = np.zeros_like(ok)
    last[:, :-1] = ok[:, :-1] & ~ok[:, 1:]
    last[:, -1] = ok[:, -1]
    idx = np.arange(e * s, dtype=np.int64)
    cand = np.where(last.reshape(-1) | ~ok.reshape(-1), idx, np.iinfo(np.int64).max)
    return np.minimum.accumulate(cand[::-1])[::-1]


def make_rows(obs: np.ndarray, actions: np.ndarray, goals: np.ndarray, drop_fallen: bool) -> PolicyRows:
    """[E, S, 29], [E, S, 8], [E, S, 2] -> PolicyRows (see module doc for runs and ``drop_fallen``)."""
    if obs.ndim != 3 or obs.shape[-1] != OBS_DIM or actions.shape != obs.shape[:2] + (ACT_DIM,):
        raise DatasetError(f"ant policy rows need observations [E, S, {OBS_DIM}] and actions [E, S, {ACT_DIM}], got "
                           f"{obs.shape} and {actions.shape}; regenerate with jobs/make_dataset.py env=antmaze-*")
    up = healthy(obs) & upright(obs)
    ok = up if drop_fallen else np.ones_like(up)
    end = run_ends(ok)
    flat_ok = ok.reshape(-1)
    idx = np.arange(flat_ok.size, dtype=np.int64)
    valid = idx[flat_ok & (end > idx)]
    stats = {"rows": int(flat_ok.size), "fallen_rows": int((~up).sum()),
             "episodes_with_falls": int((~up).any(axis=1).sum()), "trained_rows": int(valid.size)}
    return PolicyRows(np.ascontiguousarray(obs.reshape(-1, OBS_DIM), np.float32),
                      np.ascontiguousarray(actions.reshape(-1, ACT_DIM), np.float32),
                      np.ascontiguousarray(goals.reshape(-1, 2), np.float32), end, valid, stats)


def load_policy_data(cfg: Config, drop_fallen: bool,
                     path: Path | None = None) -> tuple[PolicyRows, PolicyRows, dict[str, Any]]:
    """Train and val rows of the dataset ``cfg`` names (manifest, expert and sha256 verified) + the manifest."""
    path = path or dataset_dir(cfg)
    manifest = load_manifest(path, cfg, verify=True)
    if manifest.get("obs_dim") != OBS_DIM:
        raise DatasetError(f"{path} holds {manifest.get('obs_dim', 2)}-D observations; the ant policy needs the "
                           f"{OBS_DIM}-D ant state (an antmaze-* dataset from jobs/make_dataset.py)")
    out = []
    for split in ("train", "val"):
        e, s = manifest["episodes"][split], manifest["episode_steps"]
        arrays = load_npz(path / f"{split}.npz", {"observations": (np.float32, (e, s, OBS_DIM)),
                                                  "actions": (np.float32, (e, s, ACT_DIM)),
                                                  "goals": (np.float32, (e, s, 2))},
                          f"it does not match {path / 'manifest.json'}; {regenerate_fix(path, cfg)}")
        rows = make_rows(arrays["observations"], arrays["actions"], arrays["goals"], drop_fallen)
        if rows.valid.size == 0:
            raise DatasetError(f"{path / f'{split}.npz'} has no row to train on (every ant fell, or episodes of one "
                               "step); regenerate with more data.episodes / data.episode_steps")
        out.append(rows)
    return out[0], out[1], manifest
