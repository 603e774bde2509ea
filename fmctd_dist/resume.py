"""Resumable training, written once for the five loops (planner, low-level policy, ant expert, VAE, heads).

Each loop saves ``train_state.pt`` (networks, optimisers, RNG states, step, clock, history, and what it
was trained on) at every checkpoint; rerunning the same command loads it, checks the config and data
(:func:`check_resume`) and continues, bitwise the uninterrupted run where the loop's RNGs allow. What a
step does, and what a finished or shipped dir means, stays in each loop.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Callable, Iterable

import numpy as np
import torch
from tqdm import tqdm

from fmctd_dist.artifacts import atomic_torch_save, module_state, torch_load_weights
from fmctd_dist.errors import CheckpointError
from fmctd_dist.hints import word

TRAIN_STATE_FILE = "train_state.pt"
SNAPSHOTS = "snapshots"  # <out>/snapshots/kNNN-stepSSSSSSS: loadable checkpoint dirs


def save_train_state(out_dir: str | Path, state: dict[str, Any]) -> None:
    """Write train_state.pt atomically (tensors and plain types only: it loads with weights_only=True)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    atomic_torch_save(state, out_dir / TRAIN_STATE_FILE)


def load_train_state(out_dir: str | Path) -> dict[str, Any] | None:
    """The resumable state in out_dir, or None if there is none."""
    path = Path(out_dir) / TRAIN_STATE_FILE
    if not path.exists():
        return None
    state = torch_load_weights(path, f"checkpoint {path.parent}", f"delete {path} to restart training from scratch")
    if not isinstance(state, dict):
        raise CheckpointError(f"checkpoint {path.parent}: {path.name} is not a training state (a "
                              f"{type(state).__name__}, not a dict); delete {path} to restart training from scratch")
    return state


def check_resume(out: Path, what: str, fresh: str, saved: dict[str, Any], now: dict[str, Any],
                 keys: Iterable[str] = (), data: Iterable[tuple[str, Any, Any]] = (),
                 data_fix: str = "use the data it started on") -> None:
    """A resumed run trains what the saved one trained, on the same data, or one CheckpointError.

    ``keys``: dotted config keys whose ``saved`` and ``now`` values must agree (fixed by setting the key
    back); ``data``: (what, saved digest, digest now), fixed by ``data_fix``; ``fresh``: the out dir's key.
    """
    for key in keys:
        have, want = _get(saved, key), _get(now, key)
        if have != want:
            raise CheckpointError(f"{out} holds a {what} run with {key}={have!r} but the config has {key}={want!r}; "
                                  f"set {word(key, have)} to continue it, or use a fresh {fresh} dir")
    for name, have, want in data:
        if have != want:
            raise CheckpointError(f"{out} holds a {what} run trained on {name} {str(have)[:16]} but it is now "
                                  f"{str(want)[:16]}; {data_fix}, or use a fresh {fresh} dir")


def _get(d: dict[str, Any], dotted: str) -> Any:
    for part in dotted.split("."):
        d = d[part]
    return d


class Clock:
    """A run's training time over all its runs: wall and CPU seconds, the segment since the last save folded
    in by :meth:`lap`. ``kind`` picks what a time budget counts: ``cpu`` stays fair between runs when other
    jobs share the cores (with one thread)."""

    def __init__(self, wall_s: float = 0.0, cpu_s: float = 0.0, kind: str = "wall"):
        self.wall_s, self.cpu_s, self.kind = float(wall_s), float(cpu_s), kind
        self.started = self._t = time.perf_counter()  # this call's start (a per-call budget reads it)
        self._c = time.process_time()

    def used(self) -> float:
        """Budget seconds so far, the current segment included."""
        if self.kind == "cpu":
            return self.cpu_s + time.process_time() - self._c
        return self.wall_s + time.perf_counter() - self._t

    def over(self, budget_s: float) -> bool:
        """The budget (0: none) is used up."""
        return 0 < budget_s <= self.used()

    def lap(self) -> float:
        """Fold the segment since the last lap into wall_s / cpu_s (at a save) -> the wall clock now."""
        now, cnow = time.perf_counter(), time.process_time()
        self.wall_s, self.cpu_s = self.wall_s + now - self._t, self.cpu_s + cnow - self._c
        self._t, self._c = now, cnow
        return now


def snapshot_due(out_dir: Path, every_s: float, used_s: float) -> str | None:
    """The name prefix ``kNNN`` of the snapshot owed at ``used_s`` budget-clock seconds (snapshot N
    covers N * every_s), or None if that one exists already or none is asked for. Read from the
    folder, so a resumed run neither repeats nor skips one."""
    if every_s <= 0 or used_s < every_s:
        return None
    k = f"k{int(used_s // every_s):03d}"
    return None if any((out_dir / SNAPSHOTS).glob(f"{k}-step*")) else k


