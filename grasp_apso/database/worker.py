"""What runs in a batch worker process (local pool or Ray): one object in, its rows out.

A task carries the mesh file's bytes (read by the driver), so a worker needs no shared
file system, only an installed grasp_apso. The worker parses and validates the mesh
(:func:`grasp_apso.model.object_source.resolve_object` of a private temporary copy, scaled),
builds the optional table, plans with :func:`grasp_apso.search.planner.plan` and returns
plain Python rows (:func:`grasp_apso.database.schema.candidate_rows`). It never raises for
a bad object: every error comes back as an :class:`Outcome` with ``ok = False``.
"""

from __future__ import annotations

import datetime as _dt
import os
import signal
import socket
import tempfile
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import __version__
from ..errors import GraspApsoError, PlanningError
from ..model.planning_hand import is_general_hand, load_planning_hand
from ..model.mesh_checks import DEFAULT_MAX_TRIANGLES
from ..model.object_source import MeshFile, resolve_object
from ..model.poses import pose_to_matrix
from ..search.options import PlanOptions
from .schema import candidate_rows

__all__ = ["ObjectTask", "Outcome", "run_task", "run_task_warm", "init_worker", "ensure_warm",
           "worker_status", "warm_status"]

_WARM = False
_WARM_ERROR = ""


@dataclass(frozen=True)
class ObjectTask:
    """One object to plan, as sent to a worker (picklable, no open files).

    Attributes
    ----------
    object_id, source_path : str
    data : bytes
        The mesh file's content.
    source_sha256 : str
        SHA-256 of ``data``.
    scale : float
        File units times scale = metres.
    pose : tuple of 7 float or None
        Object pose for planning (x y z qx qy qz qw); None = identity.
    table : bool
        A support plane under the object's lowest point (in that pose).
    seed : int
        ``np.random.default_rng(seed)`` drives the plan.
    options : dict
        :class:`~grasp_apso.search.options.PlanOptions` keyword arguments.
    options_json, options_key : str
        Stored with every row (the resume key).
    hand_path : str or None
        Hand description file (.urdf, .xml or .yaml); None = the shipped hand.
    hand_config : str or None
        Its override config (:func:`~grasp_apso.model.planning_hand.load_planning_hand`).
    max_triangles : int
    attempt : int
        0 for the first try; the local engine retries a task once after a worker died.
    """

    object_id: str
    source_path: str
    data: bytes = field(repr=False)
    source_sha256: str
    scale: float
    pose: tuple[float, ...] | None
    table: bool
    seed: int
    options: dict[str, Any]
    options_json: str
    options_key: str
    hand_path: str | None = None
    hand_config: str | None = None
    max_triangles: int = DEFAULT_MAX_TRIANGLES
    attempt: int = 0


@dataclass
class Outcome:
    """The result of one task.

    ``ok``: ``columns`` holds the grasp rows (column -> list). Otherwise ``error_type`` /
    ``error`` say why and ``retry`` is False for a deterministic failure (a bad mesh, an
    object the hand cannot grasp: a rerun would fail the same way) and True otherwise
    (a crashed worker, an unexpected exception).
    """

    object_id: str
    source_path: str
    source_sha256: str | None
    ok: bool
    columns: dict[str, list] | None = None
    mesh_hash: str = ""
    n_grasps: int = 0
    error_type: str = ""
    error: str = ""
    retry: bool = False
    seconds: float = 0.0
    worker: str = ""
    #: The Ray node it ran on ("" in the local pool).
    node: str = ""


