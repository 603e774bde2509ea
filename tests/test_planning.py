"""Planners, episodes and the local eval job with a real (tiny) Diffusion Forcing checkpoint."""

import subprocess
import sys

import numpy as np
import pyarrow.parquet as pq
import pytest
import torch

from fmctd_dist.config import REPO_ROOT, load_config
from fmctd_dist.denoiser.local import LocalDenoiser
from fmctd_dist.diffusion.checkpoint import load_checkpoint, normaliser_from_manifest
from fmctd_dist.families import plan_rules
from fmctd_dist.families.maze.make import make_env
from fmctd_dist.families.maze.episode import run_episode
from fmctd_dist.planners import make_planner, plan_seed

pytestmark = pytest.mark.usefixtures("one_torch_thread")

SEARCH = ["method=p-mctd", "method.parallel=8", "method.budget=24", "method.early_stop=false",
          "method.warp_threshold=1000"]  # an untrained model warps; keep its plans as real outputs



def planner_for(tiny_checkpoint, micro_batch, *extra):
    args, ckpt = tiny_checkpoint
    cfg = load_config(args + SEARCH + list(extra))
    model, manifest = load_checkpoint(ckpt, cfg)
    denoiser = LocalDenoiser(model, cfg.diffusion, "cpu", micro_batch=micro_batch)
    return cfg, make_planner(cfg, denoiser, normaliser_from_manifest(manifest), plan_rules(cfg))


def test_plan_is_pure_function_of_config_checkpoint_seed(tiny_checkpoint):
    start, goal = np.array([0.0, 0.0]), np.array([20.0, 20.0])
    plans = {}
    for m in (3, 5, 64):  # micro-batches that cut the batches differently (M * T >= 12 rows)
        cfg, planner = planner_for(tiny_checkpoint, m)
        plans[m] = planner.plan(start, goal, seed=7)
        plans[m].tree = planner.last_result.tree
        again = planner.plan(start, goal, seed=7)
        assert np.array_equal(plans[m].waypoints, again.waypoints)
    ref = plans[64]
    assert ref.status != "stay" and np.abs(np.diff(ref.waypoints, axis=0)).max() > 0
    assert ref.expansions >= 24 and ref.iterations >= 2
    for m in (3, 5):
        assert np.array_equal(plans[m].waypoints, ref.waypoints), f"micro_batch {m} changed the plan"
        assert plans[m].expansions == ref.expansions
        n = ref.tree.num_nodes
        assert np.array_equal(plans[m].tree.x[:n], ref.tree.x[:n])  # every node's denoised payload
    other = planner_for(tiny_checkpoint, 64)[1].plan(start, goal, seed=8)
    assert not np.array_equal(other.waypoints, ref.waypoints)


def test_plan_seeds_are_distinct_and_stable():
    assert plan_seed(0, 1, 0, 0) == plan_seed(0, 1, 0, 0)
    assert len({plan_seed(0, t, s, k) for t in range(1, 6) for s in range(10) for k in range(3)}) == 150


def test_episode_row_and_replanning(tiny_checkpoint):
    cfg, planner = planner_for(tiny_checkpoint, 64, "method.replan_every=30")
    calls = []
    real = planner.plan
    planner.plan = lambda s, g, seed: calls.append(seed) or real(s, g, seed)
    row = run_episode(cfg, make_env(cfg.env.name), planner, task=3, seed=0)
    assert row["env_steps"] <= 100 and len(calls) == row["plans"]
    assert row["success"] or len(calls) == 4  # 100 steps / replan every 30 -> 4 plans
    assert 0 < row["denoise_time_s"] <= row["plan_time_s"] and row["expansions"] > 0
    assert len(row["traj_xy"]) == 2 * (row["env_steps"] + 1)


def test_the_progress_bar_counts_an_episodes_plans_and_changes_none(tiny_checkpoint):
    from fmctd_dist.evaluation.grid import PlanTicker

    class Bar:
        def __init__(self):
            self.postfixes = []

        def set_postfix(self, **kw):
            self.postfixes.append(kw)

    cfg, planner = planner_for(tiny_checkpoint, 64, "method.replan_every=30")
    bar = Bar()
    ticker = PlanTicker(planner, bar)
    ticker.start(3, 0, success="0/0")
    row = run_episode(cfg, make_env(cfg.env.name), ticker, task=3, seed=0)
    plain = run_episode(cfg, make_env(cfg.env.name), planner, task=3, seed=0)
    assert np.array_equal(row["traj_xy"], plain["traj_xy"]) and row["plan_status"] == plain["plan_status"]
    assert [b["plans"] for b in bar.postfixes] == list(range(1, row["plans"] + 1))
    assert {b["episode"] for b in bar.postfixes} == {"3/0"}
    assert [b["last"] for b in bar.postfixes] == row["plan_status"].split(",")
    ticker.start(4, 1, success="0/1")
    assert ticker.plans == 0 and ticker.episode == "4/1"


def run_eval(args, *extra):
    return subprocess.run([sys.executable, "jobs/eval.py", *args, *extra], cwd=REPO_ROOT, capture_output=True,
                          text=True, timeout=600)


