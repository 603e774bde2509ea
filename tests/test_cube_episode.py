"""Cube planning and episodes (issue 20): the family hooks, object-wise plans from a tiny cube model, the
arm's pre-defined plans, a whole cube episode on both runners, failure reasons and bad inputs."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from fmctd_dist.config import load_config
from fmctd_dist.families.cube.scripts import ABOVE, EFFECTOR, PrePosition, Release, yaw_offset
from fmctd_dist.families.cube.env import CubeEpisodes
from fmctd_dist.errors import CheckpointError, ConfigError
from fmctd_dist.families.cube.failures import DROPPED, KNOCKED, PLANNING_TIME_OUT, TIME_OUT, WRONG_CUBE, why_failed
from fmctd_dist.families import hooks_for, plan_rules
from fmctd_dist.search.actions import scale_actions
from fmctd_dist.search.loop import SearchParams, search
from fmctd_dist.search.value_rule import MazeValue

TINY_DATA = ["data.episodes=2", "data.episode_steps=121", "env.horizon=100", "data.train_window=100"]
TINY_MODEL = ["model.width=32", "model.layers=1", "model.heads=2", "model.ff=64", "jump=5"]
SEARCH = ["method.parallel=3", "method.budget=6"]


# ---- the family hooks ----

def test_maze_hooks_give_the_search_its_old_defaults():
    """Mazes: the hook's actions and value are the loop's defaults, so trees and batches are bitwise unchanged."""
    from fakes import FakeDenoiser, make_codec, make_schedule

    cfg = load_config(["method=p-mctd", "method.parallel=4", "method.budget=12"])
    acts, value = hooks_for(cfg.env.name).plan_rules(cfg).tree(np.zeros(2), np.ones(2))
    params = SearchParams.from_method(cfg.method)
    default = scale_actions(params.guidance_scales)
    assert np.array_equal(acts.scale, default.scale) and acts.mask is None and acts.scale.dtype == np.float32
    assert value == MazeValue(params.warp_threshold, params.goal_radius)
    start, goal = np.array([10.0, 10.0]), np.array([14.0, 12.0])
    runs = []
    for kw in ({}, {"actions": acts, "value": value}):
        den = FakeDenoiser()
        r = search(den, make_schedule(), make_codec(), start, goal, params, 7, **kw)
        runs.append((r, den.batches))
    (a, ba), (b, bb) = runs
    assert json.dumps(a.tree.to_json()) == json.dumps(b.tree.to_json()) and np.array_equal(a.plan, b.plan)
    assert len(ba) == len(bb) and all(np.array_equal(x.x, y.x) and np.array_equal(x.scale, y.scale)
                                      and x.guide_mask is None and y.guide_mask is None for x, y in zip(ba, bb))


def test_cube_hooks_build_object_actions_from_the_unsolved_cubes():
    cfg = load_config(["env=cube-double", "method=fast-mctd-replan"])
    rules = hooks_for("cube-double").plan_rules(cfg)
    start = np.array([0.0, 1.0, 0.2, 1.0, -1.0, 0.2])
    goal = np.array([0.0, 1.0, 0.2, 2.0, 1.0, 0.2])  # cube 0 is already at its goal
    acts, value = rules.tree(start, goal)
    assert list(acts.obj) == [1, 1, 1] and list(acts.scale) == [1.0, 2.0, 4.0]
    assert acts.mask.tolist() == [[0, 0, 0, 1, 1, 1]] * 3
    assert value.warp_threshold == 2.0 and value.replanning  # jump 5: the sparse threshold; a replan method
    fixed, _ = rules.fixed(start, goal)
    assert fixed.mask.tolist() == [[0, 0, 0, 1, 1, 1]] and fixed.scale.tolist() == [cfg.method.guidance_scale]
    dense = load_config(["env=cube-double", "method=mctd", "jump=1"])
    v = hooks_for("cube-double").plan_rules(dense).value
    assert v.warp_threshold == 1.0 and not v.replanning
    with pytest.raises(ConfigError, match="object_scales"):
        hooks_for("cube-double").plan_rules(load_config(["env=cube-double", "env.object_scales=[]"]))


def test_an_env_without_hooks_is_one_error():
    with pytest.raises(ConfigError, match="did you mean 'visual-pointmaze-medium'"):
        hooks_for("visual-pointmaze-meduim")


# ---- scripted arm motions ----

@pytest.fixture(scope="module")
def single():
    env = CubeEpisodes("cube-single")
    yield env
    env.close()


def test_pre_position_and_release_move_the_effector_where_intended(single):
    obs = single.reset(1, seed=0).obs
    cube = single.state(obs)
    pre = PrePosition(cube)
    for k in range(pre.steps):
        a = pre.act(obs, k)
        assert a.shape == (5,) and np.all(np.abs(a) <= 1.0) and a[4] == -1.0
        obs, _ = single.step(a)
    assert np.linalg.norm(obs[EFFECTOR] - (cube + [0, 0, ABOVE])) < 0.3  # within 3 cm of the point above the cube
    assert obs[17] < 0.3  # gripper open
    before = obs[EFFECTOR].copy()
    rel = Release()
    for k in range(rel.steps):
        a = rel.act(obs, k)
        assert np.all(np.abs(a) <= 1.0)
        obs, _ = single.step(a)
        if k == 9:
            lifted = obs[EFFECTOR] - before
    assert lifted[2] > 0.5 and abs(lifted[0]) < lifted[2]  # 10 steps mostly up (5+ cm)
    assert obs[EFFECTOR][0] - before[0] > 1.0 and obs[17] < 0.3  # then 10+ cm away in +x, still open


def test_pre_position_turns_to_the_cube_only_when_asked(single):
    """env.preposition_yaw: a start 30-45 degrees off the cube ends face-on (mod 90); off, the actions are the
    authors' rule bit for bit (yaw action 0) and the default config hash is the one old rows carry."""
    from fmctd_dist.evaluation.identity import config_hash

    obs0 = single.reset(4, seed=8).obs
    assert 30 <= abs(np.degrees(yaw_offset(obs0, 0))) <= 45  # seed 8 starts ~43 degrees off
    runs = {}
    for turn in (None, 0):
        obs = single.reset(4, seed=8).obs
        pre, acts = PrePosition(single.state(obs), turn_to=turn), []
        for k in range(pre.steps):
            acts.append(pre.act(obs, k))
            obs, _ = single.step(acts[-1])
        runs[turn] = (np.array(acts), obs)
    (old, _), (new, end) = runs[None], runs[0]
    assert np.all(old[:, 3] == 0.0) and abs(np.degrees(yaw_offset(end, 0))) < 3.0
    assert np.abs(new[:, 3]).max() == 1.0 and np.linalg.norm(end[EFFECTOR] - (single.state(obs0) + [0, 0, ABOVE])) < 0.3
    obs = single.reset(4, seed=8).obs
    pre = PrePosition(single.state(obs))
    for k in range(pre.steps):  # the default is the old script: same actions for the same seed
        a = pre.act(obs, k)
        assert np.array_equal(a, old[k]) and np.array_equal(a, np.r_[np.clip((pre.target - obs[EFFECTOR]) / 0.5, -1, 1),
                                                                       0.0, -1.0])
        obs, _ = single.step(a)
    cube = ["env=cube-single", "method=fast-mctd-replan"]
    # the cube configs turn by default; the authors' rule (false) hashes as the rows made before the option
    assert load_config(cube).env.preposition_yaw is True
    assert config_hash(load_config([*cube, "env.preposition_yaw=false"])) == "40035edf105f5ce3"
    assert config_hash(load_config(cube)) != "40035edf105f5ce3"  # results/cube-methods-s9's rows


