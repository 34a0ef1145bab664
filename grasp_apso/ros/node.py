"""The ROS 2 node ``grasp_apso``: a thin adapter over :func:`grasp_apso.search.planner.plan`.

Interface (names relative to the node, so ``/grasp_apso/...`` by default): service and
action ``~/plan_grasp`` (``grasp_apso_interfaces``; the action streams progress as
feedback and is cancellable), topic ``~/progress`` (one ``GraspProgress`` per iteration
of every plan), topic ``~/grasp_markers`` (``MarkerArray``, transient local: the last
grasp, its candidates' approaches, the pre-grasp hand and the scene) and one parameter
per node tunable (:mod:`grasp_apso.ros.parameters`, ``config/grasp_apso.yaml``). With
``grasp_database`` set, stored objects are answered from that database
(``grasp_source`` "database"; :mod:`.database_answers`).

This module builds the node and holds its callbacks (parameters: :mod:`.parameters`,
parsing: :mod:`.requests`, queue, threads, time bound, cancel: :mod:`.worker`, :mod:`.goals`). It loads
the planner's compiled kernels before it logs "ready". The callbacks are coroutines in a
``ReentrantCallbackGroup``: they check a request, reserve a place (or answer "busy"), hand
the job to the worker and ``await`` its Future, so the executor keeps serving while plans
run; whatever fails, they answer (``success: false``, "internal error", details in the
log). The servers keep a history of :data:`REQUEST_HISTORY` requests (reliable), more than
the node can ever hold; a reply the middleware drops is sent again (:mod:`.responses`). A
busy action goal is rejected in ``goal_callback``; a cancelled queued goal is answered at
once; when the last client of the service (or of the action) has left the graph (seen,
then gone: :mod:`.departures`), its requests are cancelled (checked every :data:`WATCH_PERIOD` s).
"""

from __future__ import annotations

import gc
import os
import signal
import sys
import threading
import traceback
import uuid
from typing import Any

import rclpy
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future
from std_msgs.msg import Header
from visualization_msgs.msg import MarkerArray

from grasp_apso_interfaces.action import PlanGrasp as PlanGraspAction
from grasp_apso_interfaces.msg import GraspProgress
from grasp_apso_interfaces.srv import PlanGrasp

from ..errors import GraspApsoError
from .conversions import fill_result, progress_msg, reply_header
from .departures import DepartureWatch
from .goals import GoalRegistry
from .job import Job
from .markers import grasp_markers
from .parameters import PARAMETER_NAMES, PARAMETERS, NodeParameters
from .plan_request import RequestKind
from .replies import Outcome, internal_error_message
from .requests import parse_request
from .responses import resend_dropped_responses
from .usage import usage_text, wants_help
from .worker import Worker

__all__ = ["GraspPlannerNode", "PARAMETERS", "PARAMETER_NAMES", "REQUEST_HISTORY", "main"]

NODE_NAME = "grasp_apso"
#: History depth of the service and action servers (requests held before they are read).
REQUEST_HISTORY = 1000
#: Period of the departed-client watch, s (two sightings in a row cancel: within 1 s).
WATCH_PERIOD = 0.2
_REQUESTS_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=REQUEST_HISTORY,
                           reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