def test_eval_job_writes_rows_and_resumes(tiny_checkpoint, tmp_path):
    args, _ = tiny_checkpoint
    args = args + SEARCH + [f"eval.out={tmp_path}", "eval.run=t", "runner=local", "tasks=[1,3]", "seeds=[0]"]
    first = run_eval(args)
    assert first.returncode == 0, first.stderr
    files = sorted(tmp_path.glob("t/p-mctd/pointmaze-medium/task=*/seed=*.parquet"))
    assert [f.parent.name for f in files] == ["task=1", "task=3"]
    row = pq.read_table(files[0]).to_pylist()[0]
    for key in ("method", "env", "task", "seed", "success", "env_steps", "plan_time_s", "denoise_time_s",
                "overhead_s", "expansions", "iterations", "retries", "n_denoiser_actors", "device", "git_sha",
                "checkpoint_digest", "config_hash", "denoise_call_s", "call_share"):
        assert key in row
    # the search knobs the ablation tables group by are recorded, with this run's values
    assert (row["parallel"], row["virtual_weight"], row["redundancy_aware"], row["leaf_parallel"], row["jump"]) == \
        (8, 1.0, True, False, 1)
    assert row["denoise_time_s"] <= row["denoise_call_s"] <= row["plan_time_s"]
    mtimes = [f.stat().st_mtime_ns for f in files]
    second = run_eval(args[:-1] + ["seeds=[0,1]"])  # resume: only the two new keys run
    assert second.returncode == 0, second.stderr
    assert [f.stat().st_mtime_ns for f in files] == mtimes
    assert len(list(tmp_path.glob("t/p-mctd/pointmaze-medium/task=*/seed=*.parquet"))) == 4
    assert "| p-mctd | pointmaze-medium | 4 |" in second.stdout
    assert (tmp_path / "t/summary.png").stat().st_size > 0
    assert (tmp_path / "t/p-mctd/pointmaze-medium/episode.png").stat().st_size > 0


@pytest.mark.parametrize("extra, message", [
    (["jump=5"], "jump"),  # sparse planning, dense checkpoint
    (["model.width=64"], "model.width"),
    (["device=cuda"], "device"),
])
def test_eval_job_bad_input_is_one_clear_error(tiny_checkpoint, tmp_path, extra, message):
    if extra == ["device=cuda"] and torch.cuda.is_available():
        pytest.skip("a GPU is present")
    args, _ = tiny_checkpoint
    out = run_eval(args + [f"eval.out={tmp_path}"] + extra)
    assert out.returncode == 2 and out.stderr.startswith("error: ") and message in out.stderr
    assert "Traceback" not in out.stderr and not list(tmp_path.rglob("*.parquet"))


def test_eval_job_missing_checkpoint(tmp_path):
    out = run_eval([f"checkpoint={tmp_path}/nothing", f"eval.out={tmp_path}"])
    assert out.returncode == 2 and "checkpoint" in out.stderr and "train.py" in out.stderr


def test_bench_speed_prints_side_by_side_ratios(tiny_checkpoint):
    args, _ = tiny_checkpoint
    out = subprocess.run([sys.executable, "jobs/bench_speed.py", "methods=[mctd,p-mctd]", *args, "tasks=[3]",
                          "seeds=[0]", "method.budget=6", "method.warp_threshold=1000"],
                         cwd=REPO_ROOT, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert "| method | success (%) | planning time (s) | time / p-mctd |" in out.stdout
    lines = [line for line in out.stdout.splitlines() if line.startswith("| mctd |") or line.startswith("| p-mctd |")]
    assert len(lines) == 2 and "| 1.0x |" in lines[1]


def test_bench_speed_runs_inference_options_side_by_side(tiny_checkpoint, tmp_path):
    """`method+option` runs the same method with diffusion.precision / diffusion.compile on the same
    episodes (the option's speed-up is its time ratio); an unknown option is one clear error."""
    args, _ = tiny_checkpoint
    common = [*args, "tasks=[3]", "seeds=[0]", "method.budget=6", "method.warp_threshold=1000"]
    out = subprocess.run([sys.executable, "jobs/bench_speed.py", "methods=[p-mctd,p-mctd+bf16]", *common,
                          f"eval.out={tmp_path}", "store=opt"], cwd=REPO_ROOT, capture_output=True, text=True,
                         timeout=600)
    assert out.returncode == 0, out.stderr
    assert [line.split(" | ")[0] for line in out.stdout.splitlines() if line.startswith("| p-mctd")] == \
        ["| p-mctd", "| p-mctd+bf16"]
    from fmctd_dist.evaluation.results import ResultStore

    # one config per (run, method, env): the option arm's row lives in run "opt+bf16", not over the fp32 one
    plain, bf16 = ResultStore(tmp_path, "opt").rows("p-mctd"), ResultStore(tmp_path, "opt+bf16").rows("p-mctd")
    assert [r["precision"] for r in plain] == ["fp32"] and [r["precision"] for r in bf16] == ["bf16"]
    # the same command again resumes: every episode is read back from the store, none planned again
    again = subprocess.run([sys.executable, "jobs/bench_speed.py", "methods=[p-mctd,p-mctd+bf16]", *common,
                            f"eval.out={tmp_path}", "store=opt"], cwd=REPO_ROOT, capture_output=True, text=True,
                           timeout=600)
    assert again.returncode == 0, again.stderr
    assert "resuming: 2 episode(s) read back from store=opt" in again.stdout
    assert ResultStore(tmp_path, "opt").rows("p-mctd")[0]["plan_time_s"] == plain[0]["plan_time_s"]
    assert [ln for ln in again.stdout.splitlines() if ln.startswith("| p-mctd |")] == \
        [ln for ln in out.stdout.splitlines() if ln.startswith("| p-mctd |")]
    bad = subprocess.run([sys.executable, "jobs/bench_speed.py", "methods=[p-mctd+fp16]", *common],
                         cwd=REPO_ROOT, capture_output=True, text=True, timeout=600)
    assert bad.returncode == 2 and "fp16" in bad.stderr and "bf16+compiled" in bad.stderr
    assert "Traceback" not in bad.stderr
