"""One exception class per failure kind, each message naming the field, the value and the fix.

Everything a user can get wrong is checked in the job process before Ray or any actor
starts, so these are the only errors a user should ever read.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable


class FmctdError(Exception):
    """Base class: every error this package raises on purpose."""


class ConfigError(FmctdError):
    """A config field, name or override is unknown, mistyped or inconsistent."""


class CheckpointError(FmctdError):
    """A checkpoint is missing, corrupt, or does not match the config."""


class DatasetError(FmctdError):
    """A dataset file is missing, corrupt, or does not match its manifest."""


class ResultsError(FmctdError):
    """A results directory holds rows of another config or checkpoint, or files that are not our rows."""


class DeviceError(FmctdError):
    """A requested device is not there, or every denoiser actor is gone."""


def did_you_mean(value: str, choices: Iterable[str]) -> str:
    """Return ' (did you mean 'x'?)' for the closest choice, or '' when nothing is close."""
    close = difflib.get_close_matches(str(value), [str(c) for c in choices], n=1, cutoff=0.5)
    return f" (did you mean '{close[0]}'?)" if close else ""


def unknown_name(field: str, value: str, choices: Iterable[str]) -> ConfigError:
    """A ConfigError for a name that is not one of ``choices``, with a suggestion."""
    choices = sorted(str(c) for c in choices)
    return ConfigError(
        f"{field}={value!r} is not known{did_you_mean(value, choices)}; "
        f"choose one of: {', '.join(choices)}"
    )
