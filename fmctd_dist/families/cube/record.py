"""The cube family's registry record: OGBench cube-single, -double and -triple with the robot arm."""

from fmctd_dist.families.cube.paper import CUBE
from fmctd_dist.records import EnvSpec, Family, Table, keyed_by_env

CUBE_TYPES = ("single", "double", "triple")  # OGBench CubeEnv env_type
CUBE_ENVS = tuple(f"cube-{c}" for c in CUBE_TYPES)
# the paper's robot table: the replanning searches only, in its order
METHODS = ("diffuser", "diffuser-replan", "diffusion-forcing", "mctd-replan", "p-mctd-replan", "s-mctd-replan",
           "fast-mctd-replan")
# the env fields only cubes read (the maze families replan on method.replan_every and use method.warp_threshold)
CUBE_FIELDS = ("policy", "replan_every", "warp_dense", "warp_sparse", "object_scales", "preposition_yaw",
               "start_tolerance")

FAMILY = Family(
    name="cube",
    envs=tuple(EnvSpec(n, "cube", 3 * (i + 1), f"xyz of {i + 1} cube(s) in obs units",
                       policy="fmctd_dist.families.cube.policy_hooks:CubeHooks", env_fields=CUBE_FIELDS)
               for i, n in enumerate(CUBE_ENVS)),
    hooks="fmctd_dist.families.cube.hooks",
    data="fmctd_dist.families.cube.data",
    hint="The cube code: python jobs/make_dataset.py env=cube-single; python jobs/train.py env=cube-single "
         "jump=5; python jobs/train_policy.py env=cube-single; python jobs/eval.py env=cube-single",
    tables=(Table("robot", CUBE_ENVS, METHODS, keyed_by_env(CUBE, "cube"),
                  columns=tuple(f"cube {c}" for c in CUBE_TYPES)),),
)
