"""One cache helper for the whole package: a thread-safe LRU bounded in entries AND bytes.

:class:`BoundedCache` keeps at most ``max_entries`` values whose approximate sizes (as
told by ``size_of``) add up to at most ``max_bytes``; inserting past either bound evicts
the least recently used entries. A value larger than ``max_bytes`` on its own is not
kept at all (it is returned to the caller and forgotten), so one huge object can never
pin the memory. :func:`approximate_nbytes` estimates the size of an object made of numpy
arrays (and trimesh meshes, dataclasses, tuples and dicts of them).

Every cache of data derived from an object lives here, as a *named cache* of the
registry (:func:`cached`, :func:`named_cache`): keyed by the object's mesh hash (plus the
options the value depends on), bounded in entries and bytes by :data:`CACHE_LIMITS` (the
one place for those bounds). No other module keeps a module-level cache of object data
(``test/test_cache.py`` reads the sources to check it). Values that live on disk (the
convex decompositions, a hand's covers and pads, the objects' distance grids) are kept
under :func:`cache_root`; :func:`disk_arrays` keeps a folder of arrays within its bytes
in :data:`DISK_LIMITS`, the least recently used files removed first.

:class:`PerThreadCache` keeps per-thread python-fcl objects (moved by ``setTransform``,
so never shared between threads), at most a few per thread.
"""

from __future__ import annotations

import dataclasses
import os
import sys
import threading
from collections import OrderedDict
from pathlib import Path
from typing import Any, Callable, Generic, Hashable, Mapping, TypeVar

import numpy as np

__all__ = ["BoundedCache", "CacheLimit", "CacheStats", "CACHE_LIMITS", "DISK_LIMITS", "PerThreadCache",
           "approximate_nbytes", "cache_root", "cache_stats", "cached", "clear_caches", "disk_arrays", "named_cache",
           "prune_folder", "set_cache_root", "touch", "write_atomically"]

V = TypeVar("V")


@dataclasses.dataclass(frozen=True)
class CacheStats:
    """A snapshot of a cache's counters."""

    entries: int
    nbytes: int
    hits: int
    misses: int
    evictions: int


def approximate_nbytes(value: Any, _depth: int = 0) -> int:
    """Approximate memory held by ``value``, bytes: numpy arrays by ``nbytes``, trimesh
    meshes by their vertex/face arrays times 4 (trimesh caches normals, adjacency and
    more alongside), containers and dataclasses by their members (5 levels deep)."""
    if _depth > 5 or value is None:
        return 0
    if isinstance(value, np.ndarray):
        return int(value.nbytes)
    if isinstance(value, (str, bytes, int, float, bool)):
        return sys.getsizeof(value)
    if hasattr(value, "vertices") and hasattr(value, "faces") and hasattr(value, "is_watertight"):
        return 4 * (int(np.asarray(value.vertices).nbytes) + int(np.asarray(value.faces).nbytes))
    if isinstance(value, dict):
        return sum(approximate_nbytes(v, _depth + 1) for v in value.values())
    if isinstance(value, (list, tuple, set, frozenset)):
        return sum(approximate_nbytes(v, _depth + 1) for v in value)
    if dataclasses.is_dataclass(value):
        return sum(approximate_nbytes(getattr(value, f.name), _depth + 1) for f in dataclasses.fields(value))
    return 64


