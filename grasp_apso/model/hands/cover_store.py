"""The sphere covers of a hand kept on disk, so that a hand is covered once per machine.

Covering every link of a real hand takes seconds to tens of seconds (:func:`.spheres.cover_link`),
far more than reading its description: a restarted node, a batch worker or another test
process reads the covers back instead. The key is the content of the collision geometry
itself (kind, size, placement and mesh arrays of every link), the cover's settings and
:data:`COVER_VERSION`, so a changed mesh file or a changed algorithm never reads a stale
cover. Files live under ``<cache root>/hand_covers/`` (:func:`grasp_apso.cache.cache_root`),
written atomically; an unreadable file is ignored (and rebuilt).
"""

from __future__ import annotations

import hashlib
import logging
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np

from ...cache import cache_root, write_atomically
from .geometry import LinkGeometry
from .spheres import SphereCover

__all__ = ["COVER_VERSION", "cover_key", "covers_from_disk", "hash_geometry"]

#: Bump when :func:`.spheres.cover_link` changes what it returns for the same input.
#: 2: a collision mesh's inward-facing inner shells (cavities) read outside again (covers of
#: such meshes made before were wrong).
COVER_VERSION = 2

_log = logging.getLogger(__name__)


def cover_key(collision: Mapping[str, Sequence[LinkGeometry]], settings: Mapping[str, object]) -> str:
    """sha256 of every link's collision geometry and the cover settings."""
    digest = hashlib.sha256(f"v{COVER_VERSION};{sorted(settings.items())!r}".encode())
    hash_geometry(digest, collision)
    return digest.hexdigest()


def hash_geometry(digest, collision: Mapping[str, Sequence[LinkGeometry]]) -> None:
    """Feed every link's collision geometry (kind, size, placement, mesh arrays) to ``digest``
    (a hashlib object): the content of the geometry, not the files it came from."""
    for link in sorted(collision):
        digest.update(f"|{link}".encode())
        for geom in collision[link]:
            digest.update(f"{geom.kind}{tuple(float(v) for v in geom.size)}".encode())
            digest.update(np.ascontiguousarray(geom.origin, dtype=np.float64).tobytes())
            if geom.mesh is not None:
                digest.update(np.ascontiguousarray(geom.mesh.vertices, dtype=np.float64).tobytes())
                digest.update(np.ascontiguousarray(geom.mesh.faces, dtype=np.int64).tobytes())


def covers_from_disk(collision: Mapping[str, Sequence[LinkGeometry]], settings: Mapping[str, object],
                     build: Callable[[str], SphereCover]) -> dict[str, SphereCover]:
    """The covers of every link: read from disk when this geometry was covered with these
    ``settings`` before, else ``build(link)`` for each link and written to disk."""
    path = cache_root() / "hand_covers" / f"{cover_key(collision, settings)}.npz"
    stored = _read(path, collision)
    if stored is not None:
        return stored
    covers = {link: build(link) for link in collision}
    _write(path, covers)
    return covers


def _read(path: Path, collision: Mapping[str, Sequence[LinkGeometry]]) -> dict[str, SphereCover] | None:
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            links = [str(v) for v in data["links"]]
            if sorted(links) != sorted(collision):
                return None
            return {link: SphereCover(data[f"c{i}"], data[f"r{i}"], float(data[f"s{i}"][0]),
                                      float(data[f"s{i}"][1]), float(data[f"s{i}"][2]), data[f"e{i}"])
                    for i, link in enumerate(links)}
    except (OSError, KeyError, ValueError, IndexError) as exc:
        _log.warning("ignoring unreadable sphere-cover cache %s: %s", path, exc)
        return None


def _write(path: Path, covers: Mapping[str, SphereCover]) -> None:
    arrays: dict[str, np.ndarray] = {"links": np.array(list(covers), dtype=str)}
    for i, cover in enumerate(covers.values()):
        arrays[f"c{i}"], arrays[f"r{i}"], arrays[f"e{i}"] = cover.centers, cover.radii, cover.ends
        arrays[f"s{i}"] = np.array([cover.max_stray, cover.uncovered, cover.tolerance])
    error = write_atomically(path, lambda handle: np.savez(handle, **arrays))
    if error is not None:
        _log.warning("cannot write sphere-cover cache %s: %s", path, error)
