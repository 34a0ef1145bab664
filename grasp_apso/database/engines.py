"""Batch engines: where the per-object tasks run.

Both take :class:`~grasp_apso.database.worker.ObjectTask` s one at a time (the driver keeps
a small window in flight, so mesh bytes do not pile up in memory) and hand back
``(task, Outcome)`` pairs as they finish.

- :class:`LocalEngine`: a ``concurrent.futures.ProcessPoolExecutor`` with the
  ``forkserver`` start method (``spawn`` where there is none): numba's threads and
  ``fork`` do not mix. Each worker ignores SIGINT and calls ``warm_up()`` once. A worker
  that dies (segfault, out of memory) breaks the pool: the pool is rebuilt and the tasks
  that were in flight are retried once; a task in flight at a second break is recorded
  as failed.
- :class:`RayEngine`: one Ray task per object (``num_cpus=1``, spread over the nodes:
  Ray's default would fill the driver's node first). Without an address it
  starts a private local Ray (``address="local"``, ``num_cpus=workers``, no dashboard);
  with one (``auto``, ``host:port``, ``ray://host:port``) it joins that cluster, whose
  nodes need grasp_apso installed (no shared file system: the mesh bytes travel with the
  task). A worker warms up on its first task.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing as mp
import os
import time
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

from ..errors import InputError, PlanningError
from .worker import (DRIVER_PID_ENV, ObjectTask, Outcome, init_worker, run_task, run_task_warm, warm_status,
                     worker_status)

__all__ = ["LocalEngine", "RayEngine", "SINGLE_THREAD_ENV", "worker_env"]

#: Thread pools of numeric libraries in workers: one thread each (a worker is one core).
SINGLE_THREAD_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
                     "NUMBA_NUM_THREADS": "1"}


def worker_env() -> dict[str, str]:
    """Environment of local workers: one thread per numeric library, and ``PYTHONPATH``
    starting with the folder this grasp_apso was imported from (a source checkout), so
    that the workers run the driver's code (Python 3.11's fork server ignores the
    driver's ``sys.path``)."""
    env = dict(SINGLE_THREAD_ENV)
    root = str(Path(__file__).resolve().parents[2])
    parts = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
    if not any(tag in root for tag in ("site-packages", "dist-packages")) and root not in parts:
        parts.insert(0, root)
    if parts:
        env["PYTHONPATH"] = os.pathsep.join(parts)
    env[DRIVER_PID_ENV] = str(os.getpid())
    return env


def _crash_outcome(task: ObjectTask, error_type: str, message: str) -> Outcome:
    return Outcome(task.object_id, task.source_path, task.source_sha256, ok=False,
                   error_type=error_type, error=message[:500], retry=True)


