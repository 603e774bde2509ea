"""Step by step through one cube episode's carry: where does the gripper lose the cube?

    python jobs/probes/probe_cube_grasp.py method=p-mctd-replan env=cube-single tasks=[4] seeds=[1]
    python jobs/probes/probe_cube_grasp.py method=fast-mctd-replan env=cube-single tasks=[4] seeds=[1] steps=8:45

Runs the episode in process exactly as jobs/eval.py does (same plans, same row) while recording what
the low-level policy saw and did at each of its steps: the gripper opening and contact flag of the
observation, effector and target cube xyz, the subgoal, and the 5-D action (xyz, yaw, gripper). A
``dropped`` row (families/cube/failures.py) says the cube came down away from its goal; this says
at which policy step contact was lost and what the arm was doing then. ``steps=A:B`` picks the
policy steps printed (default: all). Prints one line per policy step, then the row's outcome.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fmctd_dist.cli import run
from fmctd_dist.config import load_config
from fmctd_dist.families.cube.scripts import EFFECTOR
from fmctd_dist.denoiser.local import LocalDenoiser
from fmctd_dist.device import set_threads
from fmctd_dist.diffusion.checkpoint import normaliser_from_manifest, read_manifest
from fmctd_dist.errors import ConfigError
from fmctd_dist.evaluation.grid import prepare
from fmctd_dist.families import hooks_for
from fmctd_dist.planners import make_planner

GRIP, CONTACT = 17, 18  # the arm observation's gripper opening and contact flag (docs/reference.md §13)
CUBE_XYZ = slice(19, 22)  # the policy's one-cube view: the target cube's xyz after the arm's 19 numbers


def parse_steps(text: str) -> slice:
    a, sep, b = text.partition(":")
    try:
        return slice(int(a) if a else None, int(b) if b else None) if sep else slice(int(a), int(a) + 1)
    except ValueError:
        raise ConfigError(f"probe_cube_grasp: steps={text!r} is not A:B (policy step indices, e.g. steps=8:45)") \
            from None


def main(argv: list[str]) -> int:
    steps, rest = slice(None), []
    for a in argv:
        if a.startswith("steps="):
            steps = parse_steps(a.split("=", 1)[1])
        else:
            rest.append(a)
    cfg = load_config(rest)
    if len(cfg.eval.tasks) != 1 or len(cfg.eval.seeds) != 1:
        raise ConfigError("probe_cube_grasp: give one episode, e.g. tasks=[4] seeds=[1]")
    p = prepare(cfg, hooks_for)
    set_threads(cfg.eval.threads)
    denoiser = LocalDenoiser.from_checkpoint(p.checkpoint, cfg, expect_digest=p.checkpoint_digest)
    planner = make_planner(cfg, denoiser, normaliser_from_manifest(read_manifest(p.checkpoint)), p.plan_rules(cfg))
    episodes = p.episodes(cfg)
    policy = episodes.policy
    seen: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    def recorded(view: np.ndarray, subgoal: np.ndarray) -> Any:
        action = policy(view, subgoal)
        seen.append((np.array(view, np.float64), np.array(subgoal, np.float64), np.array(action, np.float64)))
        return action

    episodes.policy = recorded  # the episode calls the policy through this attribute
    row = episodes.run(planner, cfg.eval.tasks[0], cfg.eval.seeds[0])
    fmt = {"float_kind": lambda v: f"{v:5.2f}"}
    for k, (view, sub, act) in list(enumerate(seen))[steps]:
        print(f"policy step {k:3d}: grip {view[GRIP]:4.2f} contact {view[CONTACT]:.0f} effector "
              f"{np.array2string(view[EFFECTOR], formatter=fmt)} cube {np.array2string(view[CUBE_XYZ], formatter=fmt)} "
              f"subgoal {np.array2string(sub, formatter=fmt)} action {np.array2string(act, formatter=fmt)}")
    lost = [k for k in range(1, len(seen)) if seen[k - 1][0][CONTACT] > 0.5 >= seen[k][0][CONTACT]]
    print(f"{cfg.method.name} {cfg.env.name} task {row['task']} seed {row['seed']}: "
          f"{'success' if row['success'] else 'failure (' + row['why_failed'] + ')'} after {row['env_steps']} steps, "
          f"{len(seen)} policy steps; contact lost at policy steps {lost or 'never'}")
    return 0


if __name__ == "__main__":
    run(main)
