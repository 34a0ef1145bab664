"""Mesh files: load an STL / OBJ / PLY / OFF file into a :class:`GraspObject`.

:func:`from_file` is the only entry point (also available as
``grasp_apso.model.mesh_files.from_file`` and ``GraspObject.from_file``). It takes a request's
``mesh_uri`` -- a path or a ``file://`` URI -- and, in order:

1. turns the URI into a path (``file://`` only, local host, percent-decoded);
2. resolves symlinks and ``..`` and, when an allowed directory is given, refuses a file
   outside it (checked before the file is looked at);
3. takes the format from the extension (:data:`~grasp_apso.model.objects.MESH_FORMATS`);
4. reads the file, refusing more than ``max_bytes`` (default :data:`DEFAULT_MAX_BYTES`);
5. parses it with trimesh (a multi-geometry file is flattened and concatenated);
6. validates and processes the mesh with :func:`grasp_apso.model.objects.from_arrays`.

Every failure raises :class:`~grasp_apso.errors.ObjectError`: ``mesh_uri: ...`` for the
file, ``mesh: ... (mesh_uri: <path>)`` for the mesh in it. Vertices are read as metres
in the object frame.
"""

from __future__ import annotations

import io
import os
import re
import urllib.parse
from typing import Callable, Union

import numpy as np
import trimesh

from ..errors import ObjectError
from .mesh_checks import DEFAULT_MAX_TRIANGLES, check_limit
from .objects import MESH_FORMATS, GraspObject, from_arrays

__all__ = ["DEFAULT_MAX_BYTES", "PathLike", "file_format", "from_file", "read_bytes", "resolve"]

#: Default limit on the size of a mesh file, bytes.
DEFAULT_MAX_BYTES: int = 50_000_000

_URI_SCHEME = re.compile(r"^([A-Za-z][A-Za-z0-9+.\-]*)://")

PathLike = Union[str, "os.PathLike[str]"]


def _uri_to_path(path: PathLike) -> str:
    """Turn a path or ``file://`` URI into a filesystem path string.

    Raises
    ------
    ObjectError
        Empty path, NUL bytes, or a URI scheme other than ``file``.
    """
    if isinstance(path, os.PathLike):
        path = os.fspath(path)
    if not isinstance(path, str):
        raise ObjectError(f"mesh_uri: expected a path or file:// URI, got {type(path).__name__}")
    if not path.strip():
        raise ObjectError("mesh_uri: empty")
    match = _URI_SCHEME.match(path)
    if match:
        scheme = match.group(1).lower()
        if scheme != "file":
            raise ObjectError(
                f"mesh_uri: unsupported URI scheme '{scheme}://' (expected a file path or "
                f"a file:// URI): {path}"
            )
        parsed = urllib.parse.urlparse(path)
        if parsed.netloc not in ("", "localhost"):
            raise ObjectError(
                f"mesh_uri: remote file:// host '{parsed.netloc}' not supported: {path}"
            )
        path = urllib.parse.unquote(parsed.path)
        if not path:
            raise ObjectError("mesh_uri: empty")
    if "\x00" in path:
        raise ObjectError("mesh_uri: path contains a NUL character")
    return path


def _resolve_inside(path: str, allowed_dir: PathLike | None, shown: str | None = None) -> str:
    """Resolve symlinks and ``..``; refuse a result outside ``allowed_dir``.

    Parameters
    ----------
    path : str
        Requested path (relative paths are taken from the current directory).
    allowed_dir : path or None
        Directory the resolved file must lie in; None allows any path.

    Returns
    -------
    str
        The resolved absolute path.
    """
    real = os.path.realpath(path)
    if allowed_dir is None:
        return real
    allowed = os.path.realpath(os.fspath(allowed_dir))
    if not os.path.isdir(allowed):
        raise ObjectError("mesh_uri: the allowed mesh directory does not exist (a configuration problem of the node)")
    if os.path.commonpath([real, allowed]) != allowed:
        # Neither the directory nor whether the path exists is told to the caller.
        raise ObjectError(f"mesh_uri: outside the allowed mesh directory: {shown or path}")
    return real


def resolve(path: PathLike, allowed_dir: PathLike | None = None) -> str:
    """The resolved real path of a ``mesh_uri`` (ObjectError when it is malformed or lies
    outside ``allowed_dir``); for keying caches by path, modification time and size."""
    return _resolve_inside(_uri_to_path(path), allowed_dir)


def file_format(path: str, shown: str | None = None) -> str:
    """Lower-case extension of ``path`` (no dot) if it is in :data:`MESH_FORMATS`."""
    ext = os.path.splitext(path)[1].lower()
    if ext.lstrip(".") not in MESH_FORMATS:
        ext_shown = ext if ext else "(none)"
        raise ObjectError(
            f"mesh_uri: unknown format '{ext_shown}' (expected {', '.join(MESH_FORMATS)}): {shown or path}"
        )
    return ext.lstrip(".")


