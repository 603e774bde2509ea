"""Fix hints that are commands: the ``jobs/*.py`` words that make exactly what a config asked for.

A job starts from its own defaults (jobs/train.py and jobs/make_dataset.py from
configs/method/mctd.yaml, or diffuser.yaml for model.kind=diffuser), not from the method the
failing job ran, so a hint spells out every field of the sections that job reads in which the
failing config differs from that start. Run from the repo root, the command writes where the
failing config looks (relative paths are resolved from the repo root by every job).
"""

from __future__ import annotations

import dataclasses
import shlex
from pathlib import Path
from typing import Any

from fmctd_dist.config import REPO_ROOT, Config, build, group_layers

# Fields no training or dataset run reads (or that the hint sets itself).
NOT_READ = {"env.protocol", "env.policy", "train.out", "train.threads", "model.kind"}


def word(key: str, value: Any) -> str:
    """``key=value`` as a shell word a job parses back to ``value`` (lists without spaces, bools lower case)."""
    return shlex.quote(f"{key}={_text(value)}")


def _text(value: Any) -> str:
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(_text(v) for v in value) + "]"
    return str(value)


def shown(path: Path | str) -> str:
    """A path as a job word: relative to the repo root when inside it (jobs resolve it from there)."""
    path = Path(path)
    try:
        return str(path.resolve().relative_to(REPO_ROOT))
    except ValueError:
        return str(path)


def job_defaults(env: str, method: str) -> Config:
    """The config a job starts from (dataclass defaults <- env yaml <- method yaml), unvalidated."""
    return build(Config, [], lambda cfg: None, group_layers(env, method))


def differing_words(cfg: Config, base: Config, sections: tuple[str, ...]) -> list[str]:
    """``key=value`` for every field of ``sections`` where cfg differs from base, in declaration order."""
    words = []
    for section in sections:
        mine, theirs = getattr(cfg, section), getattr(base, section)
        for f in dataclasses.fields(mine):
            key = f"{section}.{f.name}"
            if key not in NOT_READ and getattr(mine, f.name) != getattr(theirs, f.name):
                words.append(word(key, getattr(mine, f.name)))
    return words


def training_words(cfg: Config) -> list[str]:
    """The ``jobs/train.py`` words that train the model ``cfg`` plans with (train.out aside)."""
    diffuser = cfg.model.kind == "diffuser"
    base = job_defaults(cfg.env.name, "diffuser" if diffuser else "mctd")
    words = [f"env={cfg.env.name}"] + (["model.kind=diffuser"] if diffuser else []) + [f"jump={cfg.jump}"]
    if cfg.device != base.device:
        words.append(word("device", cfg.device))
    return words + differing_words(cfg, base, ("env", "data", "model", "diffusion", "train"))


def train_command(cfg: Config, out: Path | str) -> str:
    """``python jobs/train.py ... train.out=<out>``: writes (or continues) the model cfg loads from out."""
    return "python jobs/train.py " + " ".join(training_words(cfg) + [word("train.out", shown(out))])


def dataset_command(cfg: Config) -> str:
    """``python jobs/make_dataset.py ...``: writes the dataset dir cfg's data.* names."""
    base = job_defaults(cfg.env.name, "mctd")
    words = [f"env={cfg.env.name}"] + differing_words(cfg, base, ("env", "data"))
    return "python jobs/make_dataset.py " + " ".join(words)
