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


# ------------------------------------------------------------ one mechanism (issue 19)
import ast  # noqa: E402
from pathlib import Path  # noqa: E402

from grasp_apso.cache import (CACHE_LIMITS, cache_root, cached, clear_caches, named_cache,  # noqa: E402
                              set_cache_root, write_atomically)

PKG = Path(__file__).resolve().parents[1] / "grasp_apso"
#: Module-level caches allowed outside cache.py, with why: keyed by a name or a file,
#: not by object data.
ALLOWED_LRU = {("model/builtin.py", "_builtin_cached"),  # the four built-in objects, by name
               ("model/hand.py", "_load_hand_cached"),  # hand description files, by path and mtime
               ("search/any_hand_squeeze.py", "sim_settings")}  # the simulation's default settings: one frozen instance
_CONTAINERS = {"dict", "OrderedDict", "defaultdict", "BoundedCache", "WeakValueDictionary", "WeakKeyDictionary",
               "LRUCache", "TTLCache"}


def _module_level_caches(path: Path) -> list[str]:
    """Module-level statements of ``path`` that hold a cache: an empty mutable mapping (or
    a BoundedCache) assigned to a name, or a function memoised by functools."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    rel = path.relative_to(PKG).as_posix() if path.is_relative_to(PKG) else path.name
    found = []
    for node in tree.body:
        value = node.value if isinstance(node, (ast.Assign, ast.AnnAssign)) else None
        if value is not None:
            empty_dict = isinstance(value, ast.Dict) and not value.keys
            call = value.func.attr if isinstance(value, ast.Call) and isinstance(value.func, ast.Attribute) else (
                value.func.id if isinstance(value, ast.Call) and isinstance(value.func, ast.Name) else "")
            if empty_dict or call in _CONTAINERS:
                found.append(f"{rel}:{node.lineno} {ast.unparse(node)[:80]}")
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for deco in node.decorator_list:
                text = ast.unparse(deco)
                if ("lru_cache" in text or text in ("cache", "functools.cache")) and (rel, node.name) not in ALLOWED_LRU:
                    found.append(f"{rel}:{node.lineno} @{text} {node.name}")
    return found


def test_no_module_outside_cache_py_keeps_a_cache_of_object_data():
    modules = [p for p in PKG.rglob("*.py") if "__pycache__" not in p.parts and p.name != "cache.py"]
    assert len(modules) > 50
    offenders = [line for p in modules for line in _module_level_caches(p)]
    assert offenders == [], "object-derived caches go through grasp_apso/cache.py:\n" + "\n".join(offenders)


def test_the_checker_finds_the_old_caches(tmp_path):
    """The AST check above can fail: the five caches issue 19 replaced are each found."""
    fake = tmp_path / "old_caches.py"
    fake.write_text(
        '"""x"""\nimport functools\nfrom collections import OrderedDict\nfrom .cache import BoundedCache\n'
        "GRID_CACHE: 'BoundedCache' = BoundedCache(max_entries=8, max_bytes=1)\n"
        "_BVH_CACHE: 'OrderedDict[str, object]' = OrderedDict()\n"
        "_MEMORY = {}\n"
        "@functools.lru_cache(maxsize=8)\ndef object_bvh(obj):\n    return obj\n")
    assert len(_module_level_caches(fake)) == 4


def test_named_caches_keep_their_byte_bounds():
    assert set(CACHE_LIMITS) >= {"sdf_grid", "normal_spread", "mesh_bvh", "convex_parts"}
    clear_caches("sdf_grid")
    limit = CACHE_LIMITS["sdf_grid"]
    items = limit.nbytes // 24 + 1            # three of these (8 bytes each) exceed the bound
    built = []

    def build(i):
        built.append(i)
        return np.zeros(items)

    for i in range(4):
        cached("sdf_grid", (f"test-hash-{i}",), lambda i=i: build(i))
        stats = named_cache("sdf_grid").stats()
        assert stats.nbytes <= limit.nbytes and stats.entries <= limit.entries
    assert named_cache("sdf_grid").stats().entries == 2          # evicted by bytes, not entries
    cached("sdf_grid", ("test-hash-3",), lambda: build(99))      # the most recent one is kept
    assert built == [0, 1, 2, 3]
    # a size given by the caller (objects numpy cannot measure) is the one counted
    clear_caches("mesh_bvh")
    cached("mesh_bvh", "test-hash-bvh", lambda: object(), nbytes=12345)
    assert named_cache("mesh_bvh").stats().nbytes == 12345
    clear_caches("sdf_grid", "mesh_bvh")


def test_object_caches_hold_every_object_the_node_keeps():
    """A node cycling through its cached objects must not rebuild their grids (0.3-0.6 s
    each, more than a plan) in every plan: each per-object cache holds as many objects as
    the node's object cache, and the grids' byte bounds fit that many grids of a real mesh."""
    from grasp_apso.model.mesh_files import from_file
    from grasp_apso.ros.worker import OBJECT_CACHE_ENTRIES
    from grasp_apso.search.planner import prepare

    for name in ("sdf_grid", "normal_spread", "mesh_bvh", "object_distance"):
        assert CACHE_LIMITS[name].entries >= OBJECT_CACHE_ENTRIES, name
    clear_caches("sdf_grid", "normal_spread")
    prepare(from_file(Path(__file__).resolve().parents[1] / "grasp_apso" / "data" / "meshes" / "mug.stl"))
    for name in ("sdf_grid", "normal_spread"):
        one = named_cache(name).stats().nbytes
        assert one > 0 and CACHE_LIMITS[name].nbytes >= OBJECT_CACHE_ENTRIES * one, name
    clear_caches("sdf_grid", "normal_spread")


def test_planner_caches_are_keyed_by_mesh_hash_and_bounded():
    from grasp_apso.geometry.collision import object_bvh
    from grasp_apso.model.builtin import builtin
    from grasp_apso.search.planner import prepare

    cube = builtin("cube")
    clear_caches("mesh_bvh")
    assert object_bvh(cube) is object_bvh(cube)
    assert named_cache("mesh_bvh").stats().entries == 1 and cube.mesh_hash in named_cache("mesh_bvh")
    prepare(cube)
    for name in ("sdf_grid", "normal_spread"):
        stats = named_cache(name).stats()
        assert 1 <= stats.entries <= CACHE_LIMITS[name].entries and stats.nbytes <= CACHE_LIMITS[name].nbytes


def test_cache_root_follows_the_setting_then_the_environment(tmp_path, monkeypatch):
    monkeypatch.delenv("GRASP_APSO_CACHE", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_root() == tmp_path / "xdg" / "grasp_apso"
    monkeypatch.setenv("GRASP_APSO_CACHE", str(tmp_path / "env"))
    assert cache_root() == tmp_path / "env"
    set_cache_root(tmp_path / "param")
    try:
        assert cache_root() == tmp_path / "param"
    finally:
        set_cache_root(None)
    assert cache_root() == tmp_path / "env"


def test_disk_cache_files_are_written_whole_or_not_at_all(tmp_path):
    path = tmp_path / "covers" / "entry.npz"
    assert write_atomically(path, lambda handle: handle.write(b"whole")) is None
    assert path.read_bytes() == b"whole" and sorted(p.name for p in path.parent.iterdir()) == ["entry.npz"]

    def fails(handle):
        handle.write(b"half")
        raise OSError("disk full")

    error = write_atomically(path, fails)
    assert isinstance(error, OSError) and "disk full" in str(error)
    # the old entry stands and no temporary file is left beside it
    assert path.read_bytes() == b"whole" and sorted(p.name for p in path.parent.iterdir()) == ["entry.npz"]
    blocked = tmp_path / "a_file"
    blocked.write_text("x")
    assert isinstance(write_atomically(blocked / "entry.npz", lambda handle: None), OSError)


def test_every_disk_folder_is_bounded_and_a_reused_file_counts_as_recent(tmp_path, monkeypatch):
    """The convex decompositions and the simulation's mesh copies are kept within their
    bytes too (:data:`grasp_apso.cache.DISK_LIMITS`): past them the least recently used
    files go, a file read back counts as used, and a folder's other kinds of file stay."""
    import os

    from grasp_apso import cache
    from grasp_apso.cache import DISK_LIMITS, prune_folder
    from grasp_apso.simulation import convex

    assert {"sdf_grids", "hand_pads", "hand_covers", "coacd", "sim_meshes"} <= set(DISK_LIMITS)
    folder = tmp_path / "coacd"
    part = np.random.default_rng(0).normal(size=(40, 3))
    paths = [folder / f"{name}.npz" for name in "abc"]
    convex._write_disk(paths[0], convex.Decomposition((part,), "coacd"), 30.0)
    size = paths[0].stat().st_size
    monkeypatch.setitem(cache.DISK_LIMITS, "coacd", int(2.5 * size))  # two files
    convex._write_disk(paths[1], convex.Decomposition((part,), "coacd"), 30.0)
    os.utime(paths[0], (1e9, 1e9))
    os.utime(paths[1], (1e9 + 100, 1e9 + 100))
    assert convex._read_disk(paths[0], 30.0) is not None  # read back: now the most recent
    convex._write_disk(paths[2], convex.Decomposition((part,), "coacd"), 30.0)
    assert sorted(folder.glob("*.npz")) == sorted([paths[0], paths[2]])

    meshes = tmp_path / "sim_meshes"
    meshes.mkdir()
    for i, name in enumerate(("old.stl", "new.stl", "grid.npz")):
        (meshes / name).write_bytes(b"x" * 1000)
        os.utime(meshes / name, (1e9 + i, 1e9 + i))
    assert prune_folder(meshes, 1500, pattern="*.stl") == 1
    assert sorted(p.name for p in meshes.iterdir()) == ["grid.npz", "new.stl"]
