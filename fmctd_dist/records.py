"""What a family's registry record holds (:mod:`fmctd_dist.registry`): plain data, importing nothing of ours.

Record modules (``families/<name>/record.py``) import only this, so the registry can import them by
name without an import cycle.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass


@dataclass(frozen=True)
class EnvSpec:
    """One env name: its kind (the robot or setting its rules are keyed by) and the planner state."""

    name: str  # e.g. pointmaze-medium, cube-double
    family: str  # the kind: pointmaze | antmaze | cube | visual-pointmaze (several kinds may share a package)
    state_dim: int  # planner state per frame: maze x, y (2) | cube xyz in obs units (3 per cube)
    state: str  # what the planner state is, in words (for messages and manifests)
    policy: str = ""  # "module:Class" of its learned low-level policy's hooks ("" = none: e.g. the point's PD law)
    env_fields: tuple[str, ...] = ()  # the env config fields only some envs read, that this one reads


# (success %, its std, planning time s, its std) as the paper prints them; None where it gives no std
PaperCell = tuple[float, "float | None", float, "float | None"]


def keyed_by_env(paper: Mapping[str, Mapping[str, PaperCell]], kind: str) -> dict[str, dict[str, PaperCell]]:
    """A paper table keyed method -> size (``medium``) re-keyed method -> env name (``pointmaze-medium``)."""
    return {m: {f"{kind}-{size}": cell for size, cell in row.items()} for m, row in paper.items()}


@dataclass(frozen=True)
class Table:
    """One of the paper's result tables a family reproduces: envs and methods in the paper's order, the
    paper's numbers, and how the report shows it."""

    name: str  # its block in docs/results.md (``<!-- report:<name> -->``)
    envs: tuple[str, ...]
    methods: tuple[str, ...]
    paper: Mapping[str, Mapping[str, PaperCell]]  # method -> env -> the paper's cell
    glance: bool = True  # a column per env in the glance table at the top of the results and the README
    columns: tuple[str, ...] = ()  # the glance table's short header per env ("point medium"); () = the env names
    render: str = ""  # "module:function(rows) -> markdown" of a table with its own layout; "" = the standard one


@dataclass(frozen=True)
class Family:
    """What a family brings. Modules are named, not imported: the record stays light."""

    name: str  # maze | cube | visual
    envs: tuple[EnvSpec, ...]
    hooks: str  # module with plan_rules, check_episodes, episodes, plot_episode [, guide_map] (fmctd_dist.family)
    data: str  # module with make(cfg, progress) -> (dir, manifest), load(cfg) -> dataset, describe(manifest)
    configs: str = ""  # folder holding env/<name>.yaml for its envs; "" = the repository's configs/
    hint: str = ""  # what to run for this family, named when a job built for others refuses one of its envs
    tables: tuple[Table, ...] = ()  # the paper's tables it reproduces, in the paper's order
