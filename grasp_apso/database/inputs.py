"""Batch inputs: mesh files, folders of them, and manifests, expanded into :class:`ObjectSpec` s.

- a mesh file (``.stl .obj .ply .off``, any case): id = the file name without extension;
- a folder: every mesh file below it (recursively, sorted), id = the path relative to the
  folder without extension (``ycb/mug``);
- a manifest, ``.csv`` (a header row naming the columns) or ``.jsonl`` / ``.ndjson`` (one
  JSON object a line): ``id``, ``path`` (relative paths are taken from the manifest's folder),
  optional ``scale`` (default 1: the file's units times scale = metres), optional ``pose``
  (``x y z qx qy qz qw``: the object pose the plan uses, planning frame; a list in JSON, a
  space-separated string in CSV) and optional ``table`` (true: a support plane under the
  object's lowest point in that pose).

A path that does not exist or a bad manifest row does not stop the batch: it becomes a spec
with ``error`` set, recorded as a failure. Only an unreadable manifest is a usage error.
"""

from __future__ import annotations

import csv
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable

from ..errors import ObjectError, UsageError
from ..model.mesh_files import file_format, read_bytes
from ..model.objects import MESH_FORMATS
from ..model.poses import pose_to_matrix

__all__ = ["ObjectSpec", "expand_inputs", "read_source", "MANIFEST_SUFFIXES"]

MANIFEST_SUFFIXES = (".csv", ".jsonl", ".ndjson")
_TRUE = {"1", "true", "yes", "y", "on"}
_FALSE = {"", "0", "false", "no", "n", "off"}


@dataclass(frozen=True)
class ObjectSpec:
    """One object of a batch (before its file is read).

    Attributes
    ----------
    object_id : str
    path : str
        The mesh file as given (absolute after expansion).
    scale : float
        File units times ``scale`` = metres.
    pose : tuple of 7 float or None
        ``x y z qx qy qz qw`` (m), the object pose for planning; None = identity.
    table : bool or None
        A support plane under the object; None = the batch default (``--table``).
    error : str
        Non-empty: the spec is already a failure (missing path, bad manifest row).
    """

    object_id: str
    path: str
    scale: float = 1.0
    pose: tuple[float, ...] | None = None
    table: bool | None = None
    error: str = ""


def _is_mesh(path: Path) -> bool:
    return path.suffix.lower().lstrip(".") in MESH_FORMATS


def expand_inputs(inputs: Iterable[str]) -> list[ObjectSpec]:
    """Expand command-line INPUTs into object specs (ids made unique with ``~2``, ``~3`` ...)."""
    specs: list[ObjectSpec] = []
    for text in inputs:
        path = Path(text).expanduser()
        if path.is_dir():
            found = sorted(p for p in path.rglob("*") if p.is_file() and _is_mesh(p))
            for p in found:
                rel = p.relative_to(path).with_suffix("")
                specs.append(ObjectSpec(rel.as_posix(), str(p.resolve())))
        elif path.suffix.lower() in MANIFEST_SUFFIXES:
            specs.extend(_read_manifest(path))
        elif not path.exists():
            specs.append(ObjectSpec(path.stem or text, str(path),
                                    error=f"mesh_uri: file not found: {text}"))
        else:
            specs.append(ObjectSpec(path.stem, str(path.resolve())))
    return _unique_ids(specs)


def _unique_ids(specs: list[ObjectSpec]) -> list[ObjectSpec]:
    seen: dict[str, int] = {}
    out = []
    for s in specs:
        n = seen.get(s.object_id, 0) + 1
        seen[s.object_id] = n
        if n > 1:
            s = ObjectSpec(f"{s.object_id}~{n}", s.path, s.scale, s.pose, s.table, s.error)
        out.append(s)
    return out


def _read_manifest(path: Path) -> list[ObjectSpec]:
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise UsageError(f"INPUT: cannot read manifest {path}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise UsageError(f"INPUT: manifest {path} is not UTF-8 text") from None
    rows: list[tuple[int, Any]] = []
    if path.suffix.lower() == ".csv":
        reader = csv.DictReader(text.splitlines())
        if not reader.fieldnames or "path" not in [f.strip() for f in reader.fieldnames]:
            raise UsageError(f"INPUT: manifest {path}: the CSV header must name a 'path' column")
        for i, row in enumerate(reader, start=2):
            rows.append((i, {k.strip(): (v or "").strip() for k, v in row.items() if k}))
    else:
        for i, line in enumerate(text.splitlines(), start=1):
            if not line.strip() or line.lstrip().startswith("#"):
                continue
            try:
                rows.append((i, json.loads(line)))
            except ValueError as exc:
                rows.append((i, f"not JSON ({exc.msg})"))
    return [_manifest_row(path, i, row) for i, row in rows]


def _manifest_row(manifest: Path, line: int, row: Any) -> ObjectSpec:
    where = f"{manifest.name}:{line}"
    if not isinstance(row, dict):
        return ObjectSpec(where, str(manifest), error=f"manifest: {where}: {row if isinstance(row, str) else 'expected an object'}")
    raw_path = str(row.get("path") or "").strip()
    object_id = str(row.get("id") or "").strip() or (Path(raw_path).stem if raw_path else where)
    if not raw_path:
        return ObjectSpec(object_id, str(manifest), error=f"manifest: {where}: no path")
    p = Path(raw_path).expanduser()
    p = p if p.is_absolute() else manifest.parent / p
    try:
        scale = float(row.get("scale") if row.get("scale") not in (None, "") else 1.0)
        if not (scale > 0 and scale < float("inf")):
            raise ValueError
    except (TypeError, ValueError):
        return ObjectSpec(object_id, str(p), error=f"manifest: {where}: scale must be a positive number, "
                                                   f"got {row.get('scale')!r}")
    pose = row.get("pose")
    try:
        pose = _pose(pose)
    except (ObjectError, ValueError, TypeError) as exc:
        return ObjectSpec(object_id, str(p), error=f"manifest: {where}: pose: {exc}")
    table = row.get("table")
    if isinstance(table, str):
        if table.strip().lower() not in _TRUE | _FALSE:
            return ObjectSpec(object_id, str(p), error=f"manifest: {where}: table must be true or false, got {table!r}")
        table = None if table.strip() == "" else table.strip().lower() in _TRUE
    elif table is not None and not isinstance(table, bool):
        return ObjectSpec(object_id, str(p), error=f"manifest: {where}: table must be true or false, got {table!r}")
    return ObjectSpec(object_id, str(p.resolve()), scale, pose, table)


def _pose(value: Any) -> tuple[float, ...] | None:
    if value is None or (isinstance(value, str) and not value.strip()):
        return None
    values = value.replace(",", " ").split() if isinstance(value, str) else list(value)
    numbers = [float(v) for v in values]
    if len(numbers) != 7:
        raise ValueError(f"expected 7 numbers x y z qx qy qz qw, got {len(numbers)}")
    pose_to_matrix(numbers[:3], numbers[3:], field="pose")  # validates (unit quaternion ...)
    return tuple(numbers)


def read_source(path: str, max_bytes: int) -> tuple[bytes, str]:
    """Read a mesh file in the driver: its bytes and their SHA-256 (hex).

    Raises
    ------
    ObjectError
        ``mesh_uri: ...``: unknown extension, missing, not a file, unreadable, empty or
        larger than ``max_bytes``.
    """
    file_format(path)  # the same checks and messages as the node's mesh files
    data = read_bytes(path, path, max_bytes)
    return data, hashlib.sha256(data).hexdigest()
