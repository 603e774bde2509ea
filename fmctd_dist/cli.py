"""How every job script ends: our own errors become one ``error: ...`` line and exit code 2."""

from __future__ import annotations

import sys
from collections.abc import Callable

from fmctd_dist.errors import FmctdError


def run(main: Callable[[list[str]], int]) -> None:
    """Call ``main(sys.argv[1:])``; an FmctdError is printed as one readable line, not a traceback."""
    try:
        sys.exit(main(sys.argv[1:]))
    except FmctdError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