# ---- target choice ----

def test_target_is_the_unsolved_cube_whose_plan_moves_most():
    from fmctd_dist.families.cube.episode import choose_target, targets_left
    from fmctd_dist.families.cube.value import CubeValue

    state = np.array([[0.0, 0.0, 0.2], [1.0, 1.0, 0.2], [2.0, 2.0, 0.2]])
    plan = np.repeat(state[None], 10, 0)
    plan[:, 0, 0] += np.linspace(0, 3, 10)  # cube 0 moves most, cube 1 a little
    plan[:, 1, 1] += np.linspace(0, 1, 10)
    assert choose_target(plan, state, [0, 1, 2]) == 0 and choose_target(plan, state, [1, 2]) == 1
    goal = np.array([[0.0, 0.18, 0.2], [3.0, 3.0, 0.2], [2.0, 2.0, 0.2]])  # cube 0 let go 0.18 from its goal
    assert CubeValue().unsolved(state.reshape(-1), goal.reshape(-1)) == [0, 1]  # outside the value's 0.15
    assert targets_left(CubeValue(), state.reshape(-1), goal.reshape(-1)) == [1]  # not picked up again


# ---- failure reasons on hand-made trajectories ----

def test_why_failed_on_hand_made_trajectories():
    goal = np.array([[2.0, 0.0, 0.2], [0.0, 2.0, 0.2]])
    still = np.array([[0.0, 0.0, 0.2], [0.0, 0.0, 0.6]])  # cube 1 on cube 0
    traj = np.repeat(still[None], 5, 0)
    assert why_failed(traj, np.full(4, -1), goal, True, False) == ""
    assert why_failed(traj, np.full(4, -1), goal, False, True) == PLANNING_TIME_OUT
    assert why_failed(traj, np.zeros(4), goal, False, False) == TIME_OUT
    knocked = traj.copy()
    knocked[3:, 1] = [1.0, 0.0, 0.2]  # the top cube ends on the table, never targeted
    assert why_failed(knocked, np.zeros(4), goal, False, False) == KNOCKED
    flat = np.repeat(np.array([[0.0, 0.0, 0.2], [0.0, -2.0, 0.2]])[None], 5, 0)
    wrong = flat.copy()
    wrong[2:, 1] = [0.0, -1.0, 0.2]  # cube 1 moved while cube 0 was the target
    assert why_failed(wrong, np.zeros(4), goal, False, False) == WRONG_CUBE
    dropped = flat.copy()
    dropped[1:3, 0] = [0.5, 0.0, 0.8]
    dropped[3:, 0] = [1.0, 0.0, 0.2]  # lifted, then down on the table short of its goal
    assert why_failed(dropped, np.zeros(4), goal, False, False) == DROPPED


