"""The toy family's registry record (step 2 of docs/adding-a-family.md)."""

from pathlib import Path

from fmctd_dist.records import EnvSpec, Family

FAMILY = Family(
    name="toy",
    envs=(EnvSpec("toy-plane", "toy", 2, "x, y"),),
    hooks="toy_family.hooks",
    data="toy_family.data",
    configs=str(Path(__file__).parent / "configs"),  # its env config lives beside it
)