class TrainRun:
    """One call of a training loop: its step, :class:`Clock`, history and progress bar, and the cadences every
    loop keeps (log, validate, checkpoint: every N steps and at the last step). The last step is ``max_steps``
    or the one that uses up ``budget_s`` seconds of the budget clock over all runs (0: no budget).

    ``saved``: what :meth:`state` wrote at the last save (or a fresh run's ``{"history": {...}}``);
    ``names``: the values :meth:`tick` is given, whose means :meth:`log` appends to ``history["train"]``.
    """

    def __init__(self, desc: str, max_steps: int, saved: dict[str, Any], budget_s: float = 0.0,
                 clock: str = "wall", progress: bool = True, names: tuple[str, ...] = ("loss",)):
        self.step, self.max_steps, self.budget_s, self.names = int(saved.get("step", 0)), max_steps, budget_s, names
        wall, cpu = float(saved.get("wall_time_s", 0.0)), saved.get("cpu_time_s")  # none saved: as the wall
        self.clock = Clock(wall, wall if cpu is None else float(cpu), clock)
        self.history: dict[str, Any] = saved["history"]
        self.bar = tqdm(total=max_steps, initial=self.step, disable=not progress, desc=desc, dynamic_ncols=True)
        self.last = self._ended()
        self._n, self._sums, self._t = 0, [0.0] * len(names), self.clock.started

    def _ended(self) -> bool:
        return self.step >= self.max_steps or self.clock.over(self.budget_s)

    def tick(self, *values: Any) -> None:
        """Count one step and its ``names`` values (floats, or tensors summed on their device until the log)."""
        self.step += 1
        self._n += 1
        self._sums = [s + v for s, v in zip(self._sums, values)]
        self.last = self._ended()

    def due(self, every: int) -> bool:
        """This step is a multiple of ``every`` (0: none) or the last."""
        return self.last or (every > 0 and self.step % every == 0)

    def log(self, **shown: float | None) -> list[float]:
        """Append [step, *means] since the last log to ``history["train"]`` and move the bar on, showing the
        means, the last validation value, ``shown`` (None: not yet) and steps/s -> the means."""
        now = time.perf_counter()
        means = [float(s) / self._n for s in self._sums]
        if means:
            self.history["train"].append([self.step, *means])
        val = self.history.get("val")
        post = {**dict(zip(self.names, means)), "val": val[-1][1] if val else None, **shown}
        self.bar.set_postfix({k: f"{v:.4g}" for k, v in post.items() if v is not None}
                             | {"steps_s": f"{self._n / (now - self._t):.1f}"}, refresh=False)
        self.bar.update(self._n)
        self._n, self._sums, self._t = 0, [0.0] * len(self.names), now
        return means

    def checkpoint(self, every: int, save: Callable[[], None]) -> bool:
        """At a checkpoint step (:meth:`due`): fold the clock's segment in (:meth:`Clock.lap`), then ``save()``
        -> whether it saved."""
        if not self.due(every):
            return False
        self.clock.lap()
        save()
        return True

    def state(self) -> dict[str, Any]:
        """The run's train_state fields, read back by the constructor."""
        return {"step": self.step, "wall_time_s": self.clock.wall_s, "cpu_time_s": self.clock.cpu_s,
                "history": self.history}

    def close(self) -> None:
        self.bar.close()


def stream_rng(*keys: int) -> np.random.Generator:
    """A loop's numpy RNG for one stream, e.g. (seed, BATCH_STREAM): streams of one seed never overlap."""
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(list(keys))))


def part_states(**parts: Any) -> dict[str, Any]:
    """train_state entries of a loop's stateful parts, by key: a numpy or torch generator's state, a module's
    weights (on the CPU), anything else's ``state_dict()`` (an optimiser)."""
    def state(part: Any) -> Any:
        if isinstance(part, np.random.Generator):
            return part.bit_generator.state
        if isinstance(part, torch.Generator):
            return part.get_state()
        return module_state(part) if isinstance(part, torch.nn.Module) else part.state_dict()

    return {k: state(part) for k, part in parts.items()}


def load_part_states(state: dict[str, Any], **parts: Any) -> None:
    """Put back what :func:`part_states` saved under each key."""
    for k, part in parts.items():
        if isinstance(part, np.random.Generator):
            part.bit_generator.state = state[k]
        elif isinstance(part, torch.Generator):
            part.set_state(state[k])
        else:
            part.load_state_dict(state[k])
