"""Every request is answered (issue 19.1), in process: the node's log hook takes every
severity in any order, and an exception anywhere in a job -- a hook, the run -- ends in
a reply ("internal error") and frees the job's place. Real rclpy nodes and Futures."""
import threading

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')

from grasp_apso.model.hand import load_hand  # noqa: E402
from grasp_apso.model.object_source import BuiltinObject  # noqa: E402
from grasp_apso.ros.job import Job, Stage  # noqa: E402
from grasp_apso.ros.node import GraspPlannerNode  # noqa: E402
from grasp_apso.ros.plan_request import PlanRequest  # noqa: E402
from grasp_apso.ros.worker import Worker  # noqa: E402
from grasp_apso.search.options import PlanOptions  # noqa: E402


@pytest.fixture
def context():
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx)
    try:
        yield ctx
    finally:
        rclpy.shutdown(context=ctx)


def test_the_log_hook_takes_an_error_after_an_info_and_every_order(context):
    """rclpy raised "Logger severity cannot be changed between calls" when one call site
    logged at two severities; the hook logs each severity from its own line."""
    node = GraspPlannerNode(node_name='grasp_apso_log_test', context=context)
    try:
        node.get_logger().set_level(rclpy.logging.LoggingSeverity.DEBUG)
        for level in ('info', 'error', 'debug', 'warning', 'info', 'debug', 'error'):
            node.log(level, f'a {level} line')  # raised ValueError on the second severity before
        node.worker.log('error', 'through the worker too')
    finally:
        node.destroy_node()


class FaultyHooks:
    """Hooks of a node whose progress publisher fails, and a log that fails at ERROR."""

    def __init__(self):
        self.lines = []

    def log(self, level, text):
        if level == 'error':
            raise RuntimeError('the log is broken too')
        self.lines.append((level, text))

    def on_progress(self, job, stats):
        raise RuntimeError('progress hook failed')

    def on_result(self, job, result):
        pass


def _job(request_id, iterations=5, timeout=30.0):
    request = PlanRequest(request_id=request_id, frame_id='world', stamp=(0, 0), pose=np.eye(4),
                          source=BuiltinObject('cube'),
                          options=PlanOptions(particles=10, iterations=iterations, neighborhood_size=5),
                          seed=1, hand=load_hand(), timeout=timeout)
    return Job(request)


def test_an_exception_in_a_hook_or_the_log_still_ends_in_a_reply():
    worker = Worker(FaultyHooks(), workers=1, queue_length=2)
    try:
        answers = []
        for i in range(3):  # more than one: the place of each is freed
            assert worker.reserve() is None
            job = _job(f'r{i}')
            done = threading.Event()
            future = worker.submit(job, executor=None)
            future.add_done_callback(lambda _f: done.set())
            assert done.wait(60.0), f'request r{i} never answered'
            answers.append(future.result())
        assert all(not a.success and a.message.startswith('internal error during planning') for a in answers), \
            [a.message for a in answers]
        assert worker.pending == 0
    finally:
        worker.stop(wait=True)


def test_a_job_is_answered_when_its_run_fails_before_planning():
    """A source the resolver does not know (a bug, not bad input) is an internal error
    named by its stage, and the place is freed."""
    worker = Worker(FaultyHooks(), workers=1, queue_length=0)
    try:
        job = _job('bad')
        object.__setattr__(job.request, 'source', 'not a source')
        assert worker.reserve() is None
        done = threading.Event()
        future = worker.submit(job, executor=None)
        future.add_done_callback(lambda _f: done.set())
        assert done.wait(30.0)
        assert not future.result().success
        assert future.result().message.startswith('internal error during validation'), future.result().message
        assert worker.pending == 0 and job.stage is Stage.VALIDATION
    finally:
        worker.stop(wait=True)


class DroppingService:
    """Sends like rclpy's Service does when rmw drops a response: the first ``drops``
    sends only raise rclpy's RuntimeWarning (the client gets nothing), the next one works."""

    def __init__(self, drops):
        self.drops, self.sent, self.tries = drops, [], 0

    def send_response(self, response, header):
        import warnings

        self.tries += 1
        if self.tries <= self.drops:
            warnings.warn('failed to send response (timeout): client will not receive response', RuntimeWarning)
            return
        self.sent.append((response, header))


def test_a_response_dropped_by_the_middleware_is_sent_again():
    import warnings

    from grasp_apso.ros import responses
    from grasp_apso_interfaces.srv import PlanGrasp

    logged = []
    service = DroppingService(drops=3)
    responses.resend_dropped_responses(service, lambda level, text: logged.append((level, text)))
    response = PlanGrasp.Response(request_id='abc')
    service.send_response(response, 'header')
    assert service.sent == [(response, 'header')] and service.tries == 4
    assert logged and logged[0][0] == 'info' and 'after 3 dropped tries' in logged[0][1]
    # Never sent: bounded, and said at ERROR.
    hopeless = DroppingService(drops=10 ** 6)
    responses.resend_dropped_responses(hopeless, lambda level, text: logged.append((level, text)))
    hopeless.send_response(response, 'header')
    assert hopeless.tries == responses.RETRIES + 1 and not hopeless.sent
    assert logged[-1][0] == 'error' and 'given up' in logged[-1][1]
    # Other warnings still reach the user.
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter('always')
        responses.resend_dropped_responses(service, lambda level, text: None)
        warnings.warn('something else', UserWarning)
    assert [str(w.message) for w in seen] == ['something else']