def read_bytes(real: str, shown: str, max_bytes: int) -> bytes:
    """Read a whole file of at most ``max_bytes`` bytes.

    Parameters
    ----------
    real : str
        Resolved path to open.
    shown : str
        Path to name in error messages (the one the caller gave).
    max_bytes : int
        Largest accepted file size, bytes.
    """
    if not os.path.exists(real):
        raise ObjectError(f"mesh_uri: file not found: {shown}")
    if not os.path.isfile(real):
        raise ObjectError(f"mesh_uri: not a regular file: {shown}")
    try:
        with open(real, "rb") as handle:
            size = os.fstat(handle.fileno()).st_size
            if size > max_bytes:
                raise ObjectError(
                    f"mesh_uri: file is {size} bytes, exceeds the limit of {max_bytes}: {shown}"
                )
            data = handle.read(max_bytes + 1)
    except OSError as exc:
        raise ObjectError(f"mesh_uri: cannot read file ({exc.strerror or exc}): {shown}") from None
    if len(data) > max_bytes:
        raise ObjectError(f"mesh_uri: file exceeds the limit of {max_bytes} bytes: {shown}")
    if not data:
        raise ObjectError(f"mesh_uri: file is empty: {shown}")
    return data


def _parse_mesh(data: bytes, file_type: str, shown: str) -> trimesh.Trimesh:
    """Parse mesh file bytes with trimesh; concatenate a Scene's meshes.

    Returns
    -------
    trimesh.Trimesh
        Unprocessed mesh with at least one triangle.
    """
    try:
        loaded = trimesh.load(io.BytesIO(data), file_type=file_type, process=False)
    except Exception as exc:  # trimesh parsers raise many exception types
        # An ImportError means trimesh wanted an optional decoder for unrecognised bytes.
        # The parser's own text stays out of the message (it may quote the file); it is
        # kept in ``detail`` for the caller's log.
        error = ObjectError(f"mesh_uri: cannot parse as {file_type.upper()}: {shown}")
        error.detail = "unrecognised content" if isinstance(exc, ImportError) else f"{type(exc).__name__}: {exc}"
        raise error from None
    if isinstance(loaded, trimesh.Scene):
        parts = [g for g in loaded.dump() if isinstance(g, trimesh.Trimesh) and len(g.faces)]
        loaded = trimesh.util.concatenate(parts) if parts else None
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise ObjectError(f"mesh_uri: file contains no triangles: {shown}")
    return loaded


def from_file(
    path: PathLike,
    allowed_dir: PathLike | None = None,
    max_triangles: int = DEFAULT_MAX_TRIANGLES,
    max_bytes: int = DEFAULT_MAX_BYTES,
    name: str | None = None,
    shown: str | None = None,
    on_stage: Callable[[str], None] | None = None,
) -> GraspObject:
    """Load, validate and build a :class:`GraspObject` from an STL/OBJ/PLY/OFF file.

    Parameters
    ----------
    path : str or os.PathLike
        File path or ``file://`` URI (percent-encoding decoded; host empty or
        ``localhost``). Other schemes (``package://``, ``http://`` ...) are refused.
        The vertices are read as metres in the object frame.
    allowed_dir : str or os.PathLike or None
        When given, the file, after resolving symlinks and ``..`` (``os.path.realpath``),
        must lie inside this directory.
    max_triangles : int
        Largest accepted number of triangles.
    max_bytes : int
        Largest accepted file size, bytes.
    name : str or None
        Object name; default the file name without extension.
    shown : str or None
        The path as the caller gave it, used in messages (default: ``path``), so that a
        message never names a directory the caller did not write.
    on_stage : callable(str), optional
        Told ``"reading"`` before the file is read and ``"validation"`` before the mesh
        is checked (a caller that bounds the time names the stage that ran out).

    Returns
    -------
    GraspObject

    Raises
    ------
    ObjectError
        ``mesh_uri: ...`` for a bad URI, a file outside ``allowed_dir``, an unknown
        extension, a missing, unreadable, empty or too large file, a file trimesh cannot
        parse or without triangles; ``mesh: ... (mesh_uri: <path>)`` when the mesh itself
        is invalid (see :func:`from_arrays`).

    Notes
    -----
    The format comes from the extension of the path as given (case-insensitive). The
    containment check resolves symlinks at call time. A multi-geometry file (a trimesh
    Scene) is flattened with its transforms and concatenated.
    """
    limit = check_limit(max_triangles)
    if isinstance(max_bytes, bool) or not isinstance(max_bytes, (int, np.integer)) or max_bytes < 1:
        raise ValueError(f"max_bytes: expected a positive integer, got {max_bytes!r}")
    requested = _uri_to_path(path)
    said = shown if shown is not None else requested
    real = _resolve_inside(requested, allowed_dir, said)
    file_type = file_format(requested, said)
    if on_stage is not None:
        on_stage("reading")
    data = read_bytes(real, said, int(max_bytes))
    loaded = _parse_mesh(data, file_type, said)
    stem = os.path.splitext(os.path.basename(requested))[0] or "mesh"
    if on_stage is not None:
        on_stage("validation")
    try:
        return from_arrays(loaded.vertices, loaded.faces, name=name or stem, max_triangles=limit)
    except ObjectError as exc:
        raise ObjectError(f"{exc} (mesh_uri: {said})") from None
