"""Declared field ranges: a field's valid values sit beside it (``spec``) and are checked in one place.

Every config root (the planner's, the ant expert's, the visual parts', the policy's) declares its
ranges this way, so a bad value reads the same wherever it is set.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from fmctd_dist.errors import ConfigError, unknown_name

# ``why`` texts several roots share
SEED = "any non-negative integer"
THREADS = "0 = torch's default; 1 when other jobs share the cores"


@dataclass(frozen=True)
class Range:
    """A field's valid values, declared beside the field (``spec``) and checked in one place.

    Bounds are inclusive (``ge``/``le``) or strict (``gt``/``lt``); ``choices`` names the valid
    strings; ``each`` applies the bounds to every item of a list field; ``nonempty`` refuses [].
    ``why`` is the fix appended to the error (what the field means, a usual value).
    """

    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    lt: float | None = None
    choices: tuple[str, ...] | Callable[[], tuple[str, ...]] | None = None  # a callable: read when checked
    each: bool = False
    nonempty: bool = False
    multiple_of: int | None = None
    why: str = ""

    def describe(self) -> str:
        bounds = ((">=", self.ge), (">", self.gt), ("<=", self.le), ("<", self.lt))
        parts = [f"{op} {b:g}" for op, b in bounds if b is not None]
        if self.multiple_of is not None:
            parts.append(f"a multiple of {self.multiple_of}")
        text = " and ".join(parts)
        return f"each item {text}" if self.each and text else text

    def ok(self, v: Any) -> bool:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            return False
        v = float(v)
        return (math.isfinite(v)
                and (self.ge is None or v >= self.ge) and (self.gt is None or v > self.gt)
                and (self.le is None or v <= self.le) and (self.lt is None or v < self.lt)
                and (self.multiple_of is None or v % self.multiple_of == 0))

    def check(self, key: str, value: Any) -> None:
        """One ConfigError naming ``key``, the bad value, the valid range and the fix."""
        fix = f"; {self.why}" if self.why else ""
        if self.choices is not None:
            choices = self.choices() if callable(self.choices) else self.choices
            if value not in choices:
                raise unknown_name(key, value, choices)
            return
        items = list(value) if self.each else [value]
        if self.nonempty and not items:
            raise ConfigError(f"{key}=[] is empty; give at least one value{fix}")
        bad = [v for v in items if not self.ok(v)]
        if bad:
            what = f" (bad item {bad[0]!r})" if self.each else ""
            raise ConfigError(f"{key}={value!r}{what} must be {self.describe()}{fix}")


def spec(default: Any = None, *, factory: Callable[[], Any] | None = None, **limits: Any) -> Any:
    """A dataclass field with its valid range in ``metadata["range"]`` (see :class:`Range`)."""
    meta = {"range": Range(**limits)}
    if factory is not None:
        return field(default_factory=factory, metadata=meta)
    return field(default=default, metadata=meta)


def field_ranges(node: Any, prefix: str = "") -> dict[str, Range]:
    """Every declared range of a config instance by dotted key (``train.lr`` -> Range), in declaration order."""
    out: dict[str, Range] = {}
    for f in dataclasses.fields(node):
        value = getattr(node, f.name)
        if dataclasses.is_dataclass(value):
            out.update(field_ranges(value, f"{prefix}{f.name}."))
        elif "range" in f.metadata:
            out[f"{prefix}{f.name}"] = f.metadata["range"]
    return out


def get(node: Any, dotted: str) -> Any:
    """The value at a dotted key (``train.lr``)."""
    for part in dotted.split("."):
        node = getattr(node, part)
    return node


def check_ranges(node: Any) -> None:
    """Check every field against the range declared beside it (``spec``); one ConfigError for the first bad one."""
    for key, rng in field_ranges(node).items():
        rng.check(key, get(node, key))
