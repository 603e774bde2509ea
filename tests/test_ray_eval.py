"""The Ray eval job end to end: resume without duplicates, the Python entry point, one readable
error per bad input, actor-side errors as our own classes, and `ray job submit` on a fresh head."""

from __future__ import annotations

import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import pyarrow.parquet as pq
import pytest
import torch

from fmctd_dist.config import REPO_ROOT, load_config
from fmctd_dist.errors import CheckpointError
from fmctd_dist.evaluation.grid import prepare
from fmctd_dist.families import hooks_for

pytestmark = [pytest.mark.ray, pytest.mark.usefixtures("one_torch_thread")]

SEARCH = ["method=p-mctd", "method.parallel=8", "method.budget=24", "method.early_stop=false",
          "method.warp_threshold=1000"]
ROWS = "p-mctd/pointmaze-medium/task=*/seed=*.parquet"



def eval_job(args, env=None, **kw):
    return subprocess.Popen([sys.executable, "jobs/eval.py", "runner=ray", *args], cwd=REPO_ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)


def keys(root: Path) -> list[tuple[str, str]]:
    return sorted((f.parent.name, f.name) for f in root.glob(ROWS))


def test_evaluate_entry_point_resumes_without_duplicates(tiny_checkpoint, ray_cluster, tmp_path):
    from fmctd_dist.evaluation.ray_runner import evaluate

    args, _ = tiny_checkpoint
    base = args + SEARCH + [f"eval.out={tmp_path}", "eval.run=r", "tasks=[2]"]
    rows = evaluate(base + ["seeds=[0]"], hooks_for, progress=False)
    assert [(r["task"], r["seed"]) for r in rows] == [(2, 0)]
    row = rows[0]
    assert row["n_denoiser_actors"] == 2 and row["retries"] == 0  # auto: one per CPU of the 2-CPU cluster
    assert row["device"] == "cpu"
    assert row["expansions"] > 0 and 0 < row["denoise_time_s"] <= row["plan_time_s"]
    first = tmp_path / "r/p-mctd/pointmaze-medium/task=2/seed=0.parquet"
    mtime = first.stat().st_mtime_ns
    # an interrupted write of seed 1 leaves only a *.tmp; the rerun must redo it, and only it
    (first.parent / "seed=1.parquet.tmp").write_bytes(b"half a file")
    rows = evaluate(base + ["seeds=[0,1]"], hooks_for, progress=False)
    assert sorted((r["task"], r["seed"]) for r in rows) == [(2, 0), (2, 1)]
    assert first.stat().st_mtime_ns == mtime
    assert keys(tmp_path / "r") == [("task=2", "seed=0.parquet"), ("task=2", "seed=1.parquet")]
    assert not list(tmp_path.rglob("*.tmp"))


def test_job_killed_after_first_row_resumes(tiny_checkpoint, ray_cluster, tmp_path):
    """SIGKILL the job process once a row exists; the rerun finishes the grid, one row per key."""
    args, _ = tiny_checkpoint
    env = {**os.environ, "RAY_ADDRESS": ray_cluster}
    job_args = args + SEARCH + [f"eval.out={tmp_path}", "eval.run=k", "tasks=[1,3,4]", "seeds=[0]",
                                "ray.env_actors=1"]
    proc = eval_job(job_args, env=env)
    deadline = time.monotonic() + 300  # returns at the first row; long only for a loaded machine
    while not list(tmp_path.glob("k/" + ROWS)) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.2)
    proc.send_signal(signal.SIGKILL)
    proc.communicate()
    done = keys(tmp_path / "k")
    assert 1 <= len(done) <= 3
    again = eval_job(job_args, env=env)
    out, err = again.communicate(timeout=300)
    assert again.returncode == 0, err
    assert keys(tmp_path / "k") == [(f"task={t}", "seed=0.parquet") for t in (1, 3, 4)]
    assert "| p-mctd | pointmaze-medium | 3 |" in out
    rows = [pq.read_table(f).to_pylist()[0] for f in (tmp_path / "k").glob(ROWS)]
    assert len({(r["task"], r["seed"]) for r in rows}) == 3


