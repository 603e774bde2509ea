"""Faults on a simulated multi-node Ray cluster (run by tests/test_ray_multinode.py in its own process,
since a process holds one Ray connection and the test session already has one).

    python tests/multinode_faults.py '{"words": [...], "out": "/tmp/x", "scenarios": ["node", "actor", "job"]}'

Starts ``ray.cluster_utils.Cluster``: a head and two worker nodes, 1 CPU each, on this machine.
Runs the grid fault-free (run ``ref``), then once per scenario with a fault injected from a watcher
thread once the first row exists, and prints one JSON line: per run, the rows (key, retries,
plan/trajectory bits) plus what was killed.

- ``node``: remove the worker node that holds the most of the run's actors (denoisers, drivers, env actors).
- ``actor``: kill an env actor (mid-episode: all pairs are busy while the queue is not empty), then,
  after the third row, a planner driver.
- ``job``: `ray job stop` equivalent: SIGTERM the jobs/eval.py process running against this cluster
  after its first row, then run the same command again.
"""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

os.environ["RAY_AUTH_MODE"] = "disabled"  # a private cluster: no stale ~/.ray/auth_token can break it
os.environ.setdefault("RAY_worker_niceness", "0")
for k in ("RAY_ADDRESS",):
    os.environ.pop(k, None)

import ray  # noqa: E402
from ray.cluster_utils import Cluster  # noqa: E402

import fmctd_dist.evaluation.ray_runner as rr  # noqa: E402
from fmctd_dist.denoiser.ray_pool import DenoiserPool  # noqa: E402

ARGS = json.loads(sys.argv[1])
OUT = Path(ARGS["out"])
ROWS = "*/*/task=*/seed=*.parquet"
PAIRS: list[tuple] = []  # every (EnvActor, PlannerDriver) the runner made, in order
POOLS: list = []
WHERE: list = []  # per pair: (info ref, kind) of its env actor and driver
_make_pair, _create_pool = rr.episode_pair, DenoiserPool.create.__func__


def recording_pair(p, denoisers):
    pair = rr.episode_pair_orig(p, denoisers)
    PAIRS.append(pair)
    WHERE.append(((pair[0].info.remote(), "env"), (pair[1].info.remote(), "driver")))  # runs before the episode
    return pair


def recording_pool(cls, *a, **kw):
    pool = _create_pool(cls, *a, **kw)
    POOLS.append(pool)
    return pool


rr.episode_pair_orig = _make_pair
rr.episode_pair = recording_pair
DenoiserPool.create = classmethod(recording_pool)


def rows_of(run: str) -> list[dict]:
    import pyarrow.parquet as pq

    out = []
    for f in sorted((OUT / run).glob(ROWS)):
        r = pq.read_table(f).to_pylist()[0]
        out.append({"task": r["task"], "seed": r["seed"], "retries": r["retries"], "success": r["success"],
                    "env_steps": r["env_steps"], "expansions": r["expansions"],
                    "plan": hashlib.sha256(np.asarray(r["plan_xy"], np.float32).tobytes()).hexdigest(),
                    "traj": hashlib.sha256(np.asarray(r["traj_xy"], np.float32).tobytes()).hexdigest(),
                    "file": str(f.relative_to(OUT / run)), "mtime": f.stat().st_mtime_ns})
    return out


def n_rows(run: str) -> int:
    return len(list((OUT / run).glob(ROWS)))


def wait_rows(run: str, n: int, timeout: float = 120.0) -> bool:
    deadline = time.monotonic() + timeout
    while n_rows(run) < n and time.monotonic() < deadline:
        time.sleep(0.05)
    return n_rows(run) >= n


def evaluate(run: str) -> float:
    t0 = time.monotonic()
    rr.evaluate(ARGS["words"] + [f"eval.out={OUT}", f"eval.run={run}"], progress=False)
    return time.monotonic() - t0


