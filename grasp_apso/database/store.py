"""The grasp database on disk: a directory of Parquet part files, written atomically, one
writer at a time.

Layout::

    DB/
      _grasp_database.json       marker: format name, schema version, layout, creation time
      grasps/part-*.parquet      one row per grasp (schema.GRASP_SCHEMA)
      _failures/part-*.parq      one row per failed attempt (schema.FAILURE_SCHEMA), Parquet
      _LOCK                      present while a batch writes: JSON {pid, host, started}

The directory opens as the grasps table in any Parquet reader as it is:
``pyarrow.parquet.read_table(DB)`` and ``pandas.read_parquet(DB)`` skip every file and folder
whose name starts with ``_`` or ``.`` (the marker, the lock, the failures, temporary
files), and the failures' ``.parq`` suffix keeps them out of DuckDB's
``read_parquet('DB/**/*.parquet')``, whose glob does not skip such names. The failures
read as ``read_table(DB / "_failures")``.

Databases written before this layout (``grasp_database.json``, ``failures/*.parquet``,
``LOCK``) are read as they are and moved to it by the next batch, under the lock
(:meth:`GraspStore.migrate`).

Appending is safe: a writer only ever adds new part files, each written to a hidden
temporary file (``.part-*.tmp``) that is fsync'ed and then renamed into place
(``os.replace``, atomic on POSIX), so a reader or an interrupted batch only ever sees whole
files. Readers need no lock (leftover temporary files are removed by the next writer).

The lock: created with ``O_CREAT | O_EXCL``. Another live process on this host holding it
(or any holder on another host) is a :class:`~grasp_apso.errors.DatabaseError`; a lock whose
pid no longer runs on this host is stale and taken over (renamed away atomically, so of two
batches taking it over at once only one wins).
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import signal
import socket
import time
from dataclasses import dataclass
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from ..errors import DatabaseError
from .schema import FAILURE_SCHEMA, FORMAT_NAME, GRASP_SCHEMA, LEGACY_DEFAULTS, SCHEMA_VERSION

__all__ = ["GraspStore", "MARKER", "LEGACY_MARKER", "TABLES", "pid_alive", "read_parts"]

#: The marker; a leading ``_`` hides it from Parquet readers' directory discovery.
MARKER = "_grasp_database.json"
#: Layout of the directory (1: marker, failures and lock without the leading ``_``).
LAYOUT = 2
LOCK = "_LOCK"
#: Names of the first layout, read as they are and migrated by the next batch.
LEGACY_MARKER, LEGACY_FAILURES, LEGACY_LOCK = "grasp_database.json", "failures", "LOCK"


@dataclass(frozen=True)
class _Table:
    """Where one table's part files live: ``DB/<folder>/part-*<suffix>``."""

    folder: str
    suffix: str
    schema: pa.Schema


TABLES = {"grasps": _Table("grasps", ".parquet", GRASP_SCHEMA),
          # Not *.parquet: a glob over the database (DuckDB's DB/**/*.parquet) reads grasps only.
          "failures": _Table("_failures", ".parq", FAILURE_SCHEMA)}