class LocalEngine:
    """Local worker processes.

    Parameters
    ----------
    workers : int
        Number of processes (>= 1).
    """

    name = "local"

    def __init__(self, workers: int):
        if workers < 1:
            raise InputError(f"--workers: expected at least 1, got {workers}", "--workers")
        self.workers = int(workers)
        self._pool: cf.ProcessPoolExecutor | None = None
        self._futures: dict[cf.Future, ObjectTask] = {}

    def start(self) -> float:
        """Start the processes and warm them up; returns the seconds it took."""
        t0 = time.perf_counter()
        self._pool = self._new_pool()
        # The pool starts processes on demand: short sleeping tasks until every worker has
        # answered, so that all are started and warmed up before the first object.
        pids: set[int] = set()
        for _ in range(50):
            status = list(self._pool.map(worker_status, [0.1] * self.workers))
            _check_warm(status, "--workers", self.close)
            pids |= {pid for pid, _ in status}
            if len(pids) >= self.workers:
                break
        return time.perf_counter() - t0

    def _new_pool(self) -> cf.ProcessPoolExecutor:
        method = "forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"
        ctx = mp.get_context(method)
        env = worker_env()
        saved = {k: os.environ.get(k) for k in env}
        os.environ.update(env)  # inherited by the fork server / spawned workers
        try:
            if method == "forkserver":
                ctx.set_forkserver_preload(["grasp_apso.database.worker"])
            pool = cf.ProcessPoolExecutor(max_workers=self.workers, mp_context=ctx, initializer=init_worker)
            try:
                pool.submit(worker_status, 0.0).result()  # starts the fork server with this environment
            except BrokenProcessPool:
                pool.shutdown(wait=False, cancel_futures=True)
                raise PlanningError("--workers: a worker process died at start-up (see the messages "
                                    "above)", "--workers") from None
        finally:
            for k, v in saved.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v
        return pool

    @property
    def in_flight(self) -> int:
        return len(self._futures)

    def submit(self, task: ObjectTask) -> None:
        if self._pool is None:
            raise RuntimeError("LocalEngine.submit: call start() first")
        self._futures[self._pool.submit(run_task, task)] = task

    def next_done(self, timeout: float) -> list[tuple[ObjectTask, Outcome]]:
        """Finished tasks, waiting up to ``timeout`` seconds for at least one."""
        if not self._futures:
            return []
        done, _ = cf.wait(list(self._futures), timeout=timeout, return_when=cf.FIRST_COMPLETED)
        out: list[tuple[ObjectTask, Outcome]] = []
        broken: list[ObjectTask] = []
        for fut in done:
            task = self._futures.pop(fut)
            try:
                out.append((task, fut.result()))
            except BrokenProcessPool:
                broken.append(task)
            except Exception as exc:  # noqa: BLE001 - e.g. an unpicklable result
                out.append((task, _crash_outcome(task, type(exc).__name__, str(exc))))
        if broken:
            out.extend(self._rebuild(broken))
        return out

    def _rebuild(self, broken: list[ObjectTask]) -> list[tuple[ObjectTask, Outcome]]:
        """A worker died: new pool; in-flight tasks retried once, else recorded."""
        broken += list(self._futures.values())
        self._futures.clear()
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
        self._pool = self._new_pool()
        failed = []
        for task in broken:
            if task.attempt >= 1:
                failed.append((task, _crash_outcome(task, "WorkerDied", "a worker process died while "
                                                    "planning this object (twice)")))
            else:
                self.submit(ObjectTask(**{**task.__dict__, "attempt": task.attempt + 1}))
        return failed

    def close(self, cancel: bool = False) -> None:
        """Stop the pool; ``cancel`` drops queued tasks and kills running ones."""
        pool, self._pool = self._pool, None
        if pool is None:
            return
        if cancel:
            procs = list(getattr(pool, "_processes", {}).values())
            pool.shutdown(wait=False, cancel_futures=True)
            for p in procs:
                if p.is_alive():
                    p.terminate()
            for p in procs:
                p.join(timeout=5)
        else:
            pool.shutdown(wait=True)
        self._futures.clear()


def _check_warm(status: list[tuple[int, str]], field: str, close) -> None:
    """Raise PlanningError (after ``close()``) when a worker could not warm up."""
    errors = sorted({e for _, e in status if e})
    if errors:
        close(cancel=True)
        raise PlanningError(f"{field}: the workers cannot plan (warm_up failed: {errors[0]})", field)


#: Where Ray keeps the token of its token authentication when RAY_AUTH_TOKEN_PATH is unset.
RAY_DEFAULT_TOKEN = os.path.join("~", ".ray", "auth_token")


def _token_auth_as_ray_start() -> None:
    """Join a cluster with the authentication ``ray start`` chose for it.

    Ray 2.60's ``ray start`` turns token authentication on when ``RAY_AUTH_MODE`` is unset and
    a token exists (``~/.ray/auth_token``, which any local ``ray.init()`` writes), but a driver
    joining with ``ray.init(address=...)`` then sends no token and is refused. Do as ``ray
    start`` does; an explicit ``RAY_AUTH_MODE`` is left as it is. Call it before the first
    ``import ray`` of the process (Ray reads the mode once).
    """
    if "RAY_AUTH_MODE" in os.environ:
        return
    path = os.environ.get("RAY_AUTH_TOKEN_PATH") or os.path.expanduser(RAY_DEFAULT_TOKEN)
    if os.environ.get("RAY_AUTH_TOKEN") or os.path.isfile(path):
        os.environ["RAY_AUTH_MODE"] = "token"