def main() -> None:
    t_start = time.monotonic()
    cluster = Cluster(initialize_head=True, connect=False, head_node_args={"num_cpus": 1})
    workers = [cluster.add_node(num_cpus=1) for _ in range(2)]
    cluster.wait_for_nodes()
    ray.init(address=cluster.address, logging_level="ERROR", log_to_driver=False)
    report: dict = {"nodes": len(ray.nodes()), "startup_s": round(time.monotonic() - t_start, 1)}
    t0 = time.monotonic()  # the fault-free reference: in process (no Ray), bitwise what Ray gives (design 4)
    from fmctd_dist.config import load_config
    from fmctd_dist.evaluation.grid import prepare, run_local
    from fmctd_dist.evaluation.results import ResultStore

    cfg = load_config(ARGS["words"] + [f"eval.out={OUT}", "eval.run=ref", "runner=local", "eval.threads=1"])
    run_local(prepare(cfg), ResultStore(cfg.eval.out, cfg.eval.run), progress=False, log=lambda s: None)
    report["ref_s"] = round(time.monotonic() - t0, 1)
    report["ref"] = rows_of("ref")

    if "node" in ARGS["scenarios"]:
        PAIRS.clear()
        POOLS.clear()
        WHERE.clear()
        killed: dict = {}

        def remove_busiest_worker():
            if not wait_rows("node", 1):
                return
            where = [("denoiser", i["node_id"]) for pool in POOLS for i in pool.infos]
            for refs in list(WHERE):
                for ref, kind in refs:
                    try:
                        where.append((kind, ray.get(ref, timeout=10)["node_id"]))
                    except Exception:  # noqa: BLE001 - an actor that is already gone
                        pass
            by_node = {w.node_id: w for w in workers}
            counts = {nid: [k for k, n in where if n == nid] for nid in by_node}
            nid = max(counts, key=lambda n: len(counts[n]))
            killed.update(node=nid[:8], actors=counts[nid], rows_before=n_rows("node"))
            cluster.remove_node(by_node[nid])

        t = threading.Thread(target=remove_busiest_worker, daemon=True)
        t.start()
        report["node_s"] = round(evaluate("node"), 1)
        t.join(timeout=5)
        report["node"], report["node_killed"] = rows_of("node"), killed
        report["nodes_after"] = len([n for n in ray.nodes() if n["Alive"]])

    if "actor" in ARGS["scenarios"]:
        PAIRS.clear()
        killed = {}

        def kill_env_then_driver():
            if not wait_rows("actor", 1):
                return
            env, _ = PAIRS[0]
            ray.kill(env, no_restart=True)
            killed["env_after_rows"] = n_rows("actor")
            if not wait_rows("actor", 2):
                return
            _, driver = PAIRS[-1]
            ray.kill(driver, no_restart=True)
            killed["driver_after_rows"] = n_rows("actor")

        t = threading.Thread(target=kill_env_then_driver, daemon=True)
        t.start()
        report["actor_s"] = round(evaluate("actor"), 1)
        t.join(timeout=5)
        report["actor"], report["actor_killed"] = rows_of("actor"), killed

    if "job" in ARGS["scenarios"]:
        env = {**os.environ, "RAY_ADDRESS": cluster.address, "OMP_NUM_THREADS": "1"}
        cmd = [sys.executable, "jobs/eval.py", "runner=ray", *ARGS["words"], f"eval.out={OUT}", "eval.run=job"]
        t0 = time.monotonic()
        job = subprocess.Popen(cmd, cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        wait_rows("job", 1, timeout=180)
        job.send_signal(signal.SIGTERM)  # what `ray job stop` sends the entrypoint first
        _, err1 = job.communicate(timeout=60)
        first = rows_of("job")
        # as after `ray job stop`: the stopped job's actors are gone (their CPUs back) before resubmitting
        t_stop, total = time.monotonic(), ray.cluster_resources().get("CPU", 0)
        while ray.available_resources().get("CPU", 0) < total and time.monotonic() - t_stop < 60:
            time.sleep(0.2)
        report["job_freed_s"] = round(time.monotonic() - t_stop, 1)
        try:
            again = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=240)
        except subprocess.TimeoutExpired as e:
            report.update(job_timeout=True, job_err=str(e.stderr)[-3000:], job_stop_err=err1[-2000:],
                          job_first=first, res=dict(ray.available_resources()))
            print("REPORT " + json.dumps(report))
            raise
        report["job_s"] = round(time.monotonic() - t0, 1)
        report["job_first"], report["job"] = first, rows_of("job")
        report["job_rc"], report["job_stop_rc"] = again.returncode, job.returncode
        report["job_err"] = again.stderr[-2000:] if again.returncode else ""
        report["job_stdout"] = again.stdout[-1500:]

    ray.shutdown()
    cluster.shutdown()
    report["total_s"] = round(time.monotonic() - t_start, 1)
    print("REPORT " + json.dumps(report))


if __name__ == "__main__":
    main()
