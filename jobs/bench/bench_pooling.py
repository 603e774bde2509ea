"""Pooled denoising side by side (issue 55): the same episodes with eval.in_flight=1 and with N trees in flight.

    python jobs/bench/bench_pooling.py env=pointmaze-medium methods=[s-mctd,mctd,fast-mctd] in_flight=8 \
        micro_batch=8 tasks=[1,2,3,4,5] seeds=[0,1] eval.threads=1 out=runs/bench/pooling

Per method, three arms run the grid in this process (``runner=local``, every row to ``<out>/<arm>``):
``alone`` (in_flight=1 at the method's own ray.micro_batch: today's default), ``alone@M`` (in_flight=1 at
``micro_batch``: what a fixed micro-batch costs a lone tree) and ``pooled`` (``in_flight`` episodes at once,
their jobs pooled at ``micro_batch``). Grid throughput is episodes per hour of wall time; rows are compared
bit for bit (plans, trajectories, outcomes) between ``pooled`` and ``alone@M`` (the contract: the same M gives
the same rows) and between ``pooled`` and ``alone``. ``alone_at_m=false`` skips the ``alone@M`` arm (slow for a
dense lone tree: every call padded to M jobs). Prints and writes ``<out>/pooling.md``.
"""

from __future__ import annotations

import time
from pathlib import Path

from fmctd_dist.cli import run
from fmctd_dist.config import load_config
from fmctd_dist.errors import ResultsError
from fmctd_dist.evaluation.grid import prepare, run_local
from fmctd_dist.evaluation.results import ResultStore
from fmctd_dist.families import hooks_for

SAME = ("success", "env_steps", "expansions", "plan_xy", "traj_xy", "traj_cubes", "plan_status")


def grid(words: list[str], out: Path, arm: str, in_flight: int, micro_batch: int | None) -> tuple[dict, float]:
    extra = [f"eval.out={out}", f"eval.run={arm}", f"eval.in_flight={in_flight}", "runner=local"]
    cfg = load_config(words + extra + ([f"ray.micro_batch={micro_batch}"] if micro_batch else []))
    store = ResultStore(cfg.eval.out, cfg.eval.run)
    if store.rows(cfg.method.name, cfg.env.name):  # a timing needs the whole grid run now, not resumed
        raise ResultsError(f"{out / arm} already holds rows; point out= at a fresh folder")
    t0 = time.perf_counter()
    rows = run_local(prepare(cfg, hooks_for), store, progress=True,
                     log=lambda s: None)
    return {(r["task"], r["seed"]): r for r in rows}, time.perf_counter() - t0


def same(a: dict, b: dict) -> str:
    if sorted(a) != sorted(b):
        return "other keys"
    diff = sum(any(k in r and r[k] != b[key].get(k) for k in SAME) for key, r in a.items())
    return "identical" if not diff else f"{diff} of {len(a)} differ"


def own_words(argv: list[str]) -> tuple[dict[str, str], list[str]]:
    """This bench's words (methods, in_flight, micro_batch, out) with their defaults, and the config's words."""
    mine = {"methods": "[s-mctd,mctd,fast-mctd]", "in_flight": "8", "micro_batch": "8", "out": "runs/bench/pooling",
            "alone_at_m": "true"}
    rest = []
    for a in argv:
        key, sep, value = a.partition("=")
        if sep and key in mine:
            mine[key] = value
        else:
            rest.append(a)
    return mine, rest


def main(argv: list[str]) -> int:
    mine, argv = own_words(argv)
    methods = [x.strip() for x in mine["methods"].strip("[]").split(",") if x.strip()]
    in_flight, m, out = int(mine["in_flight"]), int(mine["micro_batch"]), Path(mine["out"])
    lines = ["| method | episodes | alone: M, ep/h | alone@M=%d: ep/h | pooled (%d in flight, M=%d): ep/h | "
             "pooled / alone | pooled / alone@M | rows: pooled vs alone@M | pooled vs alone |" % (m, in_flight, m),
             "|---|---|---|---|---|---|---|---|---|"]
    for method in methods:
        words = [*argv, f"method={method}"]
        own_m = load_config(words).ray.micro_batch
        alone, t_alone = grid(words, out / method, "alone", 1, None)
        if own_m == m or mine["alone_at_m"] != "true":  # false: skip the slow arm (a lone dense tree at M=8)
            lone_m, t_lone_m = (alone, float("nan")) if own_m != m else (alone, t_alone)
        else:
            lone_m, t_lone_m = grid(words, out / method, f"alone-m{m}", 1, m)
        pooled, t_pooled = grid(words, out / method, f"pooled-{in_flight}-m{m}", in_flight, m)
        n = len(alone)
        rate = [3600 * n / t for t in (t_alone, t_lone_m, t_pooled)]
        skipped = t_lone_m != t_lone_m  # nan: the alone@M arm was skipped
        lone_rate, lone_ratio = ("–", "–") if skipped else (f"{rate[1]:.0f}", f"{rate[2] / rate[1]:.2f}x")
        lines.append(f"| {method} | {n} | M={own_m}, {rate[0]:.0f} | {lone_rate} | {rate[2]:.0f} | "
                     f"**{rate[2] / rate[0]:.2f}x** | {lone_ratio} | {'–' if skipped else same(pooled, lone_m)} | "
                     f"{same(pooled, alone)} |")
        print(lines[-1], flush=True)
    table = "\n".join(lines)
    out.mkdir(parents=True, exist_ok=True)
    (out / "pooling.md").write_text(table + "\n")
    print(table)
    return 0


if __name__ == "__main__":
    run(main)