def pid_alive(pid: int) -> bool:
    """True when a process with this pid exists on this host (signal 0 probe)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _part_files(folder: Path, suffix: str = ".parquet") -> list[Path]:
    if not folder.is_dir():
        return []
    return sorted(p for p in folder.glob(f"part-*{suffix}") if p.is_file())


def read_parts(folder: Path, schema: pa.Schema, columns: list[str] | None = None,
               field: str = "grasp_database", suffix: str = ".parquet") -> pa.Table:
    """All part files of one table concatenated (``columns`` only, when given).

    Raises
    ------
    DatabaseError
        ``<field>: cannot read <file>: ...`` for a corrupt or unreadable file, or a file
        missing a column of ``schema``.
    """
    want = schema if columns is None else pa.schema([schema.field(c) for c in columns])
    tables = []
    for path in _part_files(folder, suffix):
        tables.append(read_file(path, want, field))
    if not tables:
        return want.empty_table()
    return pa.concat_tables(tables)


def _legacy_type(got: pa.DataType, want: pa.DataType) -> bool:
    """A schema-1 fixed-size list where schema 2 has a list of the same values."""
    return (pa.types.is_fixed_size_list(got) and pa.types.is_list(want)
            and got.value_type == want.value_type)


def read_file(path: Path, want: pa.Schema, field: str = "grasp_database") -> pa.Table:
    """One Parquet file, checked to hold the columns of ``want`` with their types.

    Files of an older schema are read as the current one: a column they lack that
    :data:`~grasp_apso.database.schema.LEGACY_DEFAULTS` knows gets its value on every row,
    float64[18] joint vectors become lists."""
    try:
        present = set(pq.read_schema(path).names)
        legacy = [n for n in want.names if n not in present and n in LEGACY_DEFAULTS]
        table = pq.read_table(path, columns=[n for n in want.names if n not in legacy])
    except (OSError, pa.ArrowException, ValueError) as exc:
        detail = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise DatabaseError(f"{field}: cannot read {path}: {detail}", field) from None
    for name in legacy:
        table = table.append_column(want.field(name), pa.array([LEGACY_DEFAULTS[name]()] * table.num_rows,
                                                               want.field(name).type))
    for f in want:
        got = table.schema.field(f.name).type
        if got != f.type and not _legacy_type(got, f.type):
            raise DatabaseError(
                f"{field}: {path}: column {f.name} has type {got}, expected {f.type}", field)
    return table.select(want.names).cast(want)


class GraspStore:
    """A grasp database directory: create, lock, append part files, read tables.

    Parameters
    ----------
    root : path
        The database directory.
    field : str
        Name used in error messages (``--out`` for the batch, ``grasp_database`` for the node).
    """

    def __init__(self, root: str | os.PathLike, field: str = "--out"):
        self.root = Path(root)
        self.field = field
        self._seq = 0
        self._locked = False

    # ------------------------------------------------------------------ creation
    def create(self) -> None:
        """Create the directory and marker (no-op when it is already a database)."""
        if self.root.exists() and not self.root.is_dir():
            raise DatabaseError(f"{self.field}: {self.root} exists and is not a directory", self.field)
        marker = self._marker()
        if self.root.is_dir() and any(self.root.iterdir()) and marker is None:
            raise DatabaseError(
                f"{self.field}: {self.root} is a non-empty directory that is not a grasp database "
                f"(no {MARKER})", self.field)
        try:
            for table in TABLES.values():
                (self.root / table.folder).mkdir(parents=True, exist_ok=True)
            if marker is None:
                self._atomic_bytes(self.root / MARKER, _marker_text())
        except OSError as exc:
            raise DatabaseError(f"{self.field}: cannot create {self.root}: {exc.strerror or exc}",
                                self.field) from None

    def _marker(self) -> Path | None:
        """The marker file (this layout's name, else the first layout's), None when absent."""
        for name in (MARKER, LEGACY_MARKER):
            if (self.root / name).is_file():
                return self.root / name
        return None

    def check_marker(self) -> None:
        """Raise DatabaseError unless ``root`` holds a readable marker of this format."""
        marker = self._marker()
        if marker is None:
            raise DatabaseError(f"{self.field}: {self.root} is not a grasp database (no {MARKER})",
                                self.field)
        try:
            data = json.loads(marker.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise DatabaseError(f"{self.field}: cannot read {marker}: {exc}", self.field) from None
        if not isinstance(data, dict) or data.get("format") != FORMAT_NAME:
            raise DatabaseError(f"{self.field}: {marker} is not a {FORMAT_NAME} marker", self.field)
        if int(data.get("schema_version", -1)) > SCHEMA_VERSION:
            raise DatabaseError(
                f"{self.field}: {self.root} has schema version {data.get('schema_version')}, this "
                f"grasp_apso reads up to {SCHEMA_VERSION}", self.field)

    def migrate(self) -> None:
        """Move a database of the first layout to this one (call with the lock held).

        ``failures/part-*.parquet`` -> ``_failures/part-*.parq``; ``grasp_database.json`` ->
        ``_grasp_database.json``; a ``LOCK`` of an older batch that still runs is refused
        (DatabaseError), a stale one removed. Each step is a rename, so an interrupted
        migration leaves a database that reads and migrates again.
        """
        legacy_lock = self.root / LEGACY_LOCK
        holder = _read_json(legacy_lock) if legacy_lock.exists() else None
        if holder is not None:
            self._refuse_if_held(holder, socket.gethostname(), legacy_lock)
        legacy_lock.unlink(missing_ok=True)
        old = self.root / LEGACY_FAILURES
        new = self.root / TABLES["failures"].folder
        try:
            if old.is_dir():
                new.mkdir(exist_ok=True)
                for part in _part_files(old):
                    os.replace(part, new / (part.stem + TABLES["failures"].suffix))
                for tmp in old.glob(".part-*.tmp"):
                    tmp.unlink(missing_ok=True)
                if not any(old.iterdir()):
                    old.rmdir()
            if (self.root / LEGACY_MARKER).is_file():
                if (self.root / MARKER).is_file():
                    (self.root / LEGACY_MARKER).unlink()
                else:
                    data = _read_json(self.root / LEGACY_MARKER) or {}
                    self._atomic_bytes(self.root / MARKER, _marker_text(data.get("created")))
                    (self.root / LEGACY_MARKER).unlink()
            data = _read_json(self.root / MARKER) if (self.root / MARKER).is_file() else None
            if data is not None and int(data.get("schema_version", SCHEMA_VERSION)) < SCHEMA_VERSION:
                # Parts of the new schema are about to be added: older readers must refuse.
                self._atomic_bytes(self.root / MARKER, _marker_text(data.get("created")))
        except OSError as exc:
            raise DatabaseError(f"{self.field}: cannot move {self.root} to the current layout: "
                                f"{exc.strerror or exc}", self.field) from None

    # ------------------------------------------------------------------ lock
    @property
    def lock_path(self) -> Path:
        return self.root / LOCK

    def acquire(self) -> None:
        """Take the writer lock or raise DatabaseError naming the holder."""
        me = {"pid": os.getpid(), "host": socket.gethostname(), "started": _now().isoformat()}
        payload = json.dumps(me).encode()
        for _ in range(5):
            try:
                fd = os.open(self.lock_path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                holder = self._read_lock()
                if holder is None:  # being written right now, or garbage: look again
                    time.sleep(0.1)
                    holder = self._read_lock()
                    if holder is None:
                        holder = {"pid": -1, "host": me["host"]}
                self._refuse_or_take_over(holder, me["host"])
                continue
            with os.fdopen(fd, "wb") as handle:
                handle.write(payload)
                handle.flush()
                os.fsync(handle.fileno())
            self._locked = True
            self._clean_temporaries()
            return
        raise DatabaseError(f"{self.field}: could not take the lock {self.lock_path}", self.field)

    def _refuse_if_held(self, holder: dict, host: str, path: Path) -> None:
        """DatabaseError when the lock ``holder`` (read from ``path``) may still be alive."""
        pid = int(holder.get("pid", -1)) if str(holder.get("pid", "")).lstrip("-").isdigit() else -1
        if holder.get("host") != host or pid_alive(pid):
            raise DatabaseError(
                f"{self.field}: {self.root} is locked by another batch (pid {pid} on host "
                f"{holder.get('host')}, since {holder.get('started', '?')}); wait for it to finish, "
                f"or delete {path} if that process is gone", self.field)

    def _refuse_or_take_over(self, holder: dict, host: str) -> None:
        self._refuse_if_held(holder, host, self.lock_path)
        stale = self.root / f".LOCK.stale.{os.getpid()}"
        try:
            os.rename(self.lock_path, stale)
        except FileNotFoundError:
            return  # someone else removed it: try to create again
        taken = _read_json(stale)
        if taken is not None and taken.get("pid") != holder.get("pid"):
            # We moved a fresh lock of a batch that took over first: put it back.
            try:
                os.link(stale, self.lock_path)
            except FileExistsError:
                pass
            stale.unlink(missing_ok=True)
            raise DatabaseError(f"{self.field}: {self.root} was just locked by another batch "
                                f"(pid {taken.get('pid')})", self.field)
        stale.unlink(missing_ok=True)

    def _read_lock(self) -> dict | None:
        return _read_json(self.lock_path)

    def release(self) -> None:
        """Remove the lock if this process holds it."""
        if not self._locked:
            return
        holder = self._read_lock()
        if holder is not None and holder.get("pid") == os.getpid():
            self.lock_path.unlink(missing_ok=True)
        self._locked = False

    def _clean_temporaries(self) -> None:
        for table in TABLES.values():
            for tmp in (self.root / table.folder).glob(".part-*.tmp"):
                tmp.unlink(missing_ok=True)

    # ------------------------------------------------------------------ writing
    def append(self, table_name: str, columns: dict[str, list]) -> Path | None:
        """Write rows as one new part file, atomically; returns its path (None: no rows).

        SIGINT is blocked while the file is written and renamed, so Ctrl-C cannot leave
        half a part behind (it is delivered right after).
        """
        table_def = TABLES[table_name]
        if not columns or not next(iter(columns.values())):
            return None
        table = pa.Table.from_pydict(columns, schema=table_def.schema)
        self._seq += 1
        name = f"part-{time.time_ns():020d}-{os.getpid()}-{self._seq:05d}{table_def.suffix}"
        final = self.root / table_def.folder / name
        tmp = final.with_name(f".{name}.tmp")
        blocked = _block_sigint()
        try:
            with open(tmp, "wb") as handle:
                pq.write_table(table, handle, compression="zstd")
                handle.flush()
                os.fsync(handle.fileno())
            os.replace(tmp, final)
            _fsync_dir(final.parent)
        except OSError as exc:
            tmp.unlink(missing_ok=True)
            raise DatabaseError(f"{self.field}: cannot write {final}: {exc.strerror or exc}",
                                self.field) from None
        finally:
            _unblock_sigint(blocked)
        return final

    def _atomic_bytes(self, path: Path, data: bytes) -> None:
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        with open(tmp, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)

    # ------------------------------------------------------------------ reading
    def read(self, table_name: str, columns: list[str] | None = None) -> pa.Table:
        """A whole table (all part files), ``columns`` only when given."""
        t = TABLES[table_name]
        table = read_parts(self.root / t.folder, t.schema, columns, self.field, t.suffix)
        legacy = self.root / LEGACY_FAILURES
        if table_name == "failures" and legacy.is_dir():  # a first-layout database not yet migrated
            table = pa.concat_tables([table, read_parts(legacy, t.schema, columns, self.field)])
        return table

    def part_count(self, table_name: str) -> int:
        t = TABLES[table_name]
        return len(_part_files(self.root / t.folder, t.suffix))


def _marker_text(created: str | None = None) -> bytes:
    return json.dumps({"format": FORMAT_NAME, "schema_version": SCHEMA_VERSION, "layout": LAYOUT,
                       "created": created or _now().isoformat()}, indent=1).encode()


def _read_json(path: Path) -> dict | None:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _block_sigint() -> bool:
    try:
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        return True
    except (ValueError, OSError, AttributeError):
        return False


def _unblock_sigint(blocked: bool) -> None:
    if blocked:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def _now() -> _dt.datetime:
    return _dt.datetime.now(_dt.timezone.utc)
