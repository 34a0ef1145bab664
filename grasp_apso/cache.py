"""One cache helper for the whole package: a thread-safe LRU bounded in entries AND bytes.

:class:`BoundedCache` keeps at most ``max_entries`` values whose approximate sizes (as
told by ``size_of``) add up to at most ``max_bytes``; inserting past either bound evicts
the least recently used entries. A value larger than ``max_bytes`` on its own is not
kept at all (it is returned to the caller and forgotten), so one huge object can never
pin the memory. :func:`approximate_nbytes` estimates the size of an object made of numpy
arrays (and trimesh meshes, dataclasses, tuples and dicts of them).

Used by the node's object cache (:mod:`grasp_apso.ros.worker`); the planner's caches
(signed-distance grids, BVHs) can switch to it.
"""

from __future__ import annotations

import dataclasses
import sys
import threading
from collections import OrderedDict
from typing import Any, Callable, Generic, Hashable, TypeVar

import numpy as np

__all__ = ["BoundedCache", "CacheStats", "PerThreadCache", "approximate_nbytes"]

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

    def put(self, key: Hashable, value: V) -> V:
        """Store ``value`` under ``key`` (evicting as needed); returns ``value``."""
        size = max(1, int(self._size_of(value)))
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