# ---- a tiny cube-double model ----

@pytest.fixture(scope="module")
def tiny_double(tmp_path_factory):
    """A 2-episode cube-double dataset, a 2-step sparse model and a random-weight cube policy (tmp dirs)."""
    import torch

    from fmctd_dist.control.policy.config import PolicyConfig
    from fmctd_dist.control.policy.checkpoint import save_policy
    from fmctd_dist.families.cube.policy import CUBE_SPEC
    from fmctd_dist.control.policy.network import GoalPolicyNet
    from fmctd_dist.families import load_dataset, make_dataset
    from fmctd_dist.data.windows import train_data
    from fmctd_dist.diffusion.train import train

    root = tmp_path_factory.mktemp("cube2")
    args = ["env=cube-double", *TINY_DATA, *TINY_MODEL, f"data.root={root}", f"checkpoint={root / 'ckpt'}",
            f"env.policy={root / 'policy'}"]
    cfg = load_config(args + ["train.max_steps=2", "train.batch_size=4", "train.val_batches=1", "train.warmup=1"],
                      method="mctd")
    make_dataset(cfg, progress=False)
    torch.manual_seed(0)
    with torch.random.fork_rng():
        train(cfg, train_data(cfg, load_dataset(cfg)), root / "ckpt", progress=False)
    pcfg = PolicyConfig()
    pcfg.policy.hidden = [16]
    net = GoalPolicyNet([16], CUBE_SPEC.in_dim, CUBE_SPEC.act_dim)
    save_policy(root / "policy", net, CUBE_SPEC, {"config": pcfg.to_dict(), "env": "cube-single"})
    return args


