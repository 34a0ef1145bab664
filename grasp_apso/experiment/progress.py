"""Progress messages of the experiment on stderr."""

from __future__ import annotations

import sys


def _log(message: str) -> None:
    print(f"[experiment] {message}", file=sys.stderr, flush=True)
