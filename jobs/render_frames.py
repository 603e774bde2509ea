"""Render the visual maze's VAE images: seeded subsets of the point maze's train and validation frames.

    python jobs/make_dataset.py env=pointmaze-medium                     # states + actions (once)
    python jobs/render_frames.py env=visual-pointmaze-medium             # 20,000 frames (visual.frames)
    python jobs/render_frames.py env=visual-pointmaze-large visual.frames=2000 visual.frames_seed=1
    python jobs/render_frames.py env=visual-pointmaze-medium visual.shadowsize=4096   # reference, 2-4x slower

Writes data/<env>-frames-seed<s>-n<N>-shadow<k>-data<seed>-<E>x<S>/ (frames.npz: N train frames and
N x data.val_fraction validation frames; manifest.json: seed, frame indices, dataset digests,
renderer, sha256); the same config writes the same bytes.
Rerunning verifies an existing directory instead of rendering again. Also prints which train
episodes the planner's latent data uses (visual.episodes, seeded; 0 = all).
"""

import time

from fmctd_dist.cli import run
from fmctd_dist.config import load_config
from fmctd_dist.families.visual.frame_sets import episode_subset, make_frames


def main(argv: list[str]) -> int:
    t0 = time.time()
    cfg = load_config(argv, env="visual-pointmaze-medium", method="mctd")
    path, m = make_frames(cfg)
    print(f"{path}: {m['frames']} train + {m['val_frames']} validation frames of {m['point_env']} "
          f"(seed {m['frames_seed']}), sha256={m['sha256']}")
    print(f"  dataset {m['dataset']['path']} (digest {m['dataset']['digest'][:16]})")
    print(f"  renderer: {m['render']['gl']}, shadowsize {m['render']['shadowsize']}; when made: "
          f"{m['generation']['frames_per_s']} frames/s")
    eps = episode_subset(cfg)
    print(f"  planner's latent data: {len(eps)} of {cfg.data.episodes} train episodes (visual.episodes="
          f"{cfg.visual.episodes}): {eps[:8].tolist()}{' ...' if len(eps) > 8 else ''}")
    print(f"done in {time.time() - t0:.1f}s")
    return 0


if __name__ == "__main__":
    run(main)
