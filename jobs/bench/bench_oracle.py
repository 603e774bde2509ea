"""Steps the noisy oracle needs to reach each evaluation goal (a sanity check on env + oracle).

    python jobs/bench/bench_oracle.py            # all mazes, tasks 1-5, noise 0.5 and 0, seed 0

Prints a Markdown table; the paper's budgets are 500/500/1000 env steps.
"""

import sys

import numpy as np

from fmctd_dist.cli import run
from fmctd_dist.families.maze.oracle import NoisyOracle
from fmctd_dist.families.maze.make import make_env

BUDGET = {"pointmaze-medium": 500, "pointmaze-large": 500, "pointmaze-giant": 1000}


def steps_to_goal(env, oracle, task: int, seed: int, limit: int = 3000) -> int | None:
    r = env.reset(task, seed)
    rng = np.random.default_rng(seed)
    pos = r.obs
    for t in range(limit):
        pos, success = env.step(oracle.act(pos, r.goal, rng))
        if success:
            return t + 1
    return None


def main(seeds: list[int]) -> None:
    print("| maze | oracle noise | budget | task 1 | task 2 | task 3 | task 4 | task 5 |")
    print("|---|---|---|---|---|---|---|---|")
    for name, budget in BUDGET.items():
        env = make_env(name)
        for noise in (0.5, 0.0):
            oracle = NoisyOracle(env.geometry, noise)
            cells = []
            for task in range(1, 6):
                steps = [steps_to_goal(env, oracle, task, s) for s in seeds]
                cells.append("/".join("never" if s is None else str(s) for s in steps))
            print(f"| {name} | {noise} | {budget} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    run(lambda argv: main([int(s) for s in argv] or [0]))
