"""The visual maze family's registry record: the point maze seen through a 64x64 chase camera."""

from fmctd_dist.families.visual.paper import VISUAL
from fmctd_dist.records import EnvSpec, Family, Table, keyed_by_env

VISUAL_ENVS = ("visual-pointmaze-medium", "visual-pointmaze-large")
VISUAL_METHODS = ("diffuser", "diffuser-replan", "diffusion-forcing", "mctd", "p-mctd", "s-mctd", "fast-mctd",
                  "mctd-replan", "fast-mctd-replan")  # the paper's row order

FAMILY = Family(
    name="visual",
    envs=tuple(EnvSpec(n, "visual-pointmaze", 8, "8-D VAE latent of a 64x64 chase-camera image",
                       env_fields=("warp_dense", "warp_sparse"))  # on estimated positions
               for n in VISUAL_ENVS),
    hooks="fmctd_dist.families.visual.hooks",
    data="fmctd_dist.families.visual.dataset",
    hint="The visual maze's code: python jobs/train_visual.py part=... env=visual-pointmaze-medium (VAE, "
         "latents, estimator, inverse dynamics); python jobs/train.py env=visual-pointmaze-medium jump=5; "
         "python jobs/eval.py env=visual-pointmaze-medium",
    # its own layout: each line's model and settings printed (docs/results.md, the visual maze table)
    tables=(Table("visual", VISUAL_ENVS, VISUAL_METHODS, keyed_by_env(VISUAL, "visual-pointmaze"), glance=False,
                  render="fmctd_dist.families.visual.table:visual_table"),),
)
