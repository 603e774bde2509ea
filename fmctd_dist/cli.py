"""How every job script ends: our own errors become one ``error: ...`` line and exit code 2."""

from __future__ import annotations

import sys
from collections.abc import Callable

from fmctd_dist.errors import FmctdError


def wants_help(argv: list[str]) -> bool:
    """``-h`` / ``--help`` anywhere among a job's words (key=value words never start with a dash)."""
    return any(a in ("-h", "--help") for a in argv)


def print_usage() -> None:
    """The running script's docstring: its usage lines first, then what it does."""
    print((sys.modules["__main__"].__doc__ or "(no usage written)").strip())


def run(main: Callable[[list[str]], int | None]) -> None:
    """Call ``main(sys.argv[1:])``; an FmctdError is printed as one readable line, not a traceback.

    ``--help`` prints the script's docstring (its usage) and exits 0 without running anything."""
    if wants_help(sys.argv[1:]):
        print_usage()
        sys.exit(0)
    try:
        sys.exit(main(sys.argv[1:]))
    except FmctdError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
