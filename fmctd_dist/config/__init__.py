"""Structured configs: dataclass defaults <- configs/<group>/<name>.yaml <- ``key=value`` overrides.

Every job builds its config with :func:`load_config` (a side root with its own loader function on the
same :mod:`~fmctd_dist.config.loader`); nothing else reads YAML. One concept per module: ``ranges``
(valid values, declared beside each field), ``schema`` (the planner's dataclasses), ``loader``
(parsing, merging, overrides), ``checks`` (fields that depend on each other), ``repo`` (root, commit).
"""

from fmctd_dist.config.checks import is_ant, validate  # noqa: F401
from fmctd_dist.config.loader import (apply_override, build, config_from_dict, from_dict,  # noqa: F401
                                      group_layers, group_names, load_config, parse_overrides, planner_config)
from fmctd_dist.config.ranges import SEED, THREADS, Range, check_ranges, field_ranges, spec  # noqa: F401
from fmctd_dist.config.repo import REPO_ROOT, git_sha, resolve_path  # noqa: F401
from fmctd_dist.config.schema import (DEVICES, MODEL_KINDS, PROTOCOLS, TASK_IDS, Config,  # noqa: F401
                                      DiffusionConfig, MethodConfig, ModelConfig, RayConfig)