class BoundedCache(Generic[V]):
    """Thread-safe least-recently-used cache bounded in entries and approximate bytes.

    Parameters
    ----------
    max_entries : int
        At most this many values (>= 1).
    max_bytes : int
        At most this many bytes in all, as measured by ``size_of`` (>= 1).
    size_of : callable(value) -> int, optional
        Size estimate of a value; default :func:`approximate_nbytes`. Called once per
        insertion, outside the lock.
    """

    def __init__(self, max_entries: int, max_bytes: int,
                 size_of: Callable[[Any], int] | None = None) -> None:
        if max_entries < 1 or max_bytes < 1:
            raise ValueError("max_entries and max_bytes must be positive")
        self.max_entries = int(max_entries)
        self.max_bytes = int(max_bytes)
        self._size_of = size_of or approximate_nbytes
        self._lock = threading.Lock()
        self._items: OrderedDict[Hashable, tuple[V, int]] = OrderedDict()
        self._nbytes = 0
        self._hits = self._misses = self._evictions = 0

    def get(self, key: Hashable) -> V | None:
        """The value of ``key`` (now the most recently used), or None."""
        with self._lock:
            item = self._items.get(key)
            if item is None:
                self._misses += 1
                return None
            self._items.move_to_end(key)
            self._hits += 1
            return item[0]

    def put(self, key: Hashable, value: V, nbytes: int | None = None) -> V:
        """Store ``value`` under ``key`` (evicting as needed); returns ``value``.
        ``nbytes``: its size when known (else ``size_of(value)``)."""
        size = max(1, int(self._size_of(value) if nbytes is None else nbytes))
        with self._lock:
            old = self._items.pop(key, None)
            if old is not None:
                self._nbytes -= old[1]
            if size > self.max_bytes:
                return value  # never kept: it alone would exceed the bound
            self._items[key] = (value, size)
            self._nbytes += size
            while len(self._items) > self.max_entries or self._nbytes > self.max_bytes:
                _, (_, dropped) = self._items.popitem(last=False)
                self._nbytes -= dropped
                self._evictions += 1
        return value

    def get_or_create(self, key: Hashable, create: Callable[[], V]) -> V:
        """The cached value of ``key``, or ``create()`` stored (create runs outside the
        lock, so two threads may build the same value once each)."""
        value = self.get(key)
        if value is None:
            value = self.put(key, create())
        return value

    def clear(self) -> None:
        with self._lock:
            self._items.clear()
            self._nbytes = 0

    def __len__(self) -> int:
        with self._lock:
            return len(self._items)

    def __contains__(self, key: Hashable) -> bool:
        with self._lock:
            return key in self._items

    def stats(self) -> CacheStats:
        """Entries, bytes and hit/miss/eviction counters."""
        with self._lock:
            return CacheStats(len(self._items), self._nbytes, self._hits, self._misses, self._evictions)


class PerThreadCache(Generic[V]):
    """Values derived from an object (an fcl model of a hand, of a BVH ...), kept per
    thread and keyed by the object's identity: python-fcl collision objects are moved with
    ``setTransform`` between queries, so two threads must never share one.

    The source object is held with its value, so an ``id`` cannot be reused while its
    entry lives; at most ``max_entries`` per thread (the oldest is dropped first).
    """

    def __init__(self, max_entries: int = 8) -> None:
        if max_entries < 1:
            raise ValueError("max_entries must be positive")
        self.max_entries = int(max_entries)
        self._local = threading.local()

    def get(self, source: Any, build: Callable[[Any], V]) -> V:
        """The value derived from ``source`` in this thread, built once with ``build(source)``."""
        cache = getattr(self._local, "items", None)
        if cache is None:
            cache = self._local.items = {}
        entry = cache.get(id(source))
        if entry is None or entry[0] is not source:
            if len(cache) >= self.max_entries:
                cache.pop(next(iter(cache)))
            entry = cache[id(source)] = (source, build(source))
        return entry[1]



# ------------------------------------------------------------------ the named caches
@dataclasses.dataclass(frozen=True)
class CacheLimit:
    """Bounds of one named cache: at most ``entries`` values and ``nbytes`` bytes."""

    entries: int
    nbytes: int


_MB = 1024 * 1024

#: The bounds of every object-derived cache, one place. Sizes: a signed-distance grid
#: and its normal-spread grid are 240,000 float64 nodes (about 2 MB) each for the default
#: node budget; a BVH about 300 bytes per triangle; convex parts a few kB per part. The
#: per-object caches hold as many objects as the node's object cache (``ros/worker.py``,
#: 32): rebuilding an object's grids costs 0.3-0.6 s, more than a plan.
CACHE_LIMITS: Mapping[str, CacheLimit] = {
    "sdf_grid": CacheLimit(32, 256 * _MB),       # geometry.sdf: (mesh hash, grid options)
    "normal_spread": CacheLimit(32, 256 * _MB),  # geometry.normal_spread: (mesh hash, options, radius)
    "mesh_bvh": CacheLimit(32, 128 * _MB),       # geometry.collision: mesh hash
    "face_boxes": CacheLimit(32, 64 * _MB),      # quality.robustness: mesh hash (triangles and their boxes)
    "convex_parts": CacheLimit(32, 64 * _MB),    # simulation.convex: (mesh hash, decomposition key)
    "hand_model": CacheLimit(16, 1024 * _MB),
    "hand_tables": CacheLimit(16, 256 * _MB),    # geometry.any_hand_tables: hand source hash
    "grg_layout": CacheLimit(16, 16 * _MB),      # search.any_hand_grg: hand source hash
    "hand_drawing": CacheLimit(8, 200 * _MB),    # presentation.hand_geometry: (hand, decimation)    # model.hands.load: (description + config hash, folder, ...)
    "hand_collision": CacheLimit(8, 256 * _MB),  # geometry.any_hand_shapes: (hand source hash, geometry digest)
    "object_distance": CacheLimit(32, 256 * _MB),  # geometry.any_hand_shapes: mesh hash (BVH + exact distance)
    "sim_model": CacheLimit(8, 256 * _MB),       # simulation.any_hand_model: (mesh hash, hand, scene, settings)
}

