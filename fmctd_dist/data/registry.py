"""Which data module serves an env family: the one place training jobs ask for a family's dataset.

A family (docs/design.md §13) brings its own data module; each offers ``make(cfg) -> (dir, manifest)``
(generate if missing, verify if present) and ``load(cfg) -> dataset`` whose ``train`` / ``val``
arrays [E, S, state_dim], ``normaliser`` and ``digest`` are all ``data/windows.py`` needs. The
modules are imported on first use, so asking for the cube data never imports the maze code.
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import Any

from fmctd_dist.config import Config
from fmctd_dist.registry import family, require_family

# family -> (module, make function, load function)
DATA_MODULES: dict[str, tuple[str, str, str]] = {
    "pointmaze": ("fmctd_dist.families.maze.data", "make_dataset", "load_dataset"),
    "antmaze": ("fmctd_dist.families.maze.data", "make_dataset", "load_dataset"),
    "cube": ("fmctd_dist.families.cube.data", "make_cube_dataset", "load_cube_dataset"),
    "visual-pointmaze": ("fmctd_dist.families.visual.dataset", "make_visual_dataset", "load_visual_dataset"),
}


def _module(cfg: Config) -> tuple[Any, str, str]:
    require_family(cfg.env.name, tuple(DATA_MODULES), "a planner dataset")
    module, make_fn, load_fn = DATA_MODULES[family(cfg.env.name)]
    return importlib.import_module(module), make_fn, load_fn


def make_family_dataset(cfg: Config, progress: bool = True) -> tuple[Path, dict[str, Any]]:
    """Generate (or verify) the dataset of ``cfg.env``'s family; its dir and manifest."""
    mod, make_fn, _ = _module(cfg)
    return getattr(mod, make_fn)(cfg, progress=progress)


def load_family_dataset(cfg: Config) -> Any:
    """The checked dataset of ``cfg.env``'s family (train / val states, normaliser, digest)."""
    mod, _, load_fn = _module(cfg)
    return getattr(mod, load_fn)(cfg)