def _chain(exc: BaseException | None, limit: int = 10) -> list[BaseException]:
    """``exc`` and its causes / contexts (at most ``limit``)."""
    out: list[BaseException] = []
    while exc is not None and len(out) < limit:
        out.append(exc)
        exc = exc.__cause__ or exc.__context__
    return out


class RayEngine:
    """Ray tasks, one per object.

    Parameters
    ----------
    workers : int or None
        CPUs of the local Ray this starts (None: all cores); ignored with an ``address``.
    address : str or None
        A cluster to join (``auto``, ``host:port`` or ``ray://host:port``); None starts a
        private local Ray and shuts it down at :meth:`close`.
    """

    name = "ray"

    def __init__(self, workers: int | None = None, address: str | None = None):
        self.workers = workers
        self.address = address
        self._ray: Any = None
        self._remote: Any = None
        self._refs: dict[Any, ObjectTask] = {}
        self._started_here = False

    def start(self) -> float:
        t0 = time.perf_counter()
        if self.address:
            _token_auth_as_ray_start()  # before Ray is imported: it reads the mode once
        try:
            import ray
        except ImportError:
            raise InputError("--ray: Ray is not installed (pip install ray==2.60.0)", "--ray") from None
        self._ray = ray
        os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
        try:
            if self.address:
                ray.init(address=self.address, runtime_env={"env_vars": dict(SINGLE_THREAD_ENV)},
                         log_to_driver=False)
            else:
                # A private local Ray: its workers import grasp_apso as the driver does.
                env = {"env_vars": worker_env()}
                ray.init(address="local", num_cpus=self.workers or os.cpu_count() or 1,
                         include_dashboard=False, runtime_env=env, log_to_driver=False,
                         object_store_memory=256 * 1024 * 1024)
        except Exception as exc:  # noqa: BLE001 - ConnectionError, RuntimeError, ValueError ...
            where = self.address or "a local Ray"
            hint = ""
            if any("InvalidAuthToken" in str(e) or "AuthenticationError" in str(e) for e in _chain(exc)):
                hint = (" (the cluster wants a token: set RAY_AUTH_MODE=token and RAY_AUTH_TOKEN_PATH "
                        "to the token file its nodes use)")
            raise InputError(f"--ray: cannot start or join {where}: {type(exc).__name__}: {exc}{hint}",
                             "--ray") from None
        self._started_here = True
        self._remote = ray.remote(num_cpus=1, max_retries=1, scheduling_strategy="SPREAD")(run_task_warm)
        cpus = int(ray.cluster_resources().get("CPU", 1))
        self.workers = cpus
        warm = ray.remote(num_cpus=1, scheduling_strategy="SPREAD")(warm_status)
        _check_warm(ray.get([warm.remote(i) for i in range(cpus)]), "--ray", self.close)
        return time.perf_counter() - t0

    @property
    def in_flight(self) -> int:
        return len(self._refs)

    def submit(self, task: ObjectTask) -> None:
        self._refs[self._remote.remote(task)] = task

    def next_done(self, timeout: float) -> list[tuple[ObjectTask, Outcome]]:
        if not self._refs:
            return []
        ready, _ = self._ray.wait(list(self._refs), num_returns=1, timeout=timeout)
        if ready:  # collect everything else that is ready too, without waiting
            more, _ = self._ray.wait([r for r in self._refs if r not in ready],
                                     num_returns=len(self._refs) - len(ready), timeout=0)
            ready = ready + more
        out = []
        for ref in ready:
            task = self._refs.pop(ref)
            try:
                out.append((task, self._ray.get(ref)))
            except Exception as exc:  # noqa: BLE001 - RayTaskError, WorkerCrashedError ...
                out.append((task, _crash_outcome(task, type(exc).__name__, str(exc))))
        return out

    def close(self, cancel: bool = False) -> None:
        if self._ray is None:
            return
        if cancel:
            for ref in list(self._refs):
                try:
                    self._ray.cancel(ref, force=True)
                except Exception:  # noqa: BLE001 - already finished
                    pass
        self._refs.clear()
        if self._started_here:
            self._ray.shutdown()
        self._ray = None
