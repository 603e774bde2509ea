"""Faults on a simulated multi-node Ray cluster (run by tests/test_ray_multinode.py in its own process,
since a process holds one Ray connection and the test session already has one).

    python tests/multinode_faults.py '{"words": [...], "out": "/tmp/x", "scenarios": ["node", "actor", "job"]}'

Starts ``ray.cluster_utils.Cluster``: a head and two worker nodes, 1 CPU each, on this machine.
Runs the grid fault-free (run ``ref``), then once per scenario with a fault injected from a watcher
thread once the first row exists, and prints one JSON line: per run, the rows (key, retries,
plan/trajectory bits) plus what was killed.

- ``node``: at the first row, remove the worker node that holds the most of the episode pairs' actors (env
  actors, drivers; then denoisers).
- ``actor``: kill an env actor (mid-episode: all pairs are busy while the queue is not empty), then,
  after the third row, a planner driver.
- ``job``: `ray job submit` jobs/eval.py to the head's job server, `ray job stop` it after its first
  row (JobSubmissionClient.stop_job: SIGTERM to the entrypoint), then submit the same job again.
"""

from __future__ import annotations

import hashlib
import json
import os
import shlex
import socket
import sys
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

os.environ["RAY_AUTH_MODE"] = "disabled"  # a private cluster: no stale ~/.ray/auth_token can break it
# `ray job stop` sends SIGTERM and SIGKILLs what is left after this grace (Ray's default 3 s). The stopped
# eval.py was still there after the whole grace in every run (the supervisor's log: "force-killed with
# SIGKILL"), so the stop ends the same way, 2 s sooner.
os.environ["RAY_JOB_STOP_WAIT_TIME_S"] = "1"
os.environ.setdefault("RAY_worker_niceness", "0")
for k in ("RAY_ADDRESS",):
    os.environ.pop(k, None)

import ray  # noqa: E402
from ray.cluster_utils import Cluster  # noqa: E402

import fmctd_dist.evaluation.ray_runner as rr  # noqa: E402
from fmctd_dist.denoiser.ray_pool import DenoiserPool  # noqa: E402
from fmctd_dist.families import hooks_for  # noqa: E402

ARGS = json.loads(sys.argv[1])


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


DASHBOARD_PORT = _free_port()  # the job server (`ray job submit/stop`) of the head; not the default 8265
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


def say(*a) -> None:
    print(f"[{time.strftime('%H:%M:%S')}]", *a, file=sys.stderr, flush=True)


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
    rr.evaluate(ARGS["words"] + [f"eval.out={OUT}", f"eval.run={run}"], hooks_for, progress=False)
    return time.monotonic() - t0