#: Bytes each folder of :func:`disk_arrays` keeps under the cache root. An object's signed
#: distance grid is 240,000 float64 nodes (about 2 MB) for the default node budget: 256
#: objects, so that a batch over many meshes cannot fill the disk; a probed pad is one
#: point (tens of thousands of fingers); a hand's covers some hundreds of hands.
DISK_LIMITS: Mapping[str, int] = {
    "sdf_grids": 512 * _MB,  # geometry.sdf: (mesh hash, grid options, code and library versions)
    "hand_pads": 16 * _MB,   # model.hands.pad_probe: a finger's probed pad, a few hundred bytes
    "hand_covers": 128 * _MB,  # model.hands.cover_store: a hand's sphere covers, about 0.4 MB
    "coacd": 64 * _MB,       # simulation.convex: an object's convex decomposition, a few kB to 100 kB
    "sim_meshes": 256 * _MB,  # simulation.any_hand_model: STL copies of hand meshes MuJoCo cannot read
}

_REGISTRY: dict[str, BoundedCache] = {}
_REGISTRY_LOCK = threading.Lock()


def named_cache(name: str) -> BoundedCache:
    """The process-wide cache called ``name`` (one of :data:`CACHE_LIMITS`), created on
    first use. KeyError for a name without limits."""
    with _REGISTRY_LOCK:
        cache = _REGISTRY.get(name)
        if cache is None:
            limit = CACHE_LIMITS[name]
            cache = _REGISTRY[name] = BoundedCache(limit.entries, limit.nbytes)
        return cache


def cached(name: str, key: Hashable, build: Callable[[], V],
           nbytes: int | Callable[[V], int] | None = None) -> V:
    """The value of ``key`` in the named cache ``name``, or ``build()`` stored there.

    Parameters
    ----------
    name : str
        A name of :data:`CACHE_LIMITS`.
    key : hashable
        Starts with the object's mesh hash; then whatever else the value depends on.
    build : callable() -> value
        Runs outside the lock (two threads may build the same value once each).
    nbytes : int or callable(value) -> int, optional
        The value's size in bytes when :func:`approximate_nbytes` cannot tell (objects
        of compiled libraries, such as python-fcl's BVH).
    """
    cache = named_cache(name)
    value = cache.get(key)
    if value is None:
        value = build()
        size = nbytes(value) if callable(nbytes) else nbytes
        cache.put(key, value, size)
    return value


def cache_stats() -> dict[str, CacheStats]:
    """Counters of every named cache created so far."""
    with _REGISTRY_LOCK:
        caches = dict(_REGISTRY)
    return {name: cache.stats() for name, cache in caches.items()}


def clear_caches(*names: str) -> None:
    """Empty the named caches ``names`` (all when none is given); disk caches stay."""
    with _REGISTRY_LOCK:
        caches = [c for n, c in _REGISTRY.items() if not names or n in names]
    for cache in caches:
        cache.clear()


# ------------------------------------------------------------------ the disk caches
_ROOT: list[Path] = []  # the folder set by set_cache_root (the node's cache_directory)


def set_cache_root(path: str | os.PathLike | None) -> None:
    """Use ``path`` as the root of the disk caches (None or "" = the default, see
    :func:`cache_root`). The node calls it with its ``cache_directory`` parameter."""
    with _REGISTRY_LOCK:
        _ROOT.clear()
        if path:
            _ROOT.append(Path(path).expanduser())