def init_worker() -> None:
    """Pool initializer: ignore SIGINT (the driver handles Ctrl-C), start a new session and
    warm up the kernels.

    A failing warm-up does not kill the process: :func:`worker_status` reports it, so that
    the driver can stop with the reason instead of a broken pool."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:  # its own session, like a Ray worker: the kernel's autogroup scheduler then gives
        os.setsid()  # each worker its own CPU share on a busy machine (no effect when idle)
    except OSError:
        pass
    _exit_with_parent()
    try:
        ensure_warm()
    except Exception as exc:  # noqa: BLE001 - reported by worker_status
        global _WARM_ERROR
        _WARM_ERROR = f"{type(exc).__name__}: {_first_line(exc)}"


#: Environment variable naming the driver's pid (set by the local engine for its workers).
DRIVER_PID_ENV = "GRASP_APSO_BATCH_DRIVER"


def _exit_with_parent(period: float = 1.0) -> None:
    """A daemon thread that ends this worker when the batch driver (pid in
    :data:`DRIVER_PID_ENV`) is gone, so that a killed batch leaves no planning orphans."""
    try:
        driver = int(os.environ.get(DRIVER_PID_ENV, "0"))
    except ValueError:
        return
    if driver <= 0:
        return

    def watch() -> None:
        while True:
            time.sleep(period)
            try:
                os.kill(driver, 0)
            except ProcessLookupError:
                os._exit(1)
            except PermissionError:
                pass

    threading.Thread(target=watch, name="exit-with-driver", daemon=True).start()


def worker_status(sleep: float = 0.0) -> tuple[int, str]:
    """(pid, warm-up error or "") of this worker, after ``sleep`` seconds (keeps it busy so
    that the pool starts its other processes)."""
    time.sleep(sleep)
    return os.getpid(), _WARM_ERROR


def warm_status(_: Any = None) -> tuple[int, str]:
    """Warm up (once) and report like :func:`worker_status` (the Ray start-up task)."""
    global _WARM_ERROR
    try:
        ensure_warm()
    except Exception as exc:  # noqa: BLE001 - reported to the driver
        _WARM_ERROR = f"{type(exc).__name__}: {_first_line(exc)}"
    return os.getpid(), _WARM_ERROR


def ensure_warm() -> float:
    """Call :func:`grasp_apso.search.planner.warm_up` once per process; returns seconds."""
    global _WARM
    if _WARM:
        return 0.0
    from ..search.planner import warm_up

    seconds = warm_up()
    _WARM = True
    return seconds


def _load_object(task: ObjectTask):
    name = os.path.basename(task.source_path) or "mesh.stl"
    with tempfile.TemporaryDirectory(prefix="grasp_apso_batch_") as tmp:
        local = os.path.join(tmp, name)
        with open(local, "wb") as handle:
            handle.write(task.data)
        try:
            return resolve_object(MeshFile(local, max_bytes=max(1, len(task.data)), max_triangles=task.max_triangles,
                                           scale=task.scale, name=task.object_id))
        except GraspApsoError as exc:
            exc.args = (str(exc).replace(local, task.source_path),)
            raise


def _plan(task: ObjectTask, obj):
    from ..search.planner import plan

    pose = np.eye(4) if task.pose is None else pose_to_matrix(task.pose[:3], task.pose[3:], field="pose")
    kwargs = {}
    if task.table:
        from ..model.scene import Scene

        vertices = np.asarray(obj.mesh.vertices) @ pose[:3, :3].T + pose[:3, 3]
        kwargs["scene"] = Scene.table_under(vertices)
    hand = load_planning_hand(task.hand_path, task.hand_config)  # cached: loaded once per process
    result = plan(obj, pose, PlanOptions(**task.options), rng=np.random.default_rng(task.seed),
                  hand=hand.hand, **kwargs)
    return pose, hand, result


def run_task(task: ObjectTask) -> Outcome:
    """Plan one object; never raises for a bad object (see :class:`Outcome`)."""
    t0 = time.perf_counter()
    worker = f"{socket.gethostname()}:{os.getpid()}"
    out = Outcome(task.object_id, task.source_path, task.source_sha256, ok=False, worker=worker)
    try:
        obj = _load_object(task)
        out.mesh_hash = obj.mesh_hash
        pose, hand, result = _plan(task, obj)
        candidates = tuple(result.candidates)
        if not any(c.valid for c in candidates):
            raise PlanningError("planning: no valid grasp found (try more particles or iterations)")
        common = {
            "object_id": task.object_id, "source_path": task.source_path,
            "source_sha256": task.source_sha256, "scale": float(task.scale),
            "mesh_hash": obj.mesh_hash, "hand_name": hand.name, "hand_hash": hand.hash,
            "options_key": task.options_key,
            "options": task.options_json, "seed": int(task.seed), "package_version": __version__,
            "planning_time": float(result.planning_time + result.preparation_time),
            "created": _dt.datetime.now(_dt.timezone.utc),
        }
        out.columns = candidate_rows(candidates, pose, common, wrist_angles=not is_general_hand(hand.hand))
        out.n_grasps = len(candidates)
        out.ok = True
    except GraspApsoError as exc:
        out.error_type, out.error, out.retry = type(exc).__name__, _first_line(exc), False
    except Exception as exc:  # noqa: BLE001 - a worker must report, not die
        out.error_type, out.error, out.retry = type(exc).__name__, _first_line(exc), True
    out.seconds = time.perf_counter() - t0
    return out


def run_task_warm(task: ObjectTask) -> Outcome:
    """:func:`run_task` after a once-per-process warm-up (the Ray task body); the outcome
    names the Ray node it ran on."""
    ensure_warm()
    out = run_task(task)
    out.node = _ray_node_id()
    return out


def _ray_node_id() -> str:
    """This process's Ray node id ("" outside a Ray worker)."""
    try:
        import ray

        return ray.get_runtime_context().get_node_id() if ray.is_initialized() else ""
    except Exception:  # noqa: BLE001 - Ray missing or not a Ray worker: no node id
        return ""


def _first_line(exc: BaseException, limit: int = 500) -> str:
    text = str(exc).strip()
    line = text.splitlines()[0] if text else type(exc).__name__
    return line[:limit]
