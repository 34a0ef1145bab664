"""Convex parts of an object mesh for the physics check (CoACD): bounded in time, done
once per mesh, kept on disk.

MuJoCo collides a mesh geom as its convex hull, so a non-convex object (the fish, a mug)
is split into convex parts with CoACD (approximate convex decomposition, Wei et al. 2022,
``coacd`` on PyPI) and each part becomes one mesh geom.

Decisions
---------
- A mesh whose volume is at least ``1 - convex_tolerance`` of its hull's volume (closed
  meshes), or that has at most :data:`SMALL_MESH_FACES` triangles, is used as its hull:
  no decomposition (the sphere, cube and barrel are convex; a 12-triangle box has
  nothing to split). An open (non-watertight) mesh is decomposed (CoACD repairs it).
- CoACD runs with fast settings (:class:`ConvexSettings`): concavity threshold 0.05,
  at most 16 parts, 60 MCTS iterations, 10 MCTS nodes, sampling resolution 1000, seed 0.
  Measured on this project's 2-core machine: the fish (5,950 triangles) splits into 3
  parts in about 2.0 s (CoACD's defaults: 3.7 s, same parts count); the YCB meshes of
  ``data/meshes`` (about 2,900 triangles) take 1 to 23 s (the thin-walled cup and mug
  the longest), more when the cores are shared.
- Bounded in time: CoACD runs in a process of its own (:mod:`.coacd_child`), watched by a
  background thread that kills it after ``timeout`` s (the tunable
  ``decomposition_timeout``, 60 s) and then tries :meth:`ConvexSettings.coarse` (threshold
  0.15, 8 parts, a quarter of the search) under the same bound. When both fail, a mesh
  whose volume is at least :data:`HULL_FALLBACK_RATIO` of its hull's is simulated as
  its hull (nearly convex: the hull changes little); any other gets no parts, and its
  grasps are reported as not simulated, never simulated on a shape it does not have.
- Never waited for past the caller's bound: :func:`decompose` takes ``should_stop`` and
  ``deadline`` and returns ``"pending"`` when they come first; the decomposition goes
  on in the background (one per mesh, joined by later callers) and lands in the caches.
- Results are cached per ``(mesh_hash, settings.key())`` (the time bound is not part of
  the key): in memory (the named cache ``"convex_parts"`` of :mod:`grasp_apso.cache`) and
  on disk as ``.npz`` under ``<cache root>/coacd/`` (:func:`grasp_apso.cache.cache_root`:
  the node's ``cache_directory``, ``$GRASP_APSO_CACHE``, ``$XDG_CACHE_HOME/grasp_apso`` or
  ``~/.cache/grasp_apso``), written atomically; an unreadable file is ignored and
  rewritten. A failure is kept on disk too (no parts, the reason and the time bound it
  had), so a restarted node or a batch does not redo it; a longer time bound retries.
- CoACD is deterministic for a fixed seed.
"""

from __future__ import annotations

import atexit
import hashlib
import json
import logging
import os
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np
import trimesh

from ..cache import DISK_LIMITS, cache_root, clear_caches, named_cache, prune_folder, touch, write_atomically
from ..errors import InputError, SimulationError
from ..tunables import default

__all__ = ["ConvexSettings", "Decomposition", "convex_parts", "decompose", "cache_directory",
           "clear_memory_cache", "cancel_background", "wait_for_background", "SMALL_MESH_FACES", "HULL_FALLBACK_RATIO"]

_log = logging.getLogger(__name__)

#: Meshes with at most this many triangles are used as their hull.
SMALL_MESH_FACES: int = 16
#: When CoACD fails or runs out of time, a closed mesh with at least this share of its
#: hull's volume is simulated as its hull.
HULL_FALLBACK_RATIO: float = 0.9
_FORMAT_VERSION = 2
_CHILD = Path(__file__).with_name("coacd_child.py")
#: How often a waiting caller looks at its stop predicate and deadline, s.
_POLL = 0.05


