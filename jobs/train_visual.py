"""Train the visual maze's pre-trained parts, in order: VAE, episode frames, latents, estimator, inverse dynamics.

    python jobs/render_frames.py env=visual-pointmaze-medium                 # the VAE's frames (once)
    python jobs/train_visual.py part=vae env=visual-pointmaze-medium         # -> checkpoints/<env>-vae
    python jobs/train_visual.py part=episodes env=visual-pointmaze-medium visual.episodes=20  # render whole episodes
    python jobs/train_visual.py part=latents env=visual-pointmaze-medium visual.episodes=20   # encode them
    python jobs/train_visual.py part=estimator env=visual-pointmaze-medium   # z -> (x, y)
    python jobs/train_visual.py part=invdyn env=visual-pointmaze-medium visual.episodes=20    # (z-, z, z+) -> a
    python jobs/train_visual.py part=reach env=visual-pointmaze-medium visual.episodes=20     # closed-loop reach rate

Each part is resumable (rerun the same command) and bounded by ``<part>.time_budget_s`` of
training wall time; ``vae.*``, ``latents.*``, ``estimator.*``, ``invdyn.*`` and ``reach.*`` are this job's own
config (fmctd_dist/families/visual/config.py), everything else the planner's.
"""

import json
import time

from fmctd_dist.cli import run
from fmctd_dist.families.visual.config import load_parts_args


def main(argv: list[str]) -> int:
    t0 = time.time()
    cfg, pcfg, part = load_parts_args(argv)
    if part == "vae":
        from fmctd_dist.families.visual.train_vae import train_vae

        summary = train_vae(cfg, pcfg)
    elif part == "episodes":
        from fmctd_dist.families.visual.episodes import make_episodes

        path, m = make_episodes(cfg, pcfg)
        summary = {"out_dir": str(path), "episodes": len(m["episodes"]), "val_episodes": len(m["val_episodes"]),
                   "frames_digest": m["frames_digest"], "generation": m["generation"]}
    elif part == "latents":
        from fmctd_dist.families.visual.latents import make_latents

        path, m = make_latents(cfg, pcfg)
        summary = {"out_dir": str(path), "episodes": len(m["episodes"]), "val_episodes": len(m["val_episodes"]),
                   "frames": m["frames"], "sha256": m["sha256"], "generation": m["generation"]}
    elif part == "reach":
        from fmctd_dist.families.visual.reach import run_reach

        summary = run_reach(cfg, pcfg)
    else:
        from fmctd_dist.families.visual.train_head import train_head

        summary = train_head(cfg, pcfg, part)
    print(json.dumps(summary, indent=1, default=str))
    print(f"done in {time.time() - t0:.1f}s")
    return 0


if __name__ == "__main__":
    run(main)
