"""Batch planning into a grasp database: :func:`run_batch` (the engine behind ``grasp_apso_batch``).

The driver expands the inputs, reads each mesh file (its bytes and their SHA-256), skips
what the database already holds, sends one task per object to the engine (a local process
pool or Ray, :mod:`grasp_apso.database.engines`) and writes the rows as they come back.

Resume key: ``(source_sha256, scale, hand_name, options_key)`` -- the file's content, its
scale, the hand and the options (:func:`options_document`; the seed is not part of it). An
object is skipped when its key has rows, or a deterministic failure (a bad mesh, an object
the hand cannot grasp; ``retry`` False in the failures table) unless ``retry_failed``. Two
files whose processed meshes are identical (same ``mesh_hash``) are planned once per key:
the second result is dropped when it arrives.

Writes: rows are buffered and flushed as one part file every ``flush_seconds`` (or
``flush_objects`` objects), atomically (:class:`~grasp_apso.database.store.GraspStore`); at
the end, and on Ctrl-C, what has arrived is flushed before the lock is released. An
interrupted batch thus loses at most the objects in flight.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
import signal
import sys
import time
from dataclasses import asdict, dataclass, field
from typing import Callable, TextIO

from .. import __version__
from ..errors import ObjectError
from ..model.planning_hand import is_general_hand, load_planning_hand
from ..model.mesh_checks import DEFAULT_MAX_TRIANGLES
from ..model.mesh_files import DEFAULT_MAX_BYTES
from ..search.options import PlanOptions
from .engines import LocalEngine, RayEngine
from .inputs import ObjectSpec, expand_inputs, read_source
from .schema import FAILURE_SCHEMA, GRASP_SCHEMA, empty_columns, options_key
from .store import GraspStore
from .worker import ObjectTask, Outcome

__all__ = ["BatchConfig", "BatchSummary", "run_batch", "options_document", "object_seed"]


@dataclass(frozen=True)
class BatchConfig:
    """Everything a batch is told.

    Attributes
    ----------
    out : str
        The database directory (created when missing).
    options : PlanOptions
        Plan options of every object (``max_grasps`` = ``--grasps``).
    seed : int
        Base seed; each object's seed is :func:`object_seed` of it and the file content.
    table : bool
        Default of the manifest's ``table`` flag.
    hand_path : str or None
        Hand description (.urdf, .xml or .yaml); None = the shipped hand.
    hand_config : str or None
        Its override config.
    engine : "local" | "ray"
    workers : int or None
        Local processes, or CPUs of a private local Ray; None = all cores.
    ray_address : str or None
        Join this Ray cluster instead of starting one.
    retry_failed : bool
        Plan again objects whose earlier failure was deterministic.
    max_triangles : int
    max_bytes : int
        Limits on each mesh file.
    flush_seconds : float, s
    flush_objects : int
        Write a part file when this much time has passed or this many objects arrived.
    progress : "auto" | "bar" | "lines" | "none"
        ``auto``: a tqdm bar when stderr is a terminal, plain lines otherwise.
    """

    out: str
    options: PlanOptions = field(default_factory=PlanOptions)
    seed: int = 0
    table: bool = False
    hand_path: str | None = None
    hand_config: str | None = None
    engine: str = "local"
    workers: int | None = None
    ray_address: str | None = None
    retry_failed: bool = False
    max_triangles: int = DEFAULT_MAX_TRIANGLES
    max_bytes: int = DEFAULT_MAX_BYTES
    flush_seconds: float = 5.0
    flush_objects: int = 32
    progress: str = "auto"


@dataclass
class BatchSummary:
    """What a batch did. Times in seconds (wall clock)."""

    out: str
    engine: str
    workers: int = 0
    total: int = 0
    planned: int = 0
    skipped: int = 0
    failed: int = 0
    grasps: int = 0
    seconds: float = 0.0
    startup_seconds: float = 0.0
    work_seconds: float = 0.0
    interrupted: bool = False
    failures: list[tuple[str, str]] = field(default_factory=list)
    #: Objects each Ray node worked on (node id -> count; empty for the local pool).
    nodes: dict[str, int] = field(default_factory=dict)

    @property
    def objects_per_minute(self) -> float:
        """Objects planned per minute of work (after the engine started)."""
        done = self.planned + self.failed_in_workers
        return 60.0 * done / self.work_seconds if self.work_seconds > 0 else 0.0

    failed_in_workers: int = 0


def options_document(options: PlanOptions, hand_name: str, table: bool,
                     pose: tuple[float, ...] | None, hand_hash: str = "") -> str:
    """The canonical JSON of what determines an object's grasps (besides its mesh and seed).

    ``pose`` counts only with a table or the simulation (otherwise the grasps, stored in the
    object frame, do not depend on it). ``hand_hash`` (the hand's content) is part of it, so
    a changed hand file is planned again.
    """
    plan = asdict(options)
    plan.pop("decomposition_timeout", None)  # a time bound of the simulation, not what the grasps are
    if plan.get("wrist_position") is not None:
        plan["wrist_position"] = [float(v) for v in plan["wrist_position"]]
    doc = {"plan": plan, "hand": hand_name, "table": bool(table), **({"hand_hash": hand_hash} if hand_hash else {}),
           "pose": list(pose) if pose is not None and (table or options.simulate) else None}
    return json.dumps(doc, sort_keys=True, separators=(",", ":"))


def object_seed(base_seed: int, source_sha256: str, scale: float) -> int:
    """The seed of one object (63 bits): independent of the order and the engine."""
    digest = hashlib.sha256(f"{int(base_seed)}:{source_sha256}:{float(scale)!r}".encode()).hexdigest()
    return int(digest[:15], 16)


class _Progress:
    """A tqdm bar with ETA on a terminal, else one plain line per object (stderr)."""

    def __init__(self, total: int, mode: str, stream: TextIO):
        self.total, self.stream, self.done = total, stream, 0
        self.t0 = time.perf_counter()
        tty = hasattr(stream, "isatty") and stream.isatty()
        self.mode = ("bar" if tty else "lines") if mode == "auto" else mode
        self.bar = None
        if self.mode == "bar" and total:
            from tqdm import tqdm

            self.bar = tqdm(total=total, file=stream, unit="obj", smoothing=0.1)

    def update(self, text: str) -> None:
        self.done += 1
        if self.bar is not None:
            self.bar.set_postfix_str(text[:40], refresh=False)
            self.bar.update(1)
        elif self.mode == "lines":
            elapsed = time.perf_counter() - self.t0
            eta = elapsed / self.done * (self.total - self.done)
            print(f"[grasp_apso_batch] {self.done}/{self.total} {text} "
                  f"(elapsed {_hms(elapsed)}, eta {_hms(eta)})", file=self.stream, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _hms(seconds: float) -> str:
    s = int(round(seconds))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}"


def _now() -> _dt.datetime:
    return _dt.datetime.now(_dt.timezone.utc)


class _Buffers:
    """Rows waiting to be written, flushed as part files."""

    def __init__(self, store: GraspStore, config: BatchConfig):
        self.store, self.config = store, config
        self.grasps = empty_columns(GRASP_SCHEMA)
        self.failures = empty_columns(FAILURE_SCHEMA)
        self.objects = 0
        self.last = time.monotonic()

    def add_grasps(self, columns: dict[str, list]) -> None:
        for k, v in columns.items():
            self.grasps[k].extend(v)
        self.objects += 1

    def add_failure(self, object_id: str, path: str, sha: str | None, scale: float, hand: str,
                    okey: str, error_type: str, error: str, retry: bool) -> None:
        row = {"object_id": object_id, "source_path": path, "source_sha256": sha, "scale": float(scale),
               "hand_name": hand, "options_key": okey, "error_type": error_type, "error": error,
               "retry": bool(retry), "package_version": __version__, "created": _now()}
        for k in self.failures:
            self.failures[k].append(row[k])
        self.objects += 1

    def maybe_flush(self) -> None:
        if (self.objects >= self.config.flush_objects
                or time.monotonic() - self.last >= self.config.flush_seconds):
            self.flush()

    def flush(self) -> None:
        self.store.append("grasps", self.grasps)
        self.store.append("failures", self.failures)
        self.grasps = empty_columns(GRASP_SCHEMA)
        self.failures = empty_columns(FAILURE_SCHEMA)
        self.objects = 0
        self.last = time.monotonic()


def _resume_state(store: GraspStore) -> tuple[set, set, set]:
    g = store.read("grasps", ["source_sha256", "scale", "hand_name", "options_key", "mesh_hash"]).to_pydict()
    done_sources = set(zip(g["source_sha256"], g["scale"], g["hand_name"], g["options_key"]))
    done_meshes = set(zip(g["mesh_hash"], g["hand_name"], g["options_key"]))
    f = store.read("failures", ["source_sha256", "scale", "hand_name", "options_key", "retry"]).to_pydict()
    bad = {(s, sc, h, k) for s, sc, h, k, r in zip(f["source_sha256"], f["scale"], f["hand_name"],
                                                  f["options_key"], f["retry"]) if s and not r}
    return done_sources, done_meshes, bad


def run_batch(inputs: list[str], config: BatchConfig, stream: TextIO | None = None,
              on_written: Callable[[BatchSummary], None] | None = None) -> BatchSummary:
    """Plan every input object into the database ``config.out``; see the module docstring.

    Parameters
    ----------
    inputs : list of str
        Mesh files, folders, manifests.
    config : BatchConfig
    stream : text stream
        Progress and messages (default stderr).
    on_written : callable(BatchSummary), optional
        Called after each object's outcome is buffered (for tests and tools).

    Raises
    ------
    DatabaseError
        ``--out: ...``: the database cannot be created, read or written, or another live
        batch holds its lock.
    UsageError
        An unreadable manifest.
    """
    stream = stream or sys.stderr
    t0 = time.perf_counter()
    summary = BatchSummary(out=str(config.out), engine=config.engine)
    specs = expand_inputs(inputs)
    summary.total = len(specs)
    store = GraspStore(config.out, field="--out")
    store.create()
    store.acquire()
    try:
        store.migrate()
        _run_locked(specs, config, store, summary, stream, on_written)
    finally:
        store.release()
        summary.seconds = time.perf_counter() - t0
    return summary


def _run_locked(specs: list[ObjectSpec], config: BatchConfig, store: GraspStore, summary: BatchSummary,
                stream: TextIO, on_written) -> None:
    hand = load_planning_hand(config.hand_path, config.hand_config)
    done_sources, done_meshes, bad = _resume_state(store)
    buffers = _Buffers(store, config)
    todo: list[tuple[ObjectSpec, str, str, str, bool]] = []
    queued: set = set()
    for spec in specs:
        table = config.table if spec.table is None else spec.table
        # The paper hand's documents (and so its resume keys) stay those of earlier databases.
        ojson = options_document(config.options, hand.name, table, spec.pose,
                                 hand.hash if is_general_hand(hand.hand) else "")
        okey = options_key(ojson)
        sha = None
        try:
            if spec.error:
                raise ObjectError(spec.error)
            _, sha = read_source(spec.path, config.max_bytes)
        except ObjectError as exc:
            buffers.add_failure(spec.object_id, spec.path, sha, spec.scale, hand.name, okey,
                                type(exc).__name__, str(exc), retry=True)
            summary.failed += 1
            summary.failures.append((spec.object_id, str(exc)))
            continue
        key = (sha, float(spec.scale), hand.name, okey)
        if key in done_sources or key in queued or (key in bad and not config.retry_failed):
            summary.skipped += 1
            continue
        queued.add(key)
        todo.append((spec, sha, okey, ojson, table))
    buffers.flush()
    print(f"[grasp_apso_batch] {len(specs)} objects: {len(todo)} to plan, {summary.skipped} skipped "
          f"(done), {summary.failed} failed to read -> {config.out}", file=stream, flush=True)
    if not todo:
        return
    if config.engine == "ray":
        engine = RayEngine(config.workers, config.ray_address)
    else:
        engine = LocalEngine(config.workers or os.cpu_count() or 1)
    interrupted = False
    progress = None
    t_work = None
    try:
        summary.startup_seconds = engine.start()
        summary.workers = engine.workers
        t_work = time.perf_counter()
        progress = _Progress(len(todo), config.progress, stream)
        pending = iter(todo)
        window = 2 * max(1, engine.workers)
        exhausted = False
        while True:
            while not exhausted and engine.in_flight < window:
                item = next(pending, None)
                if item is None:
                    exhausted = True
                    break
                task = _make_task(item, config, buffers, summary, hand.name)
                if task is not None:
                    engine.submit(task)
                else:
                    progress.update(f"{item[0].object_id}: failed to read")
            if engine.in_flight == 0:
                break
            for task, outcome in engine.next_done(timeout=0.5):
                if outcome.node:
                    summary.nodes[outcome.node] = summary.nodes.get(outcome.node, 0) + 1
                _record(outcome, task, hand.name, buffers, summary, done_meshes)
                progress.update(_describe(outcome))
                if on_written is not None:
                    on_written(summary)
            buffers.maybe_flush()
        summary.work_seconds = time.perf_counter() - t_work
    except KeyboardInterrupt:
        interrupted = True
        summary.interrupted = True
        if t_work is not None:
            summary.work_seconds = time.perf_counter() - t_work
    finally:
        previous = _ignore_sigint() if interrupted else None
        try:
            engine.close(cancel=interrupted)
        finally:
            buffers.flush()
            if progress is not None:
                progress.close()
            _restore_sigint(previous)


def _make_task(item, config: BatchConfig, buffers: _Buffers, summary: BatchSummary,
               hand_name: str) -> ObjectTask | None:
    spec, sha, okey, ojson, table = item
    try:
        data, sha_now = read_source(spec.path, config.max_bytes)
    except ObjectError as exc:  # removed or changed since the scan
        buffers.add_failure(spec.object_id, spec.path, sha, spec.scale, hand_name, okey,
                            type(exc).__name__, str(exc), retry=True)
        summary.failed += 1
        summary.failures.append((spec.object_id, str(exc)))
        return None
    return ObjectTask(
        object_id=spec.object_id, source_path=spec.path, data=data, source_sha256=sha_now,
        scale=float(spec.scale), pose=spec.pose, table=bool(table),
        seed=object_seed(config.seed, sha_now, spec.scale), options=asdict(config.options),
        options_json=ojson, options_key=okey, hand_path=config.hand_path, hand_config=config.hand_config,
        max_triangles=config.max_triangles,
    )


def _record(outcome: Outcome, task: ObjectTask, hand_name: str, buffers: _Buffers,
            summary: BatchSummary, done_meshes: set) -> None:
    if outcome.ok and outcome.columns:
        key = (outcome.mesh_hash, hand_name, task.options_key)
        if key in done_meshes:  # the same processed mesh from another file: planned already
            summary.skipped += 1
            return
        done_meshes.add(key)
        buffers.add_grasps(outcome.columns)
        summary.planned += 1
        summary.grasps += outcome.n_grasps
        return
    buffers.add_failure(task.object_id, task.source_path, task.source_sha256, task.scale, hand_name,
                        task.options_key, outcome.error_type or "Error", outcome.error, outcome.retry)
    summary.failed += 1
    summary.failed_in_workers += 1
    summary.failures.append((task.object_id, outcome.error))


def _describe(outcome: Outcome) -> str:
    where = f" on node {outcome.node}" if outcome.node else ""
    if outcome.ok:
        return f"{outcome.object_id}: {outcome.n_grasps} grasps in {outcome.seconds:.1f} s{where}"
    return f"{outcome.object_id}{where}: FAILED {outcome.error_type}: {outcome.error[:120]}"


def _ignore_sigint():
    try:
        return signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the main thread
        return None


def _restore_sigint(previous) -> None:
    if previous is not None:
        try:
            signal.signal(signal.SIGINT, previous)
        except ValueError:
            pass