@dataclass(frozen=True)
class ConvexSettings:
    """CoACD parameters (see the module docstring for the measured choice).

    Attributes
    ----------
    threshold : float
        CoACD concavity threshold, in (0.01, 1].
    max_convex_hull : int
        Most parts, 1..64.
    mcts_iterations, mcts_nodes, mcts_max_depth, resolution : int
        CoACD search effort and sampling resolution.
    convex_tolerance : float
        A closed mesh with ``volume >= (1 - convex_tolerance) * hull volume`` is not split.
    seed : int
        CoACD's random seed (determinism).
    timeout : float, s
        Longest one CoACD run may take (then the coarse settings get as long); not part
        of the cache key.
    """

    threshold: float = 0.05
    max_convex_hull: int = 16
    mcts_iterations: int = 60
    mcts_nodes: int = 10
    mcts_max_depth: int = 3
    resolution: int = 1000
    convex_tolerance: float = 0.02
    seed: int = 0
    timeout: float = default("decomposition_timeout")

    def __post_init__(self) -> None:
        checks = {
            "threshold": 0.01 <= self.threshold <= 1.0,
            "max_convex_hull": isinstance(self.max_convex_hull, int) and 1 <= self.max_convex_hull <= 64,
            "mcts_iterations": isinstance(self.mcts_iterations, int) and 1 <= self.mcts_iterations <= 1000,
            "mcts_nodes": isinstance(self.mcts_nodes, int) and 1 <= self.mcts_nodes <= 100,
            "mcts_max_depth": isinstance(self.mcts_max_depth, int) and 1 <= self.mcts_max_depth <= 10,
            "resolution": isinstance(self.resolution, int) and 100 <= self.resolution <= 100000,
            "convex_tolerance": 0.0 <= self.convex_tolerance < 0.5,
            "seed": isinstance(self.seed, int) and self.seed >= 0,
            "timeout": isinstance(self.timeout, (int, float)) and 0.0 < self.timeout <= 3600.0,
        }
        for name, ok in checks.items():
            if not ok:
                raise InputError(f"decomposition.{name}: {getattr(self, name)!r} is out of range")

    def key(self) -> str:
        """Short stable hash of the settings but the time bound (part of the cache key)."""
        values = {k: v for k, v in asdict(self).items() if k != "timeout"}
        text = repr(sorted(values.items())) + f"|v{_FORMAT_VERSION}"
        return hashlib.sha256(text.encode()).hexdigest()[:12]

    def coarse(self) -> "ConvexSettings":
        """The fallback when these run out of time: a looser threshold, fewer parts, a
        quarter of the search, half the resolution."""
        return replace(self, threshold=max(0.15, self.threshold), max_convex_hull=min(8, self.max_convex_hull),
                       mcts_iterations=max(1, self.mcts_iterations // 4), mcts_nodes=max(1, self.mcts_nodes // 2),
                       mcts_max_depth=min(2, self.mcts_max_depth), resolution=max(100, self.resolution // 2))

    def coacd_arguments(self) -> dict:
        """Keyword arguments of ``coacd.run_coacd``."""
        return dict(threshold=self.threshold, max_convex_hull=self.max_convex_hull,
                    mcts_iterations=self.mcts_iterations, mcts_nodes=self.mcts_nodes,
                    mcts_max_depth=self.mcts_max_depth, resolution=self.resolution, seed=self.seed)


@dataclass(frozen=True)
class Decomposition:
    """The convex parts of one mesh, or why there are none.

    Attributes
    ----------
    parts : tuple of (N_i, 3) float arrays (read-only), or None
        Vertices of each convex part, object frame, m (MuJoCo takes their hull). None:
        no honest decomposition (failed, or still running: ``method`` says which).
    method : str
        ``"hull"`` (nearly convex), ``"coacd"``, ``"coacd-coarse"``, ``"hull-fallback"``,
        ``"failed"`` or ``"pending"`` (still running in the background).
    note : str
        Why, in words (for messages); "" for ``"hull"`` and ``"coacd"``.
    bound : float, s
        The time bound a failure had (a longer one retries); inf otherwise.
    """

    parts: tuple[np.ndarray, ...] | None
    method: str
    note: str = ""
    bound: float = float("inf")


def cache_directory() -> Path:
    """Disk cache folder of the decompositions: ``<cache root>/coacd``
    (:func:`grasp_apso.cache.cache_root`)."""
    return cache_root() / "coacd"


def clear_memory_cache() -> None:
    """Forget the decompositions held in memory (the disk cache stays)."""
    clear_caches("convex_parts")


def _volume_ratio(mesh: trimesh.Trimesh) -> float:
    """Mesh volume / hull volume for a closed mesh, NaN for an open one."""
    if not mesh.is_watertight:
        return float("nan")
    hull_volume = float(mesh.convex_hull.volume)
    return float(mesh.volume) / hull_volume if hull_volume > 0 else float("nan")


def _is_nearly_convex(mesh: trimesh.Trimesh, tolerance: float) -> bool:
    return len(mesh.faces) <= SMALL_MESH_FACES or _volume_ratio(mesh) >= 1.0 - tolerance


def _hull_vertices(vertices: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(trimesh.convex.convex_hull(vertices).vertices, dtype=float)


def _usable(raw: list[np.ndarray]) -> tuple[np.ndarray, ...]:
    """The parts with a volume (at least 4 points spanning 3-D)."""
    parts = []
    for v in raw:
        v = np.asarray(v, dtype=float)
        if v.ndim == 2 and v.shape[1] == 3 and len(v) >= 4 \
                and np.linalg.matrix_rank(v - v.mean(axis=0), tol=1e-7) == 3:
            parts.append(np.ascontiguousarray(v))
    return tuple(parts)


# ------------------------------------------------------------------------ disk cache
def _read_disk(path: Path, timeout: float) -> Decomposition | None:
    """The stored decomposition; None when absent, unreadable, or a failure stored with
    a shorter time bound than ``timeout`` (worth retrying)."""
    if not path.exists():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            n = int(data["n"])
            method, note = str(data["method"]), str(data["note"])
            parts = tuple(np.array(data[f"p{i}"], dtype=float) for i in range(n))
            bound = float(data["timeout"])
    except (OSError, KeyError, ValueError) as exc:
        _log.warning("ignoring unreadable convex-decomposition cache %s: %s", path, exc)
        return None
    if n == 0:
        if bound < timeout:
            return None
        touch(path)
        return Decomposition(None, method, note, bound)
    if any(p.ndim != 2 or p.shape[1] != 3 or len(p) < 4 for p in parts):
        return None
    touch(path)
    return Decomposition(parts, method, note)


def _write_disk(path: Path, found: Decomposition, timeout: float) -> None:
    parts = found.parts or ()
    error = write_atomically(path, lambda handle: np.savez(
        handle, n=np.array(len(parts)), method=np.array(found.method), note=np.array(found.note),
        timeout=np.array(float(timeout)), **{f"p{i}": p for i, p in enumerate(parts)}))
    if error is not None:
        _log.warning("cannot write convex-decomposition cache %s: %s", path, error)
    else:
        prune_folder(path.parent, DISK_LIMITS["coacd"], keep=path)


# ------------------------------------------------------------------ the background runs
class _Run:
    """One decomposition of one mesh, in a background thread that runs CoACD in a child
    process (fine settings, then coarse ones), each killed after ``settings.timeout``."""

    def __init__(self, key: str, mesh: trimesh.Trimesh, settings: ConvexSettings, path: Path | None,
                 on_done: Callable[["_Run"], None]) -> None:
        self.key, self.mesh, self.settings, self.path = key, mesh, settings, path
        self.done = threading.Event()
        self.result = Decomposition(None, "pending", "the convex decomposition is running")
        self._on_done = on_done
        self._lock = threading.Lock()
        self._process: subprocess.Popen | None = None
        self._killed = False
        self._thread = threading.Thread(target=self._run, name=f"coacd-{key[:8]}", daemon=True)

    def start(self) -> "_Run":
        self._thread.start()
        return self

    @property
    def killed(self) -> bool:
        return self._killed

    def kill(self) -> None:
        """Stop the child process now (nothing is kept of this run)."""
        with self._lock:
            self._killed = True
            if self._process is not None and self._process.poll() is None:
                self._process.kill()

    def _run(self) -> None:
        try:
            self.result = self._decompose()
        except Exception as exc:  # noqa: BLE001 -- a background thread must end in a result
            _log.warning("convex decomposition failed: %s", exc)
            self.result = Decomposition(None, "failed", f"the convex decomposition failed ({exc})",
                                        self.settings.timeout)
        finally:
            if self.path is not None and self.result.method != "pending" and not self._killed:
                _write_disk(self.path, self.result, self.settings.timeout)
            self._on_done(self)  # cached and unregistered before the waiters wake
            self.done.set()

    def _decompose(self) -> Decomposition:
        why = []
        with tempfile.TemporaryDirectory(prefix="grasp_apso_coacd_") as folder:
            mesh_file = os.path.join(folder, "mesh.npz")
            np.savez(mesh_file, vertices=np.asarray(self.mesh.vertices, dtype=float),
                     faces=np.asarray(self.mesh.faces, dtype=np.int32))
            for method, settings in (("coacd", self.settings), ("coacd-coarse", self.settings.coarse())):
                parts, problem = self._child(mesh_file, os.path.join(folder, f"{method}.npz"), settings)
                if parts:
                    note = "" if method == "coacd" else f"simulated with coarse CoACD settings ({'; '.join(why)})"
                    return Decomposition(parts, method, note)
                why.append(f"{method}: {problem}")
        ratio = _volume_ratio(self.mesh)
        if ratio >= HULL_FALLBACK_RATIO:
            _log.warning("convex decomposition failed (%s): the mesh fills %.0f%% of its hull, simulated as "
                         "the hull", "; ".join(why), 100 * ratio)
            return Decomposition((_hull_vertices(self.mesh.vertices),), "hull-fallback",
                                 f"simulated as its convex hull ({'; '.join(why)})")
        return Decomposition(None, "failed", "the convex decomposition failed (" + "; ".join(why) + ")",
                             self.settings.timeout)

    def _child(self, mesh_file: str, out_file: str, settings: ConvexSettings) -> tuple[tuple, str]:
        """Run CoACD in a child process; (parts, "") or ((), why)."""
        cpu_limit = int(max(60.0, 4.0 * settings.timeout))  # a backstop should this process die
        command = [sys.executable, str(_CHILD), mesh_file, out_file, json.dumps(settings.coacd_arguments()),
                   str(cpu_limit)]
        with self._lock:
            if self._killed:
                return (), "stopped"
            self._process = subprocess.Popen(command, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                              stderr=subprocess.PIPE)
        try:
            _, err = self._process.communicate(timeout=settings.timeout)
        except subprocess.TimeoutExpired:
            self._process.kill()
            self._process.communicate()
            return (), f"did not finish within {settings.timeout:g} s (parameter decomposition_timeout)"
        if self._process.returncode != 0:
            text = err.decode(errors="replace").strip().splitlines()
            return (), text[-1] if text else f"exit status {self._process.returncode}"
        try:
            with np.load(out_file, allow_pickle=False) as data:
                parts = _usable([data[f"p{i}"] for i in range(int(data["n"]))])
        except (OSError, KeyError, ValueError) as exc:
            return (), f"unreadable result ({exc})"
        return (parts, "") if parts else ((), "no part with a volume")


class _Runs:
    """The decompositions running in this process, one per cache key."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._runs: dict[str, _Run] = {}
        self._pid = os.getpid()
        atexit.register(self.kill_all)

    def get_or_start(self, key: str, mesh: trimesh.Trimesh, settings: ConvexSettings, path: Path | None) -> _Run:
        with self._lock:
            if self._pid != os.getpid():  # a forked worker: the runs (threads) stayed in the parent
                self._runs, self._pid = {}, os.getpid()
            run = self._runs.get(key)
            if run is None:
                run = self._runs[key] = _Run(key, mesh, settings, path, self._finished).start()
            return run

    def _finished(self, run: _Run) -> None:
        if not run.killed and (run.result.parts is not None or run.result.method == "failed"):
            _remember(run.key, run.result)
        with self._lock:
            self._runs.pop(run.key, None)

    def wait_all(self, timeout: float) -> bool:
        """Wait until no decomposition runs (True), at most ``timeout`` s (False)."""
        end = time.monotonic() + timeout
        while True:
            with self._lock:
                runs = list(self._runs.values())
            left = end - time.monotonic()
            if not runs or left <= 0:
                return not runs
            runs[0].done.wait(min(left, 1.0))

    def kill_all(self) -> None:
        with self._lock:
            runs = list(self._runs.values())
        for run in runs:
            run.kill()


_RUNS = _Runs()


def cancel_background() -> None:
    """Stop every background decomposition now (nothing is kept of them): at shutdown."""
    _RUNS.kill_all()


def wait_for_background(timeout: float) -> bool:
    """Wait until every background decomposition has ended (True) or ``timeout`` s passed."""
    return _RUNS.wait_all(timeout)


def _remember(key: str, found: Decomposition) -> Decomposition:
    for p in found.parts or ():
        p.flags.writeable = False
    named_cache("convex_parts").put(key, found)
    return found


# ------------------------------------------------------------------------------ API
def decompose(obj, settings: ConvexSettings | None = None, use_disk: bool = True,
              should_stop: Callable[[], bool] | None = None, deadline: float | None = None) -> Decomposition:
    """The convex parts of an object's mesh, waiting for them at most until
    ``should_stop()`` turns true or ``time.monotonic()`` passes ``deadline``.

    Parameters
    ----------
    obj : GraspObject
        Uses ``obj.mesh`` (trimesh) and ``obj.mesh_hash`` (cache key).
    settings : ConvexSettings, optional
    use_disk : bool
        Read and write the disk cache (the memory cache is always used).
    should_stop : callable() -> bool, optional
    deadline : float, optional
        ``time.monotonic()`` value.

    Returns
    -------
    Decomposition
        ``parts`` None when there is no honest decomposition (``method`` "failed") or it
        is still running (``"pending"``; it goes on in the background and a later call
        finds it). Shared with the caches: read-only.
    """
    settings = settings or ConvexSettings()
    mesh_hash = getattr(obj, "mesh_hash", None)
    mesh = getattr(obj, "mesh", None)
    if not isinstance(mesh_hash, str) or not isinstance(mesh, trimesh.Trimesh):
        raise InputError("obj: expected a GraspObject (mesh and mesh_hash)")
    key = f"{mesh_hash}_{settings.key()}"
    memory = named_cache("convex_parts")
    hit = memory.get(key)
    if hit is not None and hit.bound >= settings.timeout:
        return hit
    if _is_nearly_convex(mesh, settings.convex_tolerance):  # cheap: not written to disk
        return _remember(key, Decomposition((_hull_vertices(mesh.vertices),), "hull"))
    path = cache_directory() / f"{key}.npz" if use_disk else None
    stored = _read_disk(path, settings.timeout) if path is not None else None
    if stored is not None:
        return _remember(key, stored)
    run = _RUNS.get_or_start(key, mesh, settings, path)
    # the run ends by itself within its two time bounds; the margin covers starting the processes
    end = time.monotonic() + 2.0 * settings.timeout + 30.0
    deadline = end if deadline is None else min(deadline, end)
    while not run.done.is_set():
        if (should_stop is not None and should_stop()) or time.monotonic() >= deadline:
            return Decomposition(None, "pending", "the convex decomposition of this new mesh did not end in time "
                                 "(it goes on in the background and is kept, so a repeat is simulated)")
        run.done.wait(_POLL)
    return run.result


def convex_parts(obj, settings: ConvexSettings | None = None, use_disk: bool = True) -> tuple[np.ndarray, ...]:
    """Convex parts of an object's mesh, each as its vertices (object frame, m), waiting
    for the decomposition (at most twice ``settings.timeout``).

    Raises
    ------
    SimulationError
        There is no honest decomposition of the mesh (:func:`decompose` says why).
    """
    found = decompose(obj, settings, use_disk)
    if found.parts is None:
        raise SimulationError(f"simulation: {found.note}")
    return found.parts