def test_a_cube_plan_has_the_right_shape_and_pins_the_other_cube(tiny_double):
    from fmctd_dist.denoiser.local import LocalDenoiser
    from fmctd_dist.diffusion.checkpoint import normaliser_from_manifest, read_manifest
    from fmctd_dist.planners import make_planner

    cfg = load_config(["method=fast-mctd-replan", *tiny_double, *SEARCH])
    ckpt = cfg.checkpoint_dir()
    planner = make_planner(cfg, LocalDenoiser.from_checkpoint(ckpt, cfg), normaliser_from_manifest(read_manifest(ckpt)),
                           plan_rules(cfg))
    env = CubeEpisodes("cube-double")
    r = env.reset(1, seed=0)
    start = env.state(r.obs)
    out = planner.plan(start, r.goal, 0)
    env.close()
    plan = out.waypoints.reshape(-1, 2, 3)
    assert out.waypoints.shape[1] == 6 and plan.shape[0] % cfg.jump == 0 and 0 < plan.shape[0] <= cfg.env.horizon
    assert out.expansions > 0 and out.status in ("early_stop", "achieved", "partial", "not_reached", "stay")
    tree = planner.last_result.tree
    n = tree.num_nodes
    acts, _ = planner.rules.tree(start, r.goal)  # 3 children per unsolved cube (task 1: one cube to move)
    assert n > 1 and tree.children.shape[1] == acts.size == 3 * len(set(acts.obj.tolist()))
    guided = acts.obj[tree.slot[1:n]]  # the cube each node's action guides
    sims = tree.sim_plan[1:n].reshape(n - 1, -1, 2, 3)  # [nodes, F, cube, xyz]
    for node, cube in enumerate(guided):
        other = sims[node, :, 1 - cube]  # [F, 3] the un-guided cube is pinned to its start
        assert np.array_equal(other, np.broadcast_to(start.reshape(2, 3)[1 - cube], other.shape).astype(np.float32))
    moved = np.abs(plan - start.reshape(2, 3)).max(axis=(0, 2))  # [2] how far each cube's plan leaves its start
    assert (moved < 1e-6).sum() >= 1  # the returned plan moves one cube only


def run_grid(args: list[str], tmp_path, runner: str) -> list[dict]:
    from fmctd_dist.evaluation.grid import prepare, run_local
    from fmctd_dist.evaluation.results import ResultStore

    cfg = load_config(args + [f"eval.out={tmp_path}", "eval.run=r", "tasks=[1]", "seeds=[0]", "env.max_steps=100",
                              "env.replan_every=10", "eval.threads=1"])
    p = prepare(cfg, hooks_for)
    store = ResultStore(cfg.eval.out, cfg.eval.run)
    if runner == "local":
        return run_local(p, store, progress=False, log=lambda s: None)
    from fmctd_dist.evaluation.ray_runner import run_ray

    return run_ray(dataclasses.replace(p), store, progress=False, log=lambda s: None)


def check_row(row: dict, searched: bool = True) -> None:
    assert row["env"] == "cube-double" and row["env_steps"] == 100 and row["n_cubes"] == 2
    # a replan every 10 policy steps after the 30 scripted ones
    assert row["plans"] >= 2 and (row["expansions"] > 0) == searched
    assert len(row["traj_cubes"]) == 101 * 6 and len(row["traj_effector"]) == 101 * 3
    assert row["targets"] and set(row["targets"].split(",")) <= {"0", "1"}
    assert row["why_failed"] in ("", "time out", "wrong cube", "dropped", "stack knocked over")
    assert len(row["policy_digest"]) == 16  # which policy drove the arm (a policy retrained mid-run shows)


def test_a_cube_episode_runs_in_process(tiny_double, tmp_path):
    rows = run_grid(["method=fast-mctd-replan", *tiny_double, *SEARCH], tmp_path, "local")
    assert len(rows) == 1
    check_row(rows[0])
    png = hooks_for("cube-double").plot_episode(rows[0], tmp_path / "episode.png")  # what jobs/eval.py draws
    assert png.stat().st_size > 10_000


@pytest.mark.ray
def test_a_cube_episode_runs_on_ray_with_the_same_row(tiny_double, ray_cluster, tmp_path):
    args = ["method=fast-mctd-replan", *tiny_double, *SEARCH]
    local = run_grid(args, tmp_path / "local", "local")[0]
    ray_row = run_grid(args + ["ray.denoiser_actors=1"], tmp_path / "ray", "ray")[0]
    check_row(ray_row)
    for k in ("success", "env_steps", "plan_status", "targets", "traj_cubes", "why_failed"):
        assert ray_row[k] == local[k], k


@pytest.mark.parametrize("method", ["diffusion-forcing", "mctd-replan", "p-mctd-replan", "s-mctd-replan"])
def test_other_methods_run_cube_episodes_without_a_planner_change(tiny_double, tmp_path, method):
    """The named method configs on a cube env (on the tiny sparse model: jump=5 for all)."""
    rows = run_grid([f"method={method}", *tiny_double, *SEARCH], tmp_path, "local")  # tiny_double sets jump=5
    check_row(rows[0], searched=method != "diffusion-forcing")