class GraspPlannerNode(Node):
    """The ``grasp_apso`` node; see the module docstring for the interface."""

    def __init__(self, node_name: str = NODE_NAME, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.parameters = NodeParameters(self)  # raises for an invalid start-up value
        settings = self.parameters.settings
        self.worker = Worker(self, workers=settings["workers"], queue_length=settings["queue_length"],
                             database=self.parameters.database, hand=self.parameters.planning_hand.hand)
        self._goals = GoalRegistry()
        self._departures = DepartureWatch(RequestKind)
        self.get_logger().info("loading the planner's compiled kernels ...")
        seconds = self.worker.warm_up()
        if seconds is not None:
            self.get_logger().info(f"planner kernels loaded in {seconds:.2f} s")
        group = ReentrantCallbackGroup()
        self._progress_pub = self.create_publisher(GraspProgress, "~/progress", QoSProfile(
            depth=100, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE))
        self._marker_pub = self.create_publisher(MarkerArray, "~/grasp_markers", QoSProfile(
            depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self._service = self.create_service(PlanGrasp, "~/plan_grasp", self._on_plan_service,
                                            qos_profile=_REQUESTS_QOS, callback_group=group)
        resend_dropped_responses(self._service, self.log)  # see .responses: rmw can drop a reply
        self._action_server = ActionServer(
            self, PlanGraspAction, "~/plan_grasp", execute_callback=self._on_plan_goal,
            goal_callback=self._on_goal_request, cancel_callback=self._on_cancel, callback_group=group,
            goal_service_qos_profile=_REQUESTS_QOS, result_service_qos_profile=_REQUESTS_QOS,
            cancel_service_qos_profile=_REQUESTS_QOS)
        name = self.resolve_service_name("~/plan_grasp")
        self._client_endpoints = {RequestKind.SERVICE: name, RequestKind.ACTION: f"{name}/_action/send_goal"}
        self._watch = self.create_timer(WATCH_PERIOD, self._watch_clients, callback_group=MutuallyExclusiveCallbackGroup())
        db = self.parameters.database
        stored = (f", grasp database {db.path} ({len(db)} objects, {db.rows} grasps, read in "
                  f"{db.load_seconds:.2f} s)" if db is not None else "")
        self.get_logger().info(f"ready: service and action {name}, progress on {self._progress_pub.topic_name}, "
                               f"markers on {self._marker_pub.topic_name}, {self.worker.workers} worker(s){stored}")

    # ------------------------------------------------------------------ worker hooks
    def log(self, level: str, text: str) -> None:
        """Log from any thread (the worker's hook); one line per severity (rclpy raises
        ValueError when one call site logs at two severities)."""
        logger = self.get_logger()
        if level == "debug":
            logger.debug(text)
        elif level == "info":
            logger.info(text)
        elif level == "warning":
            logger.warning(text)
        else:
            logger.error(text)

    def on_progress(self, job: Job, stats: Any) -> None:
        """Worker hook: publish one iteration's progress (and the action feedback)."""
        header = Header(stamp=self.get_clock().now().to_msg(), frame_id=job.request.frame_id)
        msg = progress_msg(stats, job.request_id, job.request.options.algorithm, header)
        try:
            self._progress_pub.publish(msg)
            if job.goal_handle is not None:
                job.goal_handle.publish_feedback(PlanGraspAction.Feedback(progress=msg))
        except Exception:  # noqa: BLE001 -- progress must never stop a plan
            self.get_logger().warning(f"request {job.request_id}: progress not published\n{traceback.format_exc()}")

    def on_result(self, job: Job, result: Any) -> None:
        """Worker hook: publish the grasp, its candidates and the scene for RViz."""
        try:
            req = job.request
            self._marker_pub.publish(grasp_markers(result, reply_header(req), req.hand, req.scene))
        except Exception:  # noqa: BLE001 -- markers are best effort
            self.get_logger().warning(f"request {job.request_id}: markers not published\n{traceback.format_exc()}")

    # ------------------------------------------------------------------ requests
    async def _run(self, req: Any, goal_handle: Any = None) -> tuple[str, Outcome, Header]:
        """Check ``req``, queue it and await the worker's outcome (never raises). An action
        goal's place was reserved in :meth:`_on_goal_request`."""
        request_id = str(uuid.uuid4())
        header = Header(stamp=req.object_pose.header.stamp, frame_id=req.object_pose.header.frame_id)
        try:
            plan_request = parse_request(req, self.parameters.settings, request_id,
                                         RequestKind.SERVICE if goal_handle is None else RequestKind.ACTION)
        except GraspApsoError as exc:
            if goal_handle is not None:
                self.worker.release()
            self.get_logger().info(f"request {request_id}: refused: {exc}")
            return request_id, Outcome(False, str(exc)), header
        except Exception:  # noqa: BLE001 -- request boundary
            if goal_handle is not None:
                self.worker.release()
            self.get_logger().error(f"request {request_id}: internal error\n{traceback.format_exc()}")
            return request_id, Outcome(False, internal_error_message("the request's check", request_id)), header
        header = reply_header(plan_request)
        job = Job(plan_request, goal_handle=goal_handle)
        if goal_handle is None and (busy := self.worker.reserve()):  # (a goal's place: goal_callback)
            self.get_logger().info(f"request {request_id}: {busy}")
            return request_id, Outcome(False, busy), header
        try:
            future = self.worker.submit(job, self.executor)
            if self._goals.register(goal_handle, job):
                self.worker.cancel(job)  # cancelled before its job was registered (goals.py)
            outcome = await future
        finally:
            self._goals.remove(goal_handle)
        return request_id, outcome, header

    async def _answered(self, req: Any, msg: Any, goal_handle: Any = None) -> tuple[Any, Outcome]:
        """``msg`` filled with the answer to ``req``; an internal error is an answer too."""
        try:
            request_id, outcome, header = await self._run(req, goal_handle)
        except Exception:  # noqa: BLE001 -- request boundary: every request is answered
            self.get_logger().error(f"request: internal error in the node\n{traceback.format_exc()}")
            request_id, header = "", Header(frame_id=req.object_pose.header.frame_id)
            outcome = Outcome(False, internal_error_message("the node's callback", "unknown"))
        return self._fill(msg, request_id, outcome, header), outcome

    async def _on_plan_service(self, request: PlanGrasp.Request, response: PlanGrasp.Response):
        return (await self._answered(request, response))[0]

    def _on_goal_request(self, _goal: Any) -> GoalResponse:
        """Accept a goal only when a place is free (busy goals are rejected, not aborted)."""
        busy = self.worker.reserve()
        if busy:
            self.get_logger().info(f"action goal rejected: {busy}")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _on_cancel(self, goal_handle: Any) -> CancelResponse:
        """Cancel a goal: at once when it is queued, within one iteration when it plans."""
        job = self._goals.to_cancel(goal_handle)
        if job is not None:
            self.worker.cancel(job)
        return CancelResponse.ACCEPT

    async def _on_plan_goal(self, goal_handle: Any) -> PlanGraspAction.Result:
        result, outcome = await self._answered(goal_handle.request, PlanGraspAction.Result(), goal_handle)
        request_id = result.request_id
        if outcome.cancelled:
            # A queued goal is answered from the cancel callback, before rclpy marks the
            # goal as cancelling: let the executor finish that first (bounded).
            for _ in range(1000):
                if goal_handle.is_cancel_requested or not goal_handle.is_active:
                    break
                await self._yield()
        try:
            if outcome.cancelled and goal_handle.is_cancel_requested:
                goal_handle.canceled()
            elif outcome.success:
                goal_handle.succeed()
            else:
                goal_handle.abort()
        except Exception:  # noqa: BLE001 -- e.g. the goal was already finished
            self.get_logger().warning(f"request {request_id}: cannot set the goal state\n{traceback.format_exc()}")
        return result

    def _yield(self) -> Future:
        """A Future completed by the executor's next task (lets other callbacks run)."""
        future = Future()
        self.executor.create_task(lambda: future.set_result(None))
        return future

    def _fill(self, msg: Any, request_id: str, outcome: Outcome, header: Header) -> Any:
        msg.success = bool(outcome.success)
        msg.message = outcome.message
        msg.request_id = request_id
        msg.configuration.header = header
        msg.wrist_pose.header = header
        msg.planning_time = float(outcome.worker_time)
        if outcome.result is not None:
            try:
                fill_result(msg, outcome.result, header, outcome.worker_time, outcome.source, self.parameters.settings.hand)
            except Exception:  # noqa: BLE001 -- request boundary
                self.get_logger().error(f"request {request_id}: cannot convert the result\n{traceback.format_exc()}")
                msg.success = False
                msg.message = f"internal error while converting the result (request {request_id}; see the node's log)"
        return msg

    def _watch_clients(self) -> None:
        """Timer: cancel the requests of a kind whose clients all left the graph (seen there,
        then gone: :mod:`.departures`). With other clients of the same kind present,
        nothing is cancelled (rclpy tells how many clients are left, not which)."""
        kinds = self.worker.active_kinds()
        for kind, endpoint in self._client_endpoints.items():
            first, gone = self._departures.check(kind, kind in kinds, self.count_clients(endpoint) > 0)
            if first:
                self.get_logger().debug(f"departed-client watch: a {kind.value} client seen")
            if gone:
                n = self.worker.cancel_where(lambda j, k=kind: j.kind == k, "cancelled: the client left")
                if n:
                    self.get_logger().warning(f"no {kind.value} client left: cancelled {n} of its requests")

    # ------------------------------------------------------------------ shutdown
    def stop_worker(self, wait: bool = True) -> None:
        """Stop the running plans (within one iteration), drop queued ones, join the threads."""
        self.worker.stop(wait=wait)

    def destroy_node(self) -> None:
        self.stop_worker(wait=True)
        self._action_server.destroy()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Console script ``planner_node``: run the node until SIGINT / SIGTERM.

    The executor spins in a thread; the main thread waits for a signal with Python
    handlers (``SignalHandlerOptions.NO``: rclpy's handler can lose a SIGINT that arrives
    while the main thread waits in the executor). On the first signal the running plans
    stop (their callers are answered), queued requests are dropped, and the node and
    rclpy shut down: exit status 0. A second signal exits at once (130). Status 1 when the
    node cannot start (an invalid parameter; the message names it).
    """
    if wants_help(sys.argv[1:] if args is None else list(args)):
        sys.stdout.write(usage_text())
        return 0
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    signals: list[int] = []

    def on_signal(signum: int, _frame: Any) -> None:
        if stop.is_set() and signals:
            os.write(2, b"[grasp_apso] second signal: exiting now\n")
            os._exit(130)
        signals.append(signum)
        stop.set()

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    node = executor = spinner = None
    failures: list[BaseException] = []
    status = 0
    try:
        node = GraspPlannerNode()
        executor = MultiThreadedExecutor(num_threads=max(4, os.cpu_count() or 2))
        executor.add_node(node)
        # The ~100k objects of the imported libraries never die: keep them out of the
        # cyclic collector, whose full collections otherwise pause large requests.
        gc.freeze()

        def spin() -> None:
            try:
                executor.spin()
            except ExternalShutdownException:
                pass
            except BaseException as exc:  # noqa: BLE001 -- reported by the main thread
                if not stop.is_set():
                    failures.append(exc)
                    traceback.print_exc()
            finally:
                stop.set()

        spinner = threading.Thread(target=spin, name="grasp_apso_executor", daemon=True)
        spinner.start()
        while not stop.wait(0.5):
            pass
        if failures:
            status = 1
        elif signals:
            node.get_logger().info(f"{signal.Signals(signals[0]).name}: shutting down")
    except Exception as exc:  # noqa: BLE001 -- report start-up failures readably
        print(f"[grasp_apso] error: {exc}", file=sys.stderr)
        status = 1
    finally:
        if node is not None:
            node.stop_worker(wait=True)
        if executor is not None:
            executor.shutdown(timeout_sec=5.0)
        if spinner is not None:
            spinner.join(timeout=5.0)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return status


if __name__ == "__main__":
    sys.exit(main())
