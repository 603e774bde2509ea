"""Probe: does the visual planner hold its plan to its context, given a start like its training data's?

    python jobs/probes/visual_context_probe.py                                   # the shipped medium H=5 model
    python jobs/probes/visual_context_probe.py visual.episodes=100 \
        checkpoint=runs/visual/visual-pointmaze-medium-h5-e100
    python jobs/probes/visual_context_probe.py env=visual-pointmaze-large visual.episodes=100  # shipped large
    python jobs/probes/visual_context_probe.py visual.episodes=100 jump=1 checkpoint=<a dense (H=1) latent model>

Every searched plan of docs/results.md 13.4 starts 3-8 estimated units from its start frame, where
the point moves at most 1.0 in 5 env steps. Either the model ignores its context token, or the start
frames encoded at an episode's reset are unlike the frames it was trained on. This samples one
unguided Diffusion Forcing plan (no search, ``method.guidance_scale=0``) from two kinds of start:

- **validation**: a seeded frame of the latent store's held-out episodes (a real latent, as in
  training), with the same episode's latent 495 steps later as the goal;
- **reset**: the start and goal frames of tasks 1-5, encoded as an episode encodes them.

and prints, per kind, the first plan frame's distance from the start (estimated world units and
normalised latent units) beside the recorded next frame's (validation only), each plan's
largest estimated step and how often it falls at a token boundary, and the median step into the
first frame of a token (a boundary) and into the other frames.
"""

from __future__ import annotations

import numpy as np

from fmctd_dist.cli import run
from fmctd_dist.device import set_threads
from visual_plan_quality import probe_config, task_frames, visual_planner

WINDOWS = 20  # validation starts


def main(argv: list[str]) -> int:
    from fmctd_dist.families.visual.dataset import load_visual_dataset

    cfg = probe_config(argv)
    set_threads(cfg.eval.threads or 1)
    planner, episodes, manifest, norm = visual_planner(cfg)
    pos, jump = episodes.frames, cfg.jump
    val = load_visual_dataset(cfg).val  # [E, S, D] the held-out episodes' planner frames
    span = cfg.env.horizon - jump
    rng = np.random.default_rng(0)
    starts = []  # (kind, start z, goal z, recorded next z or None)
    for _ in range(WINDOWS):
        e, t = int(rng.integers(len(val))), int(rng.integers(val.shape[1] - span))
        starts.append(("validation", val[e, t], val[e, t + span], val[e, t + jump]))
    for task in cfg.eval.tasks:
        starts.append(("reset", *task_frames(episodes, task), None))
    stats: dict[str, dict[str, list[float]]] = {}
    for i, (kind, z, zg, nxt) in enumerate(starts):
        plan = planner.plan(z, zg, i).waypoints[::jump]  # [F, D] one frame per plan step
        xy = pos(np.concatenate([z[None], plan]))
        s = stats.setdefault(kind, {"first": [], "first_z": [], "largest": [], "real": [], "real_z": [],
                                    "boundary": [], "inside": [], "largest_at_boundary": []})
        s["first"].append(float(np.linalg.norm(xy[1] - xy[0])))
        s["first_z"].append(float(np.linalg.norm(norm.normalise(plan[:1]) - norm.normalise(z[None]))))
        steps = np.linalg.norm(np.diff(xy, axis=0), axis=-1)  # [F] step into plan frame k
        at_boundary = np.arange(len(steps)) % cfg.model.frame_stack == 0  # the first frame of a token
        s["largest"].append(float(steps.max()))
        s["largest_at_boundary"].append(float(at_boundary[int(steps.argmax())]))
        s["boundary"].append(float(np.median(steps[at_boundary])))
        s["inside"].append(float(np.median(steps[~at_boundary])))
        if nxt is not None:
            s["real"].append(float(np.linalg.norm(pos(nxt[None])[0] - xy[0])))
            s["real_z"].append(float(np.linalg.norm(norm.normalise(nxt[None]) - norm.normalise(z[None]))))
    print(f"{cfg.checkpoint_dir()} ({manifest['digest']}, {manifest.get('train_steps')} steps); "
          f"unguided DF, jump {jump}")
    print("| start | plans | first plan step: estimated units / latent units | recorded next frame: estimated / latent "
          "| largest estimated step | plans whose largest step is at a token boundary "
          "| median step at token boundaries / inside tokens |\n|---|---|---|---|---|---|---|")
    for kind, s in stats.items():
        real = (f"{np.median(s['real']):.2f} / {np.median(s['real_z']):.2f}" if s["real"] else "–")
        print(f"| {kind} | {len(s['first'])} | {np.median(s['first']):.2f} / {np.median(s['first_z']):.2f} | {real} | "
              f"{np.median(s['largest']):.2f} | {np.mean(s['largest_at_boundary']):.0%} | "
              f"{np.median(s['boundary']):.2f} / {np.median(s['inside']):.2f} |")
    return 0


if __name__ == "__main__":
    run(main)