@pytest.fixture(scope="module")
def tiny_double_dense(tiny_double, tmp_path_factory):
    """tiny_double's data and policy with a 2-step dense (jump=1) model: what MCTD-Replan, P-MCTD-Replan and
    Diffusion Forcing load by default (their configs say jump=1; the cube value's warp is then env.warp_dense)."""
    import torch

    from fmctd_dist.families import load_dataset
    from fmctd_dist.data.windows import train_data
    from fmctd_dist.diffusion.train import train

    root = tmp_path_factory.mktemp("cube2dense")
    args = [a for a in tiny_double if not a.startswith(("checkpoint=", "jump="))] + [f"checkpoint={root / 'ckpt'}"]
    cfg = load_config(args + ["jump=1", "train.max_steps=2", "train.batch_size=4", "train.val_batches=1",
                              "train.warmup=1"], method="mctd")
    torch.manual_seed(0)
    with torch.random.fork_rng():
        train(cfg, train_data(cfg, load_dataset(cfg)), root / "ckpt", progress=False)
    return args


@pytest.mark.parametrize("method", ["diffusion-forcing", "mctd-replan", "p-mctd-replan"])
def test_dense_methods_run_cube_episodes_on_their_own_jump(tiny_double_dense, tmp_path, method):
    """The dense methods as configured (jump=1, 21 frame-stacked tokens per plan), not forced to jump=5."""
    cfg = load_config([f"method={method}", *tiny_double_dense])
    assert cfg.jump == 1 and hooks_for("cube-double").plan_rules(cfg).value.warp_threshold == cfg.env.warp_dense
    rows = run_grid([f"method={method}", *tiny_double_dense, *SEARCH], tmp_path, "local")
    check_row(rows[0], searched=method != "diffusion-forcing")
    assert rows[0]["jump"] == 1


# ---- bad inputs: one clear error before anything runs ----

def test_a_missing_cube_policy_is_one_error_naming_the_training_command(tiny_double, tmp_path):
    from fmctd_dist.evaluation.grid import prepare

    args = [a for a in tiny_double if not a.startswith("env.policy=")]
    cfg = load_config(["method=fast-mctd-replan", *args, f"env.policy={tmp_path / 'none'}"])
    with pytest.raises(CheckpointError) as e:
        prepare(cfg, hooks_for)
    msg = str(e.value)
    assert "\n" not in msg and "python jobs/train_policy.py env=cube-double" in msg and "env.policy=" in msg


def test_a_missing_cube_model_is_one_error_naming_the_training_command(tiny_double, tmp_path):
    from fmctd_dist.evaluation.grid import prepare

    args = [a for a in tiny_double if not a.startswith("checkpoint=")]
    cfg = load_config(["method=fast-mctd-replan", *args, f"checkpoint={tmp_path / 'none'}"])
    with pytest.raises(CheckpointError) as e:
        prepare(cfg, hooks_for)
    assert "\n" not in str(e.value) and "python jobs/train.py env=cube-double jump=5" in str(e.value)


@pytest.mark.parametrize("method", ["diffuser", "diffuser-replan"])
def test_a_missing_cube_diffuser_is_one_error_naming_its_training_command(tmp_path, method):
    """No cube Diffuser is shipped: asking for one names the missing dir and the jobs/train.py words that make it."""
    import os
    import subprocess
    import sys

    from fmctd_dist.config import REPO_ROOT

    missing = tmp_path / "cube-single-diffuser"
    out = subprocess.run([sys.executable, "jobs/eval.py", "env=cube-single", f"method={method}",
                          f"checkpoint={missing}", "runner=local", "tasks=[1]", "seeds=[0]", f"eval.out={tmp_path}"],
                         cwd=REPO_ROOT, capture_output=True, text=True, timeout=300,
                         env={**os.environ, "OMP_NUM_THREADS": "1"})
    err = out.stderr.strip()
    assert out.returncode == 2 and err.startswith("error: ") and "\n" not in err and "Traceback" not in err
    assert f"{missing} does not exist" in err
    assert f"`python jobs/train.py env=cube-single model.kind=diffuser jump=1 train.out={missing}`" in err
    assert not list(tmp_path.rglob("*.parquet"))


