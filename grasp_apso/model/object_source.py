"""Where a grasp object comes from, as a typed union, and the ONE resolver to a GraspObject.

An object source is one of

- :class:`InlineMesh` -- vertices and triangles given as arrays (a ROS ``shape_msgs/Mesh``
  or the packed ``mesh_vertices``/``mesh_triangles`` fields of a request);
- :class:`MeshFile` -- a mesh file path or ``file://`` URI (optionally confined to an
  allowed directory, scaled after reading);
- :class:`BuiltinObject` -- one of the paper's objects by name.

:func:`resolve_object` turns any of them into a validated
:class:`~grasp_apso.model.objects.GraspObject`; the node's worker, the database's batch
worker and the command line all call it, so the three build objects the same way and
report the same errors (:class:`~grasp_apso.errors.ObjectError` naming the field).
"""

from __future__ import annotations

import hashlib
import os
import re
from dataclasses import dataclass
from typing import Callable, Hashable, Union

import numpy as np

from ..errors import ObjectError
from . import builtin as builtin_objects
from . import mesh_files
from .mesh_checks import DEFAULT_MAX_TRIANGLES
from .objects import GraspObject, from_arrays

__all__ = ["PACKED", "InlineMesh", "MeshFile", "BuiltinObject", "ObjectSource", "resolve_object",
           "source_key", "packed_message"]

#: The packed mesh fields of a request, as they are named in messages.
PACKED = "mesh_vertices/mesh_triangles"


@dataclass(frozen=True, eq=False)
class InlineMesh:
    """A mesh given as arrays (object frame, metres).

    ``vertices`` : (V, 3) float; ``triangles`` : (T, 3) int, indices into ``vertices``;
    ``packed`` : the request used the flat ``mesh_vertices``/``mesh_triangles`` fields
    (its errors then name those fields); ``max_triangles`` : the size limit.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    packed: bool = False
    max_triangles: int = DEFAULT_MAX_TRIANGLES
    name: str = "mesh"

    def describe(self) -> str:
        kind = "packed mesh" if self.packed else "mesh"
        return f"{kind} ({len(self.vertices)} vertices, {len(self.triangles)} triangles)"


@dataclass(frozen=True)
class MeshFile:
    """A mesh file: ``uri`` (path or ``file://`` URI) inside ``allowed_dir`` (None = anywhere),
    at most ``max_bytes`` bytes and ``max_triangles`` triangles; ``shown`` is the path as the
    caller wrote it (messages name only that); vertices times ``scale`` are metres."""

    uri: str
    allowed_dir: str | None = None
    max_bytes: int = mesh_files.DEFAULT_MAX_BYTES
    shown: str | None = None
    max_triangles: int = DEFAULT_MAX_TRIANGLES
    scale: float = 1.0
    name: str | None = None

    def describe(self) -> str:
        return f"mesh_uri {self.shown if self.shown is not None else self.uri}"


@dataclass(frozen=True)
class BuiltinObject:
    """One of the paper's objects (``sphere``, ``cube``, ``barrel``, ``fish``)."""

    name: str

    def describe(self) -> str:
        return f"object {self.name}"


ObjectSource = Union[InlineMesh, MeshFile, BuiltinObject]


def packed_message(text: str) -> str:
    """A validation message of the mesh checks (which say ``mesh: ...``) re-addressed to the
    packed fields: vertex problems name ``mesh_vertices``, index problems
    ``mesh_triangles``, problems of the whole mesh both."""
    if not text.startswith("mesh: "):
        return text
    rest = text[len("mesh: "):]
    if re.match(r"(vertex \d|vertices |\d+ vertices )", rest):
        name = "mesh_vertices"
    elif re.match(r"(triangle \d|triangles |\d+ triangles )", rest):
        name = "mesh_triangles"
    else:
        name = PACKED
    return f"{name} (packed mesh): {rest}"


def source_key(source: ObjectSource) -> Hashable | None:
    """A cache key for the object of ``source`` (content hash for arrays; real path, mtime
    and size for a file), or None when it cannot be keyed (the resolver then reports why)."""
    if isinstance(source, InlineMesh):
        digest = hashlib.sha1()
        for array in (source.vertices, source.triangles):
            array = np.asarray(array)
            digest.update(f"{array.dtype}{array.shape}".encode())
            digest.update(np.ascontiguousarray(array).tobytes())
        return ("mesh", digest.hexdigest(), source.max_triangles, source.name)
    if isinstance(source, MeshFile):
        try:
            real = mesh_files.resolve(source.uri, source.allowed_dir)
            stat = os.stat(real)
        except (OSError, ObjectError):
            return None
        return ("file", real, stat.st_mtime_ns, stat.st_size, source.max_triangles, source.max_bytes,
                float(source.scale), source.name)
    return ("builtin", source.name)


def _build(source: ObjectSource, on_stage: Callable[[str], None] | None) -> GraspObject:
    if isinstance(source, BuiltinObject):
        if on_stage is not None:
            on_stage("preparation")
        return builtin_objects.builtin(source.name)
    if isinstance(source, MeshFile):
        if not (source.scale > 0 and np.isfinite(source.scale)):
            raise ObjectError(f"mesh_scale: expected a positive number, got {source.scale:g}", "mesh_scale")
        obj = mesh_files.from_file(source.uri, allowed_dir=source.allowed_dir, max_triangles=source.max_triangles,
                                   max_bytes=source.max_bytes, name=source.name, shown=source.shown,
                                   on_stage=on_stage)
        if source.scale != 1.0:
            obj = from_arrays(np.asarray(obj.mesh.vertices) * source.scale, np.asarray(obj.mesh.faces),
                              name=obj.name, max_triangles=source.max_triangles)
        return obj
    if isinstance(source, InlineMesh):
        if on_stage is not None:
            on_stage("validation")
        try:
            return from_arrays(source.vertices, source.triangles, name=source.name,
                               max_triangles=source.max_triangles)
        except ObjectError as exc:
            if not source.packed:
                raise
            raise ObjectError(packed_message(str(exc))) from None
    raise TypeError(f"not an object source: {type(source).__name__}")


def resolve_object(source: ObjectSource, *, cache=None,
                   on_stage: Callable[[str], None] | None = None) -> GraspObject:
    """The validated :class:`GraspObject` of ``source``.

    Parameters
    ----------
    source : InlineMesh, MeshFile or BuiltinObject
    cache : grasp_apso.cache.BoundedCache, optional
        Objects already built, keyed by :func:`source_key` (a file is rebuilt when it
        changed); built-in objects are cached by :func:`~grasp_apso.model.builtin.builtin`.
    on_stage : callable(str), optional
        Told the stage it enters: ``"reading"`` (a file), ``"validation"`` (mesh checks),
        ``"preparation"`` (a built-in object), so that a time bound can name it.

    Raises
    ------
    ObjectError
        Naming the field at fault (``mesh``, ``mesh_vertices``, ``mesh_uri``, ``object_name``...).
    """
    key = source_key(source) if cache is not None and not isinstance(source, BuiltinObject) else None
    if key is not None:
        cached = cache.get(key)
        if cached is not None:
            return cached
    obj = _build(source, on_stage)
    return cache.put(key, obj) if key is not None else obj
