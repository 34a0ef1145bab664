"""The sphere covers of a hand kept on disk, so that a hand is covered once per machine.

Covering every link of a real hand takes seconds to tens of seconds (:func:`.spheres.cover_link`),
far more than reading its description: a restarted node, a batch worker or another test
process reads the covers back instead. The key is the content of the collision geometry
itself (kind, size, placement and mesh arrays of every link), the cover's settings and
:data:`COVER_VERSION`, so a changed mesh file or a changed algorithm never reads a stale
cover. Files live under ``<cache root>/hand_covers/`` (:func:`grasp_apso.cache.disk_arrays`:
written atomically, an unreadable file built again, the folder kept within its bytes in
:data:`grasp_apso.cache.DISK_LIMITS`).
"""

from __future__ import annotations

import hashlib
from typing import Callable, Mapping, Sequence

import numpy as np

from ...cache import disk_arrays
from .geometry import LinkGeometry
from .spheres import SphereCover

__all__ = ["COVER_VERSION", "cover_key", "covers_from_disk", "hash_geometry"]

#: Bump when :func:`.spheres.cover_link` changes what it returns for the same input.
#: 2: a collision mesh's inward-facing inner shells (cavities) read outside again (covers of
#: such meshes made before were wrong). 3: a shell lying inside a larger one is left out of
#: the union (a cavity folding through itself read points outside the link as inside).
COVER_VERSION = 3


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
    ``settings`` before, else ``build(link)`` for each link and written to disk
    (:func:`grasp_apso.cache.disk_arrays`, folder ``hand_covers``)."""
    def arrays() -> dict[str, np.ndarray]:
        out: dict[str, np.ndarray] = {"links": np.array(list(collision), dtype=str)}
        for i, link in enumerate(collision):
            cover = build(link)
            out[f"c{i}"], out[f"r{i}"], out[f"e{i}"] = cover.centers, cover.radii, cover.ends
            out[f"s{i}"] = np.array([cover.max_stray, cover.uncovered, cover.tolerance])
        return out

    def check(stored: Mapping[str, np.ndarray]) -> bool:
        links = [str(v) for v in stored["links"]]
        return sorted(links) == sorted(collision) and all(
            f"{k}{i}" in stored for i in range(len(links)) for k in "cres") and all(
            stored[f"s{i}"].shape == (3,) for i in range(len(links)))

    stored = disk_arrays("hand_covers", cover_key(collision, settings), arrays, check)
    return {str(link): SphereCover(stored[f"c{i}"], stored[f"r{i}"], float(stored[f"s{i}"][0]),
                                   float(stored[f"s{i}"][1]), float(stored[f"s{i}"][2]), stored[f"e{i}"])
            for i, link in enumerate(stored["links"])}
