"""The package's cache helpers (grasp_apso/cache.py): bounded in entries and bytes, and
per-thread values of an object kept by identity."""

import threading

import numpy as np
import pytest

from grasp_apso.cache import BoundedCache, PerThreadCache


def test_bounded_cache_evicts_least_recently_used_by_entries_and_bytes():
    cache = BoundedCache(max_entries=3, max_bytes=1000, size_of=lambda v: v.nbytes)
    for k in "abc":
        cache.put(k, np.zeros(10))          # 80 bytes each
    assert cache.get("a") is not None       # a is now the most recently used
    cache.put("d", np.zeros(10))            # over 3 entries: b (least recently used) goes
    assert "b" not in cache and {"a", "c", "d"} <= {k for k in "abcd" if k in cache}
    cache.put("big", np.zeros(100))         # 800 bytes: the others are evicted down to the bound
    assert cache.stats().nbytes <= 1000 and "big" in cache
    cache.put("huge", np.zeros(200))        # alone over max_bytes: returned, never kept
    assert "huge" not in cache
    with pytest.raises(ValueError):
        BoundedCache(0, 10)


def test_per_thread_cache_builds_once_per_thread_and_object():
    built = []
    cache = PerThreadCache(max_entries=2)

    def build(source):
        built.append((threading.get_ident(), id(source)))
        return object()

    a, b, c = object(), object(), object()
    first = cache.get(a, build)
    assert cache.get(a, build) is first and len(built) == 1
    other = {}
    thread = threading.Thread(target=lambda: other.setdefault("v", cache.get(a, build)))
    thread.start()
    thread.join(timeout=10.0)
    assert other["v"] is not first and len(built) == 2   # another thread, another value
    cache.get(b, build)
    cache.get(c, build)                                  # over 2 entries: a (oldest) is dropped
    assert cache.get(a, build) is not first and len(built) == 5