def corrupt_checkpoint(tmp_path, ckpt):
    bad = tmp_path / "corrupt"
    shutil.copytree(ckpt, bad)
    data = bytearray((bad / "model.pt").read_bytes())
    data[len(data) // 2] ^= 0xFF
    (bad / "model.pt").write_bytes(bytes(data))
    return [f"checkpoint={bad}"]


BAD = [  # (extra overrides, text the message must contain)
    (["method=fast-mctdd"], "fast-mctd"),
    ("missing", "checkpoint"),
    (["env=pointmaze-large"], "env"),
    (["device=cuda"], "device"),
    (["ray.denoiser_actors=-1"], "ray.denoiser_actors"),
    (["ray.env_actors=-1"], "ray.env_actors"),
    (["ray.micro_batch=0"], "ray.micro_batch"),
    (["tasks=[9]"], "eval.tasks"),
    (["seeds=[-1]"], "eval.seeds"),
    ("corrupt", "corrupt"),
    (["ray.num_gpus=1"], "ray.num_gpus"),
    (["ray.max_restarts=-1"], "ray.max_restarts"),
    (["device=auto", "ray.num_gpus=1"], "GPU"),  # only the cluster can tell: checked after ray.init
]


@pytest.mark.parametrize("extra, message", BAD, ids=[str(b[0]) for b in BAD])
def test_bad_input_is_one_readable_error(tiny_checkpoint, ray_cluster, tmp_path, extra, message):
    if "device=cuda" in extra or "device=auto" in extra:
        if torch.cuda.is_available():
            pytest.skip("a GPU is present")
    args, ckpt = tiny_checkpoint
    if extra == "missing":
        extra = [f"checkpoint={tmp_path}/nothing"]
    elif extra == "corrupt":
        extra = corrupt_checkpoint(tmp_path, ckpt)
    proc = eval_job(args + SEARCH + [f"eval.out={tmp_path}/res", "tasks=[1]", "seeds=[0]"] + extra,
                    env={**os.environ, "RAY_ADDRESS": ray_cluster})
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 2, err
    assert err.startswith("error: ") and message in err, err
    assert "Traceback" not in err and "RayTaskError" not in err
    assert not list(tmp_path.rglob("*.parquet"))


def test_actor_side_error_keeps_its_class(tiny_checkpoint, ray_cluster):
    """A checkpoint that changed after prepare() fails inside the actors: the user gets CheckpointError."""
    import dataclasses

    from fmctd_dist.denoiser.ray_pool import DenoiserPool

    args, _ = tiny_checkpoint
    p = prepare(load_config(args + SEARCH), hooks_for)
    with pytest.raises(CheckpointError, match="differs from the expected"):
        DenoiserPool.create(dataclasses.replace(p, checkpoint_digest="0123456789abcdef"), 1)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def readme_submit_command() -> str:
    """The README's ``ray job submit`` command, word for word (the bash block after its test marker)."""
    text = (REPO_ROOT / "README.md").read_text()
    block = text.split("<!-- tested: tests/test_ray_eval.py::test_ray_job_submit -->", 1)[1]
    block = block.split("```bash\n", 1)[1].split("```", 1)[0]
    command = block[block.index("ray job submit"):].replace("\\\n", " ")
    return command.splitlines()[0].strip()


def test_ray_job_submit(ray_cluster, tmp_path):
    """`ray start --head` + the README's `ray job submit` command, run word for word by bash, prints the table.

    The command uploads only the checkpoints the job reads (jobs/runtime_env.py): under Ray's 100 MiB
    limit whatever the repository ships. Token auth is on, with the token in RAY_AUTH_TOKEN for both
    commands: a stale ~/.ray/auth_token cannot make them disagree. The head runs with --block under this
    test and is stopped by signalling that process (not `ray stop`, which would stop every Ray cluster
    on the machine, the session one included); it listens on free ports, named by RAY_ADDRESS as the
    README's `export RAY_ADDRESS=...` line does.
    """
    command = readme_submit_command()
    assert "--runtime-env-json \"$(python jobs/runtime_env.py" in command, command
    port, dash, agent, agent_grpc, metrics = (free_port() for _ in range(5))
    temp = tempfile.mkdtemp(prefix="rj", dir="/tmp")  # short: Ray's socket paths must stay < 108 chars
    token = secrets.token_hex(32)
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
    env.update(RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=token, RAY_ADDRESS=f"http://127.0.0.1:{dash}")
    env["PATH"] = f"{Path(sys.executable).parent}:{env.get('PATH', '')}"  # this venv's python and ray first
    out = REPO_ROOT / "results" / "submitted"  # the README's eval.out and eval.run: a user's rows there are kept
    kept = tmp_path / "kept"
    if out.exists():
        shutil.move(out, kept)
    head = subprocess.Popen(["ray", "start", "--head", "--block", f"--port={port}", f"--dashboard-port={dash}",
                             "--dashboard-host=127.0.0.1", "--num-cpus=2", f"--temp-dir={temp}",
                             # not the default agent ports: the session cluster of the other tests holds them
                             f"--dashboard-agent-listen-port={agent}", f"--dashboard-agent-grpc-port={agent_grpc}",
                             f"--metrics-export-port={metrics}",
                             "--disable-usage-stats"],
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 300  # returns at the first row; long only for a loaded machine
        while True:
            try:
                req = urllib.request.Request(f"{env['RAY_ADDRESS']}/api/version",
                                             headers={"Authorization": f"Bearer {token}"})
                json.load(urllib.request.urlopen(req, timeout=5))
                break
            except OSError:
                assert head.poll() is None and time.monotonic() < deadline, "ray head did not come up"
                time.sleep(1)
        deadline = time.monotonic() + 60
        for _ in range(30):  # the dashboard answers before the head's job agent is up
            sub = subprocess.run(["bash", "-c", command], cwd=REPO_ROOT, env=env, capture_output=True, text=True,
                                 timeout=300)
            if "No available agent" not in sub.stderr or time.monotonic() > deadline:
                break
            time.sleep(2)
        log = sub.stdout + sub.stderr
        assert sub.returncode == 0, sub.stdout[-3000:] + sub.stderr[-3000:]
        assert "succeeded" in log and "| fast-mctd |" in log, log[-3000:]  # the job's table, tailed by ray
        files = list(out.glob("fast-mctd/pointmaze-medium/task=*/seed=*.parquet"))
        assert len(files) == 1
        row = pq.read_table(files[0]).to_pylist()[0]
        assert (row["task"], row["seed"]) == (1, 0) and row["n_denoiser_actors"] >= 1
    finally:
        os.killpg(head.pid, signal.SIGTERM)
        try:
            head.wait(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(head.pid, signal.SIGKILL)
        shutil.rmtree(temp, ignore_errors=True)
        shutil.rmtree(out, ignore_errors=True)
        if kept.exists():
            shutil.move(kept, out)


def test_the_job_uploads_only_the_checkpoints_it_reads():
    """Each family's default job reads its planner and its robot's parts, and the upload stays small."""
    from fmctd_dist.evaluation.job_upload import checkpoints_read, runtime_env, upload_bytes

    assert checkpoints_read(load_config([]), hooks_for) == ["checkpoints/pointmaze-medium-h5"]
    ant = load_config(["env=antmaze-large"])
    assert checkpoints_read(ant, hooks_for) == ["checkpoints/antmaze-large-h5", "checkpoints/antmaze-large-policy"]
    cube = load_config(["env=cube-double", "method=fast-mctd-replan"])
    assert checkpoints_read(cube, hooks_for) == ["checkpoints/cube-double-h5", "checkpoints/cube-single-policy"]
    env = runtime_env(load_config([]), hooks_for)
    assert "/checkpoints/*" in env["excludes"] and env["excludes"][-1] == "!/checkpoints/pointmaze-medium-h5"
    assert upload_bytes(REPO_ROOT, env) < 50 * 2**20  # Ray refuses over 100 MiB


def test_a_broken_job_fails_before_anything_is_uploaded(tmp_path):
    with pytest.raises(CheckpointError):
        from fmctd_dist.evaluation.job_upload import runtime_env

        runtime_env(load_config([f"checkpoint={tmp_path / 'nothing'}"]), hooks_for)


def test_address_local_starts_a_private_cluster_at_nice_0(monkeypatch):
    """`ray.address=local` starts a fresh cluster of ours: its workers at nice 0 (Ray's default 15 starved the
    denoiser actors beside two training jobs), no dashboard, and the caller shuts it down."""
    from fmctd_dist.evaluation import ray_runner

    calls = []
    monkeypatch.delenv("RAY_worker_niceness", raising=False)
    monkeypatch.setattr(ray_runner.ray, "is_initialized", lambda: False)
    monkeypatch.setattr(ray_runner.ray, "init", lambda **kw: calls.append(kw))
    assert ray_runner.connect("local") is True
    assert calls[0]["address"] == "local" and calls[0]["include_dashboard"] is False
    assert os.environ["RAY_worker_niceness"] == "0"