def main() -> None:
    t_start = time.monotonic()
    # the job server, and agent ports of our own: another Ray cluster on this machine (the test session's)
    # holds the default ones
    dashboard = {"include_dashboard": True, "dashboard_host": "127.0.0.1", "dashboard_port": DASHBOARD_PORT,
                 **{k: _free_port() for k in ("dashboard_agent_listen_port", "runtime_env_agent_port",
                                              "metrics_agent_port", "metrics_export_port")}}
    cluster = Cluster(initialize_head=True, connect=False,
                      head_node_args={"num_cpus": 1, **(dashboard if "job" in ARGS["scenarios"] else {})})
    workers = [cluster.add_node(num_cpus=1) for _ in range(2)]
    cluster.wait_for_nodes()
    ray.init(address=cluster.address, logging_level="ERROR", log_to_driver=False)
    say("cluster up", cluster.address)
    report: dict = {"nodes": len(ray.nodes()), "startup_s": round(time.monotonic() - t_start, 1)}
    t0 = time.monotonic()  # the fault-free reference: in process (no Ray), bitwise what Ray gives (docs/design.md §7)
    from fmctd_dist.config import load_config
    from fmctd_dist.evaluation.grid import prepare, run_local
    from fmctd_dist.evaluation.results import ResultStore

    cfg = load_config(ARGS["words"] + [f"eval.out={OUT}", "eval.run=ref", "runner=local", "eval.threads=1"])
    run_local(prepare(cfg, hooks_for), ResultStore(cfg.eval.out, cfg.eval.run), progress=False, log=lambda s: None)
    report["ref_s"] = round(time.monotonic() - t0, 1)
    report["ref"] = rows_of("ref")

    if "node" in ARGS["scenarios"]:
        PAIRS.clear()
        POOLS.clear()
        WHERE.clear()
        killed: dict = {}

        def remove_busiest_worker():
            # Find every actor's node first, then remove at the first row: then each pair still has an episode
            # running or queued (4 keys, 2 pairs), so a removed pair actor always loses work. An idle denoiser
            # on the removed node loses none (Ray restarts it), so the node is chosen by its pair actors.
            # An actor answers its info call once its worker process is up; on a loaded CI machine (two
            # pytest workers, six actors starting on two cores) that took over 30 s, and an actor that had
            # not answered counted as on no node. Its episode runs after the info call, so waiting costs no
            # fault timing: the first row cannot exist before every pair actor answered.
            deadline = time.monotonic() + 240
            while (len(WHERE) < 2 or not POOLS) and time.monotonic() < deadline:
                time.sleep(0.02)
            where = [("denoiser", i["node_id"]) for pool in POOLS for i in pool.infos]
            for refs in list(WHERE):
                for ref, kind in refs:
                    try:
                        where.append((kind, ray.get(ref, timeout=max(1.0, deadline - time.monotonic()))["node_id"]))
                    except Exception as e:  # noqa: BLE001 - an actor that is already gone
                        killed.setdefault("lookup_errors", []).append(f"{kind}: {type(e).__name__}")
            killed["placement"] = {n[:8]: sorted(k for k, m in where if m == n) for n in {m for _, m in where}}
            if not wait_rows("node", 1):
                return
            by_node = {w.node_id: w for w in workers}
            counts = {nid: [k for k, n in where if n == nid] for nid in by_node}
            nid = max(counts, key=lambda n: (sum(k != "denoiser" for k in counts[n]), len(counts[n])))
            killed.update(node=nid[:8], actors=counts[nid], rows_before=n_rows("node"))
            cluster.remove_node(by_node[nid])

        def remove_then_release():
            try:
                remove_busiest_worker()
            finally:
                removed.set()  # a watcher that gave up must not hold the writer

        # The runner writes rows in this process: hold it in its first write until the node is gone, so the fault
        # lands with one row written whatever the episodes' speed (on a fast machine two more rows were written
        # while the watcher was still looking up where the actors live). The actors keep running meanwhile.
        removed = threading.Event()
        write = ResultStore.write

        def gated_write(self, row):
            path = write(self, row)
            removed.wait(timeout=120)
            return path

        ResultStore.write = gated_write
        t = threading.Thread(target=remove_then_release, daemon=True)
        t.start()
        say("node: evaluate")
        try:
            report["node_s"] = round(evaluate("node"), 1)
        finally:
            ResultStore.write = write
        say("node: done")
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
        say("actor: evaluate")
        report["actor_s"] = round(evaluate("actor"), 1)
        say("actor: done")
        t.join(timeout=5)
        report["actor"], report["actor_killed"] = rows_of("actor"), killed

    if "job" in ARGS["scenarios"]:
        from ray.job_submission import JobStatus, JobSubmissionClient

        client = JobSubmissionClient(f"http://127.0.0.1:{DASHBOARD_PORT}")
        # one denoiser and one env actor: the job's own resume is under test here, not the pool
        words = [w for w in ARGS["words"] if not w.startswith(("ray.denoiser_actors=", "ray.env_actors="))]
        entry = (f"cd {shlex.quote(str(REPO))} && OMP_NUM_THREADS=1 " + shlex.join(
            ["python", "jobs/eval.py", "runner=ray", *words, "ray.denoiser_actors=1", "ray.env_actors=1",
             f"eval.out={OUT}", "eval.run=job"]))
        t0 = time.monotonic()

        def submit() -> str:
            for _ in range(60):  # the dashboard answers before the head's job agent is up
                try:
                    return client.submit_job(entrypoint=entry)
                except Exception as e:  # noqa: BLE001
                    if "agent" not in str(e).lower() and "connect" not in str(e).lower():
                        raise
                    time.sleep(1)
            raise RuntimeError("no job agent")

        def wait(jid: str, timeout: float) -> str:
            deadline = time.monotonic() + timeout
            while time.monotonic() < deadline:
                st = client.get_job_status(jid)
                if st.is_terminal():
                    return st.value
                time.sleep(0.2)
            return "TIMEOUT"

        first_id = submit()
        say("job: submitted", first_id)
        wait_rows("job", 1, timeout=180)
        client.stop_job(first_id)  # `ray job stop`: SIGTERM to the entrypoint, SIGKILL after a grace period
        report["job_stop_status"] = wait(first_id, 60)
        first = rows_of("job")
        # the stopped job's actors are gone (their CPUs back) before resubmitting
        t_stop, total = time.monotonic(), ray.cluster_resources().get("CPU", 0)
        while ray.available_resources().get("CPU", 0) < total and time.monotonic() - t_stop < 60:
            time.sleep(0.2)
        report["job_freed_s"] = round(time.monotonic() - t_stop, 1)
        say("job: stopped", report["job_stop_status"], "freed after", report["job_freed_s"])
        second_id = submit()
        say("job: resubmitted", second_id)
        report["job_status"] = wait(second_id, 240)
        logs = client.get_job_logs(second_id)
        report["job_s"] = round(time.monotonic() - t0, 1)
        report["job_first"], report["job"] = first, rows_of("job")
        report["job_err"] = logs[-3000:] if report["job_status"] != JobStatus.SUCCEEDED.value else ""
        report["job_stdout"] = logs[-1500:]

    ray.shutdown()
    cluster.shutdown()
    report["total_s"] = round(time.monotonic() - t_start, 1)
    print("REPORT " + json.dumps(report))


if __name__ == "__main__":
    main()
