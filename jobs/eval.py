"""Evaluate a planner on an env's task x seed grid (mazes, cubes); one Parquet row per episode, resumable.

    python jobs/eval.py                                         # embedded default (see README)
    python jobs/eval.py method=fast-mctd env=pointmaze-medium runner=local tasks=[1] seeds=[0]
    python jobs/eval.py method=p-mctd env=pointmaze-giant eval.run=giant eval.episode_time_limit=120

Everything is validated before any episode (or Ray actor) starts; rerunning an interrupted
evaluation only runs the missing (task, seed) keys. Prints the paper-style table at the end
and writes it to <eval.out>/<eval.run>/summary.md, with summary.png (success vs planning
time) and <method>/<env>/episode.png (the first episode's plan and trajectory, in the env family's picture).
"""

import time

from fmctd_dist.cli import run
from fmctd_dist.config import load_config
from fmctd_dist.evaluation.grid import prepare, run_local
from fmctd_dist.evaluation.plots import plot_success_vs_time
from fmctd_dist.evaluation.results import ResultStore, markdown_table, summarise
from fmctd_dist.families import hooks_for


def main(argv: list[str]) -> int:
    t0 = time.time()
    cfg = load_config(argv)
    prepared = prepare(cfg, hooks_for)  # config, device, checkpoint: all checked here
    store = ResultStore(cfg.eval.out, cfg.eval.run)
    if cfg.eval.runner == "local":
        run_local(prepared, store)
    else:
        from fmctd_dist.evaluation.ray_runner import run_ray

        run_ray(prepared, store)
    keys = {(t, s) for t in cfg.eval.tasks for s in cfg.eval.seeds}
    rows = [r for r in store.rows(cfg.method.name, cfg.env.name) if (r["task"], r["seed"]) in keys]
    summary = summarise(rows)
    table = markdown_table(summary)
    (store.root / "summary.md").write_text(table + "\n")
    plot_success_vs_time(summary, store.root / "summary.png")
    if rows:
        first = min(rows, key=lambda r: (r["task"], r["seed"]))
        hooks_for(cfg.env.name).plot_episode(first, store.root / cfg.method.name / cfg.env.name / "episode.png")
    print(table)
    print(f"{len(rows)} episodes in {store.root}; wall time {time.time() - t0:.1f}s")
    return 0


if __name__ == "__main__":
    run(main)