def test_the_cube_diffuser_hint_trains_one_that_plans_cube_episodes(tiny_double, tmp_path):
    """The suggested command, run as printed (the tiny config's words keep it smoke-sized), makes a cube Diffuser
    that Diffuser-Replan then plans a whole cube episode with, through the same planner as the mazes."""
    import os
    import re
    import subprocess

    from fmctd_dist.config import REPO_ROOT
    from fmctd_dist.evaluation.grid import prepare

    args = [a for a in tiny_double if not a.startswith(("checkpoint=", "jump="))]
    args += [f"checkpoint={tmp_path / 'ck'}", "model.unet_channels=[8,16]", "model.unet_edge_frames=2",
             "train.max_steps=2", "train.batch_size=4", "train.val_batches=1", "train.val_every=0"]
    cfg = load_config(["method=diffuser-replan", *args])
    with pytest.raises(CheckpointError, match="does not exist") as e:
        prepare(cfg, hooks_for)
    (cmd,) = [c for c in re.findall(r"`([^`]+)`", str(e.value)) if "jobs/train.py" in c]
    assert "env=cube-double" in cmd and "model.kind=diffuser" in cmd and f"train.out={tmp_path / 'ck'}" in cmd
    done = subprocess.run(cmd, shell=True, cwd=REPO_ROOT, capture_output=True, text=True, timeout=600,
                          env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert done.returncode == 0, done.stderr[-2000:]
    rows = run_grid(["method=diffuser-replan", *args], tmp_path / "res", "local")
    check_row(rows[0], searched=False)
    assert rows[0]["method"] == "diffuser-replan"


def test_a_maze_checkpoint_given_to_a_cube_env_is_one_error(tiny_double, tiny_checkpoint):
    from fmctd_dist.evaluation.grid import prepare

    _, maze_ckpt = tiny_checkpoint
    args = [a for a in tiny_double if not a.startswith("checkpoint=")]
    cfg = load_config(["method=fast-mctd-replan", *args, f"checkpoint={maze_ckpt}"])
    with pytest.raises(CheckpointError, match="pointmaze-medium"):
        prepare(cfg, hooks_for)


def test_eval_job_smoke_on_a_cube_env(tiny_double, tmp_path):
    """jobs/eval.py env=cube-double as a subprocess (tiny model, random policy): a row, the table, the figure."""
    import os
    import subprocess
    import sys

    from fmctd_dist.config import REPO_ROOT

    words = ["method=fast-mctd-replan", *tiny_double, *SEARCH, "runner=local", f"eval.out={tmp_path}",
             "eval.run=smoke", "tasks=[2]", "seeds=[0]", "env.max_steps=100", "eval.threads=1"]
    out = subprocess.run([sys.executable, "jobs/eval.py", *words], cwd=REPO_ROOT, capture_output=True, text=True,
                         timeout=600, env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert out.returncode == 0, out.stderr[-2000:]
    assert "| fast-mctd-replan | cube-double | 1 |" in out.stdout
    assert (tmp_path / "smoke/fast-mctd-replan/cube-double/task=2/seed=0.parquet").is_file()
    assert (tmp_path / "smoke/fast-mctd-replan/cube-double/episode.png").stat().st_size > 10_000


def test_bench_speed_runs_cube_episodes_side_by_side(tiny_double, tmp_path):
    """jobs/bench_speed.py on a cube env: the family's episodes (arm scripts + policy), ratios against
    fast-mctd-replan, and the rows kept with store=<run>."""
    import os
    import subprocess
    import sys

    from fmctd_dist.config import REPO_ROOT
    from fmctd_dist.evaluation.results import ResultStore

    words = ["methods=[s-mctd-replan,fast-mctd-replan]", *tiny_double, *SEARCH, "tasks=[1]", "seeds=[0]",
             "env.max_steps=100", "env.replan_every=10", "eval.threads=1", f"eval.out={tmp_path}", "store=speed"]
    out = subprocess.run([sys.executable, "jobs/bench_speed.py", *words], cwd=REPO_ROOT, capture_output=True,
                         text=True, timeout=600, env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert out.returncode == 0, out.stderr[-2000:]
    assert "| method | success (%) | planning time (s) | time / fast-mctd-replan |" in out.stdout
    lines = [ln for ln in out.stdout.splitlines() if ln.startswith(("| s-mctd-replan |", "| fast-mctd-replan |"))]
    assert len(lines) == 2 and "| 1.0x |" in lines[1]
    rows = ResultStore(tmp_path, "speed").rows(env="cube-double")
    assert sorted(r["method"] for r in rows) == ["fast-mctd-replan", "s-mctd-replan"]
    assert all(r["n_cubes"] == 2 and r["env_steps"] == 100 for r in rows)  # cube rows, from the cube episode


def test_probe_cube_grasp_prints_the_policy_steps_of_the_eval_episode(tiny_double, tmp_path):
    """jobs/probes/probe_cube_grasp.py runs the episode jobs/eval.py would (same row) and prints each policy step."""
    import os
    import subprocess
    import sys

    from fmctd_dist.config import REPO_ROOT

    words = ["method=fast-mctd-replan", *tiny_double, *SEARCH, "tasks=[1]", "seeds=[0]", "env.max_steps=100",
             "env.replan_every=10", "eval.threads=1"]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    out = subprocess.run([sys.executable, "jobs/probes/probe_cube_grasp.py", *words, "steps=0:3"], cwd=REPO_ROOT,
                         capture_output=True, text=True, timeout=600, env=env)
    assert out.returncode == 0, out.stderr[-2000:]
    lines = out.stdout.splitlines()
    assert [ln.split(":")[0] for ln in lines[:3]] == [f"policy step {k:3d}" for k in range(3)]
    assert "grip" in lines[0] and "contact" in lines[0] and "subgoal" in lines[0] and "action" in lines[0]
    row = run_grid(["method=fast-mctd-replan", *tiny_double, *SEARCH], tmp_path, "local")[0]  # the eval episode
    outcome = "success" if row["success"] else f"failure ({row['why_failed']})"
    assert lines[-1].startswith(f"fast-mctd-replan cube-double task 1 seed 0: {outcome} after {row['env_steps']} steps")
    bad = subprocess.run([sys.executable, "jobs/probes/probe_cube_grasp.py", *words, "steps=x"], cwd=REPO_ROOT,
                         capture_output=True, text=True, timeout=300, env=env)
    assert bad.returncode == 2 and "steps='x' is not A:B" in bad.stderr


def test_ideal_plans_job_smoke(tiny_double, tmp_path):
    """jobs/probes/cube_ideal_plans.py (arc plans instead of a model) runs the cube episode with the given policy."""
    import os
    import subprocess
    import sys

    from fmctd_dist.config import REPO_ROOT

    policy = next(a for a in tiny_double if a.startswith("env.policy="))
    out = subprocess.run([sys.executable, "jobs/probes/cube_ideal_plans.py", "env=cube-double", policy, "tasks=[1]",
                          "seeds=[0]", "env.max_steps=60", "env.horizon=50", "data.train_window=50"], cwd=REPO_ROOT,
                         capture_output=True, text=True, timeout=300, env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert out.returncode == 0, out.stderr[-2000:]
    assert "task 1 seed 0:" in out.stdout and "episodes solved with ideal arc plans" in out.stdout


def test_pooled_cube_episodes_give_the_lone_rows(tiny_double, tmp_path):
    """eval.in_flight (issue 55) on the cube family: two episodes at once, their jobs pooled, the lone rows."""
    from fmctd_dist.evaluation.grid import prepare, run_local
    from fmctd_dist.evaluation.results import ResultStore

    def grid(in_flight: int) -> dict:
        cfg = load_config(["method=s-mctd-replan", *tiny_double, *SEARCH, "ray.micro_batch=2",
                           f"eval.out={tmp_path}", f"eval.run=f{in_flight}", f"eval.in_flight={in_flight}",
                           "tasks=[1,2]", "seeds=[0]", "env.max_steps=100", "env.replan_every=10", "eval.threads=1"])
        got = run_local(prepare(cfg, hooks_for), ResultStore(cfg.eval.out, cfg.eval.run), progress=False,
                        log=lambda s: None)
        return {(r["task"], r["seed"]): r for r in got}

    alone, pooled = grid(1), grid(2)
    assert sorted(alone) == sorted(pooled) == [(1, 0), (2, 0)]
    for key, r in alone.items():
        for k in ("success", "env_steps", "plan_status", "targets", "traj_cubes", "why_failed", "expansions"):
            assert pooled[key][k] == r[k], (key, k)
