"""The maze family's registry record: PointMaze and AntMaze, medium / large / giant."""

from fmctd_dist.families.maze.paper import ANTMAZE, POINTMAZE
from fmctd_dist.records import EnvSpec, Family, Table, keyed_by_env

MAZES = ("medium", "large", "giant")
POINT_ENVS = tuple(f"pointmaze-{m}" for m in MAZES)
ANT_ENVS = tuple(f"antmaze-{m}" for m in MAZES)
MAZE_KINDS = ("pointmaze", "antmaze")
# the paper's maze tables, in its order
METHODS = ("diffuser", "diffuser-replan", "diffusion-forcing", "mctd", "p-mctd", "s-mctd", "fast-mctd")

FAMILY = Family(
    name="maze",
    envs=(*(EnvSpec(n, "pointmaze", 2, "x, y") for n in POINT_ENVS),
          *(EnvSpec(n, "antmaze", 2, "torso x, y", policy="fmctd_dist.families.maze.ant_policy_hooks:AntHooks",
                    env_fields=("policy",))
            for n in ANT_ENVS)),
    hooks="fmctd_dist.families.maze.hooks",
    data="fmctd_dist.families.maze.data",
    hint="The maze code: python jobs/make_dataset.py env=pointmaze-medium; python jobs/train.py "
         "env=pointmaze-medium jump=5; python jobs/eval.py env=pointmaze-medium",
    tables=(Table("maze", POINT_ENVS, METHODS, keyed_by_env(POINTMAZE, "pointmaze"),
                  columns=tuple(f"point {m}" for m in MAZES)),
            Table("antmaze", ANT_ENVS, METHODS, keyed_by_env(ANTMAZE, "antmaze"),
                  columns=tuple(f"ant {m}" for m in MAZES))),
)
