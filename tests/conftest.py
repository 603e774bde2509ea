"""Shared fixtures. Pure tests never start Ray; Ray tests use the session-scoped cluster below."""

from __future__ import annotations

import importlib.util
import os
import shutil
import sys
import tempfile
from pathlib import Path
from types import ModuleType

import pytest

from fmctd_dist.device import torch_threads  # noqa: F401 - re-exported: tests do `from conftest import torch_threads`

os.environ.setdefault("MUJOCO_GL", "egl")
# before any test opens a GL context (ours or OGBench's own pixel env): Mesa's LLVM, loaded first, makes
# triton's import segfault later in the same worker (fmctd_dist/families/visual/env.py says more)
from fmctd_dist.families.visual.env import load_llvm_users_first  # noqa: E402

load_llvm_users_first()


def worker_threads() -> int:
    """Torch threads per test process: this machine's cores shared by the xdist workers (``-n 2`` in pyproject).

    Torch's default, one thread per core in each of two workers, puts 4 spinning threads on 2 cores, which
    makes every model call slower (``fmctd_dist.device.set_threads`` says why jobs run ``threads=1`` next
    to each other); the subprocesses tests start (jobs/*.py) inherit the count through ``OMP_NUM_THREADS``.
    """
    workers = max(1, int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")))
    return max(1, (os.cpu_count() or 1) // workers)


if "PYTEST_XDIST_WORKER" in os.environ:
    import torch

    torch.set_num_threads(worker_threads())
    os.environ.setdefault("OMP_NUM_THREADS", str(worker_threads()))

JOBS = Path(__file__).resolve().parent.parent / "jobs"


def uses_ray(item: pytest.Item) -> bool:
    """A test that needs the session Ray cluster: marked ``ray`` or asking for the ``ray_cluster`` fixture."""
    return item.get_closest_marker("ray") is not None or "ray_cluster" in getattr(item, "fixturenames", ())


RUN_DIR = "FMCTD_PYTEST_RUN_DIR"  # a folder the xdist controller and its workers share for one pytest run


def pytest_configure(config: pytest.Config) -> None:
    """The controller (or a run without xdist) makes the run's shared folder; workers inherit its path."""
    if "PYTEST_XDIST_WORKER" not in os.environ and RUN_DIR not in os.environ:
        os.environ[RUN_DIR] = tempfile.mkdtemp(prefix="fmctd-pytest-")
        config.add_cleanup(lambda: shutil.rmtree(os.environ.pop(RUN_DIR), ignore_errors=True))


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Each xdist worker lists the Ray tests it collected, for the controller's scheduler below."""
    worker = os.environ.get("PYTEST_XDIST_WORKER")
    if worker is not None and RUN_DIR in os.environ:
        ray_ids = [item.nodeid for item in items if uses_ray(item)]
        (Path(os.environ[RUN_DIR]) / f"ray-tests-{worker}.txt").write_text("\n".join(ray_ids))


@pytest.hookimpl(tryfirst=True, optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log):
    """``--dist loadgroup`` (pyproject's addopts): every Ray test in one worker, in turn; the rest load-balanced.

    One session cluster then serves them all (a second worker's cluster would contend for the
    dashboard agent's ports) and no two Ray tests share the 2 cores; pure tests fill the other worker.
    The Ray tests are known from the workers' lists (above), not from xdist's ``xdist_group`` node-id
    suffix, which pytest 9.2 no longer lets xdist 3.8 write (the Ray tests were spread over both workers).
    ``ray_cluster`` checks the result at run time (``claim_ray_worker``).
    """
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class RayGroupScheduling(LoadScopeScheduling):
        """One scope, "ray", for every Ray test; every other test is a scope of its own."""

        ray_ids: frozenset[str] | None = None

        def _split_scope(self, nodeid: str) -> str:
            if self.ray_ids is None:  # read once: every worker has written its list before it reports
                self.ray_ids = frozenset(line for f in Path(os.environ[RUN_DIR]).glob("ray-tests-*.txt")
                                         for line in f.read_text().splitlines())
            return "ray" if nodeid in self.ray_ids else nodeid

    return RayGroupScheduling(config, log)


def claim_ray_worker(run_dir: Path, worker: str) -> None:
    """Record that ``worker`` owns the session Ray cluster; raise if another xdist worker started one too.

    ``run_dir`` is the folder every worker of one pytest run shares. This checks the grouping by its
    effect, one worker for every Ray test, not by how xdist was told.
    """
    owner = run_dir / "ray-cluster-worker"
    try:
        with open(owner, "x") as f:
            f.write(worker)
    except FileExistsError:
        first = owner.read_text()
        if first != worker:
            raise RuntimeError(f"Ray tests ran on two xdist workers ({first} and {worker}): the Ray group's "
                               "scheduler did not apply (tests/conftest.py, pytest_xdist_make_scheduler)") from None


def job_path(name: str) -> Path:
    """jobs/<name>.py, or jobs/<folder>/<name>.py for the benchmarks, figures, probes and GPU tools."""
    found = sorted(JOBS.glob(f"{name}.py")) + sorted(JOBS.glob(f"*/{name}.py"))
    if not found:
        raise FileNotFoundError(f"no job script {name}.py under {JOBS}")
    return found[0]


def with_words(base: list[str], *extra: str) -> list[str]:
    """``base`` with each ``extra`` word replacing base's word of the same key (config loaders refuse a key
    given twice)."""
    keys = {w.split("=", 1)[0] for w in extra}
    return [w for w in base if w.split("=", 1)[0] not in keys] + list(extra)


def load_job(name: str) -> ModuleType:
    """A script under jobs/ or one of its folders (not a package) imported as a module, so tests call its
    functions. Its folder goes on sys.path, as when Python runs it, so its imports of sibling scripts resolve."""
    path = job_path(name)
    if str(path.parent) not in sys.path:
        sys.path.insert(0, str(path.parent))
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory):
    """A small medium-maze dataset (8 train + 1 val episodes of 301 steps), generated once."""
    from fmctd_dist.config import load_config
    from fmctd_dist.families.maze.data import make_dataset

    root = tmp_path_factory.mktemp("data")
    cfg = load_config(TINY_DATA + [f"data.root={root}"], method="mctd")
    path, _ = make_dataset(cfg, progress=False)
    return cfg, path


@pytest.fixture
def one_torch_thread():
    with torch_threads(1):
        yield


TINY_DATA = ["env=pointmaze-medium", "data.episodes=8", "data.episode_steps=301",
             "env.horizon=100", "data.train_window=100"]


TINY_MODEL = ["model.width=32", "model.layers=2", "model.heads=2", "model.ff=64"]


@pytest.fixture(scope="session")
def tiny_checkpoint(tiny_dataset, tmp_path_factory):
    """A tiny dense (jump=1, 10 plan tokens) model trained 30 steps on the tiny dataset."""
    import torch

    from fmctd_dist.config import load_config
    from fmctd_dist.families.maze.data import load_dataset
    from fmctd_dist.data.windows import train_data
    from fmctd_dist.diffusion.train import train

    data_cfg, _ = tiny_dataset
    out = tmp_path_factory.mktemp("ckpt")
    args = tiny_args(data_cfg.data.root, out)
    cfg = load_config(args + ["train.max_steps=30", "train.batch_size=16", "train.ckpt_every=30",
                              "train.val_every=30", "train.val_batches=1"], method="mctd")
    with torch_threads(1):
        train(cfg, train_data(cfg, load_dataset(cfg)), out, progress=False)
    return args, out


def tiny_args(data_root, ckpt) -> list[str]:
    """Overrides that describe the tiny dataset + tiny checkpoint (for jobs run as subprocesses)."""
    return TINY_DATA + TINY_MODEL + [f"data.root={data_root}", f"checkpoint={ckpt}", "env.max_steps=100",
                                     "jump=1"]


@pytest.fixture(scope="session")
def ray_cluster():
    """ONE local Ray cluster for every ``@pytest.mark.ray`` test (2 logical CPUs, no dashboard).

    Always a fresh private cluster (address="local"), even when a `ray start` cluster runs on
    the machine. Token auth is off for it (RAY_AUTH_MODE=disabled), so a stale
    ~/.ray/auth_token from another run cannot break it. Yields the cluster's address, which
    subprocess tests pass on as RAY_ADDRESS.
    """
    import logging

    import ray

    from fmctd_dist.evaluation.ray_runner import local_cluster_env

    worker = os.environ.get("PYTEST_XDIST_WORKER")
    if worker is not None and RUN_DIR in os.environ:
        claim_ray_worker(Path(os.environ[RUN_DIR]), worker)
    local_cluster_env()  # workers at nice 0, as for a cluster jobs/eval.py starts
    before = os.environ.get("RAY_AUTH_MODE")
    os.environ["RAY_AUTH_MODE"] = "disabled"
    ray.init(address="local", num_cpus=2, include_dashboard=False, logging_level=logging.ERROR, log_to_driver=False)
    yield ray.get_runtime_context().gcs_address
    ray.shutdown()
    if before is None:
        os.environ.pop("RAY_AUTH_MODE", None)
    else:
        os.environ["RAY_AUTH_MODE"] = before
