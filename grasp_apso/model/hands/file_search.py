"""Where a file a description names but does not find lies in its tree: the hints of the
loaders' "mesh not found" errors (a model file copied out of its folder, a URDF whose
mesh paths point beside the folder that holds them)."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["SCAN_FILES", "find_in_tree"]

#: At most this many files are looked at per search (a description's tree; a repository
#: at most: the search stops there, with no hint).
SCAN_FILES = 20000


def find_in_tree(folder: Path, tail: tuple[str, ...], limit: int = SCAN_FILES) -> Path | None:
    """The first file under ``folder`` whose path ends with the parts ``tail`` (its name
    last), walking the tree top-down; None when none is found within ``limit`` files."""
    if not tail:
        return None
    seen = 0
    for top, _, names in os.walk(folder):
        seen += len(names)
        if seen > limit:
            break
        if tail[-1] in names:
            found = Path(top) / tail[-1]
            if found.parts[-len(tail):] == tail:
                return found
    return None