def write_atomically(path: Path, write: Callable[[Any], None]) -> OSError | None:
    """Write a disk-cache file whole or not at all: ``write(handle)`` fills a temporary file
    beside ``path`` (binary), which then replaces it (atomic on POSIX: a reader, or another
    process writing the same entry, only ever sees whole files). Returns the error, the
    temporary file removed, when the folder cannot be written (the caller goes on without
    the cache), else None."""
    import tempfile

    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=path.suffix + ".tmp")
        with os.fdopen(fd, "wb") as handle:
            write(handle)
        os.replace(tmp, path)
        return None
    except OSError as exc:
        if tmp is not None and os.path.exists(tmp):
            os.unlink(tmp)
        return exc


def cache_root() -> Path:
    """Root folder of the disk caches: the one set by :func:`set_cache_root`, else
    ``$GRASP_APSO_CACHE``, else ``$XDG_CACHE_HOME/grasp_apso``, else
    ``~/.cache/grasp_apso``. Not created here."""
    with _REGISTRY_LOCK:
        if _ROOT:
            return _ROOT[0]
    if os.environ.get("GRASP_APSO_CACHE"):
        return Path(os.environ["GRASP_APSO_CACHE"]).expanduser()
    if os.environ.get("XDG_CACHE_HOME"):
        return Path(os.environ["XDG_CACHE_HOME"]).expanduser() / "grasp_apso"
    return Path.home() / ".cache" / "grasp_apso"


def disk_arrays(folder: str, key: str, build: Callable[[], Mapping[str, np.ndarray]],
                check: Callable[[Mapping[str, np.ndarray]], bool] | None = None) -> dict[str, np.ndarray]:
    """Named arrays kept on disk as ``<cache root>/<folder>/<key>.npz``: read back when there
    (and ``check`` accepts them), its time of use refreshed; else ``build()``, written
    atomically, and the folder pruned to :data:`DISK_LIMITS` ``[folder]`` bytes
    (:func:`prune_folder`). An unreadable or refused file is built again; a folder that
    cannot be written leaves the value built (logged, not an error).

    Parameters
    ----------
    folder : str
        A name of :data:`DISK_LIMITS` (KeyError otherwise).
    key : str
        The file's name: a digest of everything the arrays depend on.
    build : callable() -> mapping of str to ndarray
    check : callable(arrays) -> bool, optional
        Validates arrays read back (shapes, finiteness).
    """
    import logging

    limit = DISK_LIMITS[folder]
    path = cache_root() / folder / f"{key}.npz"
    if path.is_file():
        try:
            with np.load(path, allow_pickle=False) as data:
                arrays = {name: np.array(data[name]) for name in data.files}
            if check is None or check(arrays):
                touch(path)
                return arrays
        except (OSError, ValueError, KeyError, EOFError) as exc:
            logging.getLogger(__name__).warning("ignoring unreadable cache file %s: %s", path, exc)
    arrays = {name: np.asarray(value) for name, value in build().items()}
    error = write_atomically(path, lambda handle: np.savez(handle, **arrays))
    if error is not None:
        logging.getLogger(__name__).warning("cannot write cache file %s: %s", path, error)
    else:
        prune_folder(path.parent, limit, keep=path)
    return arrays


def touch(path: Path) -> None:
    """Mark a cache file as just used (:func:`prune_folder` removes the least recently
    used first); a file another process removed meanwhile is left alone."""
    try:
        os.utime(path)
    except OSError:
        pass


def prune_folder(folder: Path, max_bytes: int, keep: Path | None = None, pattern: str = "*.npz") -> int:
    """Remove the least recently used (oldest modification time) files of ``folder``
    matching ``pattern`` until the rest add up to at most ``max_bytes``; ``keep`` is never
    removed. Files another process removes meanwhile are skipped. Returns the number
    removed."""
    entries = []
    for path in folder.glob(pattern):
        try:
            stat = path.stat()
        except OSError:
            continue
        entries.append((stat.st_mtime, path, stat.st_size))
    total = sum(size for _, _, size in entries)
    removed = 0
    for _, path, size in sorted(entries, key=lambda e: e[0]):
        if total <= max_bytes:
            break
        if keep is not None and path == keep:
            continue
        try:
            path.unlink()
        except OSError:
            continue
        total -= size
        removed += 1
    return removed
