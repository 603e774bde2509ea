"""A family's dataset, asked through its registry record: the one place jobs and training get planner data.

A family's data module (``registry.Family.data``) offers ``make(cfg, progress) -> (dir, manifest)``
(generate if missing, verify if present), ``load(cfg) -> dataset`` whose ``train`` / ``val`` arrays
[E, S, state_dim], ``normaliser`` and ``digest`` are all ``data/windows.py`` needs, and
``describe(manifest) -> lines`` for ``jobs/make_dataset.py``. Modules are imported on first use, so asking
for the cube data never imports the maze code.
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import Any

from fmctd_dist.config import Config
from fmctd_dist.registry import family_record


def data_module(env_name: str) -> Any:
    return importlib.import_module(family_record(env_name).data)


def make_family_dataset(cfg: Config, progress: bool = True) -> tuple[Path, dict[str, Any]]:
    """Generate (or verify) the dataset of ``cfg.env``'s family; its dir and manifest."""
    return data_module(cfg.env.name).make(cfg, progress=progress)


def load_family_dataset(cfg: Config) -> Any:
    """The checked dataset of ``cfg.env``'s family (train / val states, normaliser, digest)."""
    return data_module(cfg.env.name).load(cfg)


def describe_family_dataset(env_name: str, manifest: dict[str, Any]) -> list[str]:
    """The lines ``jobs/make_dataset.py`` prints about a dataset of ``env_name``'s family."""
    return data_module(env_name).describe(manifest)
