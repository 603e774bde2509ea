"""Reach rate of the cube policy: from a held-out state, can it take the cube where the data took it?

This is the low-level half of cube planning in isolation, with the data's own cube path as
the "plan". For N val rows (seeded) in the middle of a pick-and-place that the data's oracle
completed (the target cube ends within ``radius`` of the oracle's target), with the cube still
more than ``radius`` from where the pick-and-place left it:

- the MuJoCo state (qpos, qvel) of the row is restored, with the env's target for that cube
  set to the plan's end (so OGBench's oracle can be asked to go there too);
- the *plan* is the target cube's recorded xyz from the row to the end of its pick-and-place;
  the policy gets the plan point ``offset`` (10) steps ahead as subgoal, moved on by
  ``offset`` each time the cube comes within ``advance`` of it (:class:`SubgoalTracker`, the
  authors' cube controller: 10 steps, 1.0 obs units);
- reached = the cube within ``radius`` (0.4 obs units = OGBench's 0.04 m) of the plan's end
  after some step, within ``max_steps`` env steps.

References on the same tries: OGBench's ``CubePlanOracle`` (the data's own settings, noise 0.1,
seeded), re-planned from the restored state to the plan's end (it sees that target, not the
plan; its keyframes start with an open gripper, so a carried cube is dropped and picked again;
it needs ~90 steps for a whole pick-and-place), and zero actions (the arm holds still: the
floor). Rates are also given apart for tries that start with the cube on the table (grasp,
carry, place) and in the air (carry, place). Deterministic given the seed.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from fmctd_dist.families.cube.policy import cube_view
from fmctd_dist.families.cube.policy_rows import CubeRows
from fmctd_dist.families.maze.subgoal import SubgoalTracker
from fmctd_dist.families.cube.data import NOISE_SMOOTHING, SEGMENT_DT, global_numpy_seed
from fmctd_dist.device import torch_threads
from fmctd_dist.families.cube.env import ACT_DIM, XYZ_CENTER, XYZ_SCALE, cube_xyz, make_cube_env, n_cubes

Controller = Callable[[np.ndarray, np.ndarray], np.ndarray]  # (view [28], subgoal [3]) -> action [5]
ROW_STREAM = 7  # SeedSequence([reach.seed, ROW_STREAM]) picks the rows
ON_TABLE_Z = 0.25  # obs units: a cube resting on the table has z = 0.2; above this it is lifted (or stacked)


def reach_rows(rows: CubeRows, n: int, radius: float, seed: int) -> np.ndarray:
    """Up to n val rows (without replacement, sorted): inside a completed pick-and-place, cube still to move."""
    idx = np.arange(len(rows.target), dtype=np.int64)
    c = rows.target
    here = rows.xyz[idx, c]
    there = rows.xyz[rows.end, c]
    placed = np.linalg.norm(there - rows.target_pos, axis=-1) <= radius  # the data's oracle completed it
    ok = placed & (rows.end > idx) & (np.linalg.norm(there - here, axis=-1) > radius)
    if not ok.any():
        raise ValueError("no val row has a cube left to move in a completed pick-and-place; use more val data")
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, ROW_STREAM])))
    return np.sort(rng.choice(idx[ok], size=min(n, int(ok.sum())), replace=False))


def zero_controller(view: np.ndarray, subgoal: np.ndarray) -> np.ndarray:
    """No motion (the gripper keeps its opening): how often a cube is already where it must go."""
    return np.zeros(ACT_DIM)


def restore(env, rows: CubeRows, i: int, cube: int, goal: np.ndarray, goal_quat: np.ndarray) -> tuple[np.ndarray, dict]:
    """Put the env in row i's MuJoCo state, with ``cube``'s target at ``goal`` [3] (obs units); returns (obs, info)."""
    import mujoco

    u = env.unwrapped
    mujoco.mj_resetData(u._model, u._data)
    u._data.qpos[:] = rows.qpos[i]
    u._data.qvel[:] = rows.qvel[i]
    u._target_block = int(cube)
    for k, mocap in enumerate(u._cube_target_mocap_ids):
        u._data.mocap_pos[mocap] = goal / XYZ_SCALE + XYZ_CENTER if k == cube else (0, 0, -0.3)
        u._data.mocap_quat[mocap] = goal_quat if k == cube else (1, 0, 0, 0)
    mujoco.mj_forward(u._model, u._data)  # site positions (the effector) and contacts of the restored state
    mujoco.mj_rnePostConstraint(u._model, u._data)
    ob = u.compute_observation()
    return np.asarray(ob, dtype=np.float64), u.get_reset_info()


def try_once(env, controller: Controller | None, rows: CubeRows, i: int, n: int, offset: int, advance: float,
             radius: float, max_steps: int) -> dict[str, Any]:
    """One try from row i (``controller`` None: OGBench's oracle); see the module doc."""
    from ogbench.manipspace.oracles.plan.cube_plan import CubePlanOracle

    c, u = int(rows.target[i]), int(rows.end[i])
    plan = rows.xyz[i:u + 1, c].astype(np.float64)  # [F, 3] the data's cube path
    goal = plan[-1]
    quat = rows.views[u, 22:26].astype(np.float64)  # the placed cube's orientation: the oracle's target yaw
    ob, info = restore(env, rows, i, c, goal, quat)
    tracker = SubgoalTracker(plan, offset, advance, dim=3)
    oracle = None
    if controller is None:
        oracle = CubePlanOracle(env=env, segment_dt=SEGMENT_DT, noise=0.1, noise_smoothing=NOISE_SMOOTHING)
        oracle.reset(ob, info)
    d0 = float(np.linalg.norm(cube_xyz(ob, n)[3 * c:3 * c + 3] - goal))
    hit, best = None, d0
    for s in range(1, max_steps + 1):
        xyz = cube_xyz(ob, n)[3 * c:3 * c + 3]
        if oracle is not None:
            action = np.zeros(ACT_DIM) if oracle.done else np.asarray(oracle.select_action(ob, info))
        else:
            action = controller(cube_view(ob, c), tracker.update(xyz))
        ob, _, _, _, info = env.step(np.clip(action, -1.0, 1.0))
        d = float(np.linalg.norm(cube_xyz(ob, n)[3 * c:3 * c + 3] - goal))
        best = min(best, d)
        if d <= radius:
            hit = s
            break
    return {"hit": hit, "d0": d0, "dmin": best, "plan_steps": len(plan) - 1, "on_table": bool(plan[0, 2] < ON_TABLE_Z)}


def evaluate_reach(env_name: str, controllers: dict[str, Controller | None], rows: CubeRows, n: int, offset: int,
                   advance: float, radius: float, max_steps: int, seed: int,
                   progress: bool = True) -> dict[str, dict[str, Any]]:
    """The same seeded tries for each named controller (``None`` = OGBench's oracle), on one cube env."""
    from tqdm.auto import tqdm

    picks = reach_rows(rows, n, radius, seed)
    env = make_cube_env(env_name, mode="data_collection")
    env.reset(seed=0)  # builds MuJoCo's state once; every try then restores its own
    ncube = n_cubes(env_name)
    out: dict[str, dict[str, Any]] = {}
    try:
        with torch_threads(1):
            for name, ctrl in controllers.items():
                res = []
                for k, i in enumerate(tqdm(picks, desc=f"reach {name}", disable=not progress, mininterval=10)):
                    with global_numpy_seed(int(np.random.SeedSequence([seed, k]).generate_state(1)[0])):
                        res.append(try_once(env, ctrl, rows, int(i), ncube, offset, advance, radius, max_steps))
                hits = [r["hit"] for r in res if r["hit"] is not None]
                table = [r["hit"] is not None for r in res if r["on_table"]]
                lifted = [r["hit"] is not None for r in res if not r["on_table"]]
                out[name] = {"tries": len(res), "reach_rate": len(hits) / max(len(res), 1),
                             "mean_steps_to_reach": float(np.mean(hits)) if hits else None,
                             "reach_rate_on_table": float(np.mean(table)) if table else None,
                             "tries_on_table": len(table),  # the cube starts on the table: grasp + carry + place
                             "reach_rate_lifted": float(np.mean(lifted)) if lifted else None,  # starts in the air
                             "mean_plan_steps": float(np.mean([r["plan_steps"] for r in res])),
                             "mean_start_dist": float(np.mean([r["d0"] for r in res])),
                             "mean_min_dist": float(np.mean([r["dmin"] for r in res])),
                             "radius": radius, "advance": advance, "offset": offset, "max_steps": max_steps,
                             "seed": seed}
    finally:
        env.close()
    return out


def format_reach(name: str, r: dict[str, Any]) -> str:
    """One line of a reach result (job output)."""
    steps = "-" if r["mean_steps_to_reach"] is None else f"{r['mean_steps_to_reach']:.1f}"
    split = "; ".join(f"{what} {r[key]:.1%}" for what, key in (("from the table", "reach_rate_on_table"),
                                                                 ("from the air", "reach_rate_lifted"))
                      if r[key] is not None)
    return (f"  {name:7s} reach {r['reach_rate']:.1%} (cube within {r['radius']} obs units = "
            f"{r['radius'] / XYZ_SCALE:.2f} m of the plan's end in {r['max_steps']} steps; {split}; "
            f"{r['tries_on_table']} start on the table), mean steps {steps}; "
            f"{r['tries']} val rows, plan {r['mean_plan_steps']:.0f} steps, start dist {r['mean_start_dist']:.2f}, "
            f"closest {r['mean_min_dist']:.2f}")
