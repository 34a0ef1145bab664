"""The node in its own process (``python -m grasp_apso.ros.node`` with the shipped parameter
file), a client in this process and a progress subscriber in a third process.

Checks the result and the progress count seen by the other process, then that SIGINT
(and SIGTERM in the middle of a plan) stops the node cleanly: exit status 0 within 10 s.
"""
import os
import re
import signal
import subprocess
import threading

import pytest

rclpy = pytest.importorskip('rclpy')

from grasp_apso_interfaces.srv import PlanGrasp  # noqa: E402

from node_helpers import (  # noqa: E402
    DISCOVERY_TIMEOUT, DYING_CLIENT_SCRIPT, PYTHON, REPO_ROOT, SUBSCRIBER_SCRIPT, LineReader, burst_calls,
    identity_pose, ros_env, wait_future)

from grasp_apso.model.hand import JOINT_NAMES  # noqa: E402
from grasp_apso.ros.node import PARAMETER_NAMES  # noqa: E402

PARAMS_FILE = os.path.join(REPO_ROOT, 'config', 'grasp_apso.yaml')
SERVICE = '/grasp_apso/plan_grasp'
TOPIC = '/grasp_apso/progress'


def test_parameter_file_lists_every_parameter():
    import yaml

    from grasp_apso.tunables import yaml_text

    with open(PARAMS_FILE, encoding='utf-8') as handle:
        text = handle.read()
    assert text == yaml_text()
    params = yaml.safe_load(text)['grasp_apso']['ros__parameters']
    assert set(params) == set(PARAMETER_NAMES)


def _start_node(*extra_args):
    return subprocess.Popen(
        [PYTHON, '-m', 'grasp_apso.ros.node', '--ros-args', '--params-file', PARAMS_FILE, *extra_args],
        cwd=REPO_ROOT, env=ros_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _stop(proc, sig=signal.SIGINT, timeout=10.0):
    """Send ``sig`` and wait; kill (and fail) if it does not exit in time."""
    if proc.poll() is None:
        proc.send_signal(sig)
    try:
        return proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(timeout=5.0)
        return None


@pytest.fixture
def client_context():
    context = rclpy.context.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('grasp_apso_process_test_client', context=context)
    executor = rclpy.executors.SingleThreadedExecutor(context=context)
    executor.add_node(node)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    try:
        yield node
    finally:
        executor.shutdown(timeout_sec=5.0)
        thread.join(timeout=5.0)
        node.destroy_node()
        rclpy.shutdown(context=context)


def test_node_process_with_client_and_progress_subscriber_processes(client_context):
    node_proc = _start_node('-p', 'particles:=20')
    node_out = LineReader(node_proc.stdout)
    listener = subprocess.Popen([PYTHON, '-c', SUBSCRIBER_SCRIPT, TOPIC], cwd=REPO_ROOT, env=ros_env(),
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    listener_out = LineReader(listener.stdout)
    try:
        client = client_context.create_client(PlanGrasp, SERVICE)
        assert client.wait_for_service(timeout_sec=DISCOVERY_TIMEOUT), node_out.text()
        assert listener_out.wait(lambda lines: 'matched' in lines, DISCOVERY_TIMEOUT), listener_out.text()

        req = PlanGrasp.Request()
        req.object_name = 'cube'
        req.object_pose = identity_pose('world')
        req.iterations, req.seed = 6, 11  # particles from the -p override

        # Discovery is not symmetric: the listener can see the node's publisher before that
        # publisher knows the listener, and what it publishes meanwhile is lost (volatile
        # QoS); a plan takes a few tens of ms. Probe until the listener hears a plan.
        def heard(request_id):
            return lambda lines: any(l.startswith(f'progress {request_id} ') for l in lines)

        for _ in range(10):
            probe = wait_future(client.call_async(req), 60.0)
            if listener_out.wait(heard(probe.request_id), 2.0):
                break
        else:
            pytest.fail(f'the listener heard none of 10 plans\n{listener_out.text()}')

        res = wait_future(client.call_async(req), 60.0)
        assert res.success, res.message
        assert list(res.configuration.name) == list(JOINT_NAMES)
        assert res.wrist_pose.header.frame_id == 'world'
        assert '20 particles' in node_out.wait(
            lambda lines: next((l for l in lines if res.request_id in l and 'particles' in l), ''), 5.0)

        def progress_lines(lines):
            mine = [l for l in lines if l.startswith(f'progress {res.request_id} ')]
            return mine if len(mine) >= res.iterations_run else None

        got = listener_out.wait(progress_lines, 10.0)
        assert got, listener_out.text()
        assert [int(l.split()[2]) for l in got] == list(range(1, res.iterations_run + 1))
    finally:
        status = _stop(node_proc, signal.SIGINT)
        _stop(listener, signal.SIGINT)
    assert status == 0, f'node exit status {status}\n{node_out.text()}'
    assert 'Traceback' not in node_out.text(), node_out.text()


def test_sigterm_during_a_plan_exits_cleanly(client_context):
    node_proc = _start_node()
    node_out = LineReader(node_proc.stdout)
    try:
        client = client_context.create_client(PlanGrasp, SERVICE)
        assert client.wait_for_service(timeout_sec=DISCOVERY_TIMEOUT), node_out.text()
        req = PlanGrasp.Request()
        req.object_name = 'sphere'
        req.object_pose = identity_pose('world')
        req.particles, req.iterations = 20, 10000
        client.call_async(req)  # never answered: the node stops in the middle
        assert node_out.wait(lambda lines: any('10000 iterations' in l for l in lines), 30.0), node_out.text()
    finally:
        status = _stop(node_proc, signal.SIGTERM)
    assert status == 0, f'node exit status {status}\n{node_out.text()}'
    assert 'Traceback' not in node_out.text(), node_out.text()


def _request(name='cube', **fields):
    req = PlanGrasp.Request()
    req.object_name = name
    req.object_pose = identity_pose('world')
    for key, value in fields.items():
        setattr(req, key, value)
    return req


def test_a_burst_of_30_requests_is_answered_completely(client_context):
    """10 clients x 3 requests at once (issue 14.1): every request gets an answer, a plan
    or "busy"; none is lost (the servers keep a history of 1000 requests)."""
    node_proc = _start_node()
    node_out = LineReader(node_proc.stdout)
    try:
        batches = [[_request(('cube', 'sphere', 'barrel')[(c + r) % 3], particles=30, iterations=20, seed=c)
                    for r in range(3)] for c in range(10)]
        answers = burst_calls(client_context.context, SERVICE, batches, 10, timeout=90.0)
    finally:
        status = _stop(node_proc, signal.SIGINT)
    lost = [i for i, (res, _) in enumerate(answers) if res is None]
    assert not lost, (f'{len(lost)} of 30 requests never answered ({lost}); the node logged '
                      f'{len(_burst_requests_logged(node_out.text()))} of them (30: answers lost on the way '
                      f'back)\n{node_out.text()[-3000:]}')
    planned = [res for res, _ in answers if not res.message.startswith('busy')]
    busy = [res for res, _ in answers if res.message.startswith('busy')]
    assert len(planned) + len(busy) == 30
    assert len(planned) >= 5  # at least the running one and the queue_length 4 behind it
    assert all(res.success for res in planned), [res.message for res in planned if not res.success]
    assert all(not res.success and 'queue_length' in res.message for res in busy)
    assert status == 0, node_out.text()


def _burst_requests_logged(text):
    """The distinct ids of the requests the node's log shows taken or refused as busy
    (``request <id>: object ...`` / ``request <id>: busy: ...``; the clients' empty round
    trips, refused as invalid, not counted)."""
    return set(re.findall(r'request ([0-9a-f-]{36}): (?:object |busy:)', text))


def _log_time(line):
    """The epoch seconds of a node log line ``[LEVEL] [1796229075.278472807] [grasp_apso]: ...``."""
    return float(line.split('] [', 1)[1].split(']', 1)[0])


@pytest.mark.parametrize('how', ['sigint', 'sigkill'])
def test_a_client_that_leaves_has_its_requests_cancelled_within_a_second(client_context, how):
    """A client stopped mid-request (Ctrl-C: it says goodbye; SIGKILL: it cannot, and the
    node learns it from the participant's lease, so that client runs with the short-lease
    profile config/fastdds_short_lease.xml): its running plan and two queued ones are
    cancelled within 1 s of its departure, and the next caller is served at once."""
    import time

    node_proc = _start_node('--log-level', 'grasp_apso:=debug')  # (the watch's first sighting)
    node_out = LineReader(node_proc.stdout)
    extra = {'FASTRTPS_DEFAULT_PROFILES_FILE': os.path.join(REPO_ROOT, 'config', 'fastdds_short_lease.xml')}
    dying = subprocess.Popen([PYTHON, '-c', DYING_CLIENT_SCRIPT, SERVICE], cwd=REPO_ROOT,
                             env=ros_env(**(extra if how == 'sigkill' else {})),
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    dying_out = LineReader(dying.stdout)
    try:
        assert dying_out.wait(lambda lines: 'sent' in lines, 60.0), dying_out.text()
        assert node_out.wait(lambda lines: any('10000 iterations' in l for l in lines), 30.0), node_out.text()
        # The node's graph shows a new client a few hundred ms after its requests arrive:
        # only a client it has seen can be seen leaving (before, the watch cancelled on the
        # second check whoever the client was, which this test took for the departure).
        assert node_out.wait(lambda lines: any('a service client seen' in l for l in lines), 30.0), node_out.text()
        assert 'client left' not in node_out.text(), node_out.text()
        if how == 'sigkill':
            dying.kill()
            dying.wait(timeout=10.0)
        else:
            # 30 s: twice on this 2-core machine loaded beside the suite, the client's
            # rclpy shutdown took over 10 s (the node's side is timed from its exit)
            assert _stop(dying, signal.SIGINT, timeout=30.0) is not None
        left = time.time()
        line = node_out.wait(lambda lines: next((l for l in lines if 'no service client left: cancelled 3' in l), ''),
                             15.0)
        assert line, node_out.text()
        print(how, 'cancelled after', round(_log_time(line) - left, 3), 's')
        assert _log_time(line) - left < 1.0, (line, left)
        client = client_context.create_client(PlanGrasp, SERVICE)
        assert client.wait_for_service(timeout_sec=DISCOVERY_TIMEOUT)
        t0 = time.monotonic()
        res = wait_future(client.call_async(_request(particles=20, iterations=3)), 30.0)
        assert res.success, res.message
        assert time.monotonic() - t0 < 5.0
    finally:
        _stop(dying, signal.SIGKILL)
        status = _stop(node_proc, signal.SIGINT)
    assert status == 0, node_out.text()


def test_debug_logging_answers_every_request(client_context):
    """With ``--log-level grasp_apso:=debug`` (issue 19: one logging call site at several
    severities raised in rclpy and wedged the node) every request is answered: a plan, a
    refused request, a malformed mesh, a planning error, and a plan after them."""
    from grasp_apso.ros.conversions import arrays_to_mesh

    node_proc = _start_node('--log-level', 'grasp_apso:=debug')
    node_out = LineReader(node_proc.stdout)
    try:
        assert node_out.wait(lambda lines: any('ready' in l for l in lines), 120.0), node_out.text()
        client = client_context.create_client(PlanGrasp, SERVICE)
        assert client.wait_for_service(timeout_sec=DISCOVERY_TIMEOUT), node_out.text()
        tiny = _request('')
        tiny.mesh = arrays_to_mesh([[0, 0, 0], [4e-3, 0, 0], [0, 4e-3, 0], [0, 0, 4e-3]],
                                   [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
        nan = _request('')
        nan.mesh = arrays_to_mesh([[0, 0, 0], [float('nan'), 0, 0], [0, 0.05, 0], [0, 0, 0.05]],
                                  [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
        cases = [(_request(particles=20, iterations=5, seed=1), True, 'grasp found'),
                 (_request('teapot'), False, 'object_name'),
                 (nan, False, 'mesh'),
                 (tiny, False, 'too small'),
                 (_request('sphere', particles=20, iterations=5, seed=2), True, 'grasp found')]
        for req, success, words in cases:
            res = wait_future(client.call_async(req), 60.0)
            assert res.success is success, res.message
            assert words in res.message, res.message
    finally:
        status = _stop(node_proc, signal.SIGINT)
    text = node_out.text()
    assert status == 0, text
    assert 'Traceback' not in text and 'severity cannot be changed' not in text, text
    assert '[DEBUG]' in text or 'DEBUG' in text, text


def test_a_large_request_is_answered_within_its_time_bound(client_context):
    """1000 particles x 10000 iterations with plan_timeout 2 s: GRG's start and the swarm
    poll the deadline, the reply comes within 3.5 s of the request (issue 19.6)."""
    import time

    node_proc = _start_node('-p', 'plan_timeout:=2.0')
    node_out = LineReader(node_proc.stdout)
    try:
        client = client_context.create_client(PlanGrasp, SERVICE)
        assert client.wait_for_service(timeout_sec=DISCOVERY_TIMEOUT), node_out.text()
        assert node_out.wait(lambda lines: any('ready' in l for l in lines), 120.0), node_out.text()
        seconds = []
        for name, seed in (('sphere', 3), ('fish', 4)):
            req = _request(name, particles=1000, iterations=10000, seed=seed)
            t0 = time.monotonic()
            res = wait_future(client.call_async(req), 30.0)
            seconds.append(time.monotonic() - t0)
            print(res.message, len(res.grasps), res.iterations_run)
            assert 'timed out after 2 s' in res.message, res.message
            assert seconds[-1] < 3.5, (seconds, res.message)
    finally:
        status = _stop(node_proc, signal.SIGINT)
    print('round trips', seconds)
    assert status == 0, node_out.text()


def test_help_prints_the_usage_and_exits_without_starting_ros():
    """``planner_node --help``: usage and every parameter (from tunables), status 0, no node."""
    proc = subprocess.run([PYTHON, '-m', 'grasp_apso.ros.node', '--help'], cwd=REPO_ROOT, env=ros_env(),
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.startswith('usage: planner_node')
    for name in PARAMETER_NAMES:
        assert f'\n  {name} (' in proc.stdout, name
    assert '[INFO]' not in proc.stdout + proc.stderr  # no node was built


def test_the_first_request_after_ready_is_answered_at_once(client_context):
    """The node says "ready" after loading its kernels (issue 19.3): the first request's
    round trip is within 2 s of its planning time."""
    import time

    node_proc = _start_node()
    node_out = LineReader(node_proc.stdout)
    try:
        assert node_out.wait(lambda lines: any(': ready:' in l for l in lines), 180.0), node_out.text()
        lines = node_out.text().splitlines()
        assert any('planner kernels loaded in' in l for l in lines), node_out.text()
        client = client_context.create_client(PlanGrasp, SERVICE)
        assert client.wait_for_service(timeout_sec=DISCOVERY_TIMEOUT), node_out.text()
        t0 = time.monotonic()
        res = wait_future(client.call_async(_request('fish', seed=5)), 60.0)
        round_trip = time.monotonic() - t0
        assert res.success, res.message
        assert round_trip - res.planning_time < 2.0, (round_trip, res.planning_time)
    finally:
        status = _stop(node_proc, signal.SIGINT)
    assert status == 0, node_out.text()


def test_simulate_on_a_new_non_convex_mesh_is_answered_within_the_time_bound(client_context, tmp_path):
    """``simulate`` with a mesh the node has never seen (issue 19.4): its convex
    decomposition cannot end within ``plan_timeout``, yet the reply comes within it and
    carries the verified candidates, unsimulated (``sim_result`` -1), saying why."""
    import time

    import numpy as np
    import trimesh

    rng = np.random.default_rng(190404)
    # 36,864 triangles: CoACD took 7.2 s on a quiet machine (the 9,216 of a 96 x 48 torus took
    # 2.6 s there, within the bound, and the test failed: every returned grasp was simulated)
    torus = trimesh.creation.torus(major_radius=0.03, minor_radius=0.012, major_sections=192, minor_sections=96)
    torus.vertices += rng.normal(0.0, 2e-4, torus.vertices.shape)  # a mesh hash no cache holds
    mesh_dir = tmp_path / 'meshes'
    mesh_dir.mkdir()
    torus.export(str(mesh_dir / 'torus.stl'))
    timeout = 3.0  # a CoACD run of this torus takes far longer
    node_proc = _start_node('-p', f'plan_timeout:={timeout}', '-p', f'allowed_mesh_dir:={mesh_dir}',
                            '-p', f'cache_directory:={tmp_path / "cache"}')
    node_out = LineReader(node_proc.stdout)
    try:
        client = client_context.create_client(PlanGrasp, SERVICE)
        assert client.wait_for_service(timeout_sec=DISCOVERY_TIMEOUT), node_out.text()
        assert node_out.wait(lambda lines: any('ready' in l for l in lines), 120.0), node_out.text()
        req = _request('', mesh_uri=str(mesh_dir / 'torus.stl'), particles=30, iterations=10, seed=5,
                       simulate=True, max_grasps=3)
        t0 = time.monotonic()
        res = wait_future(client.call_async(req), 60.0)
        seconds = time.monotonic() - t0
    finally:
        status = _stop(node_proc, signal.SIGINT)
    print(res.success, res.message, seconds)
    assert seconds < timeout + 0.5, (seconds, res.message)
    assert res.success, res.message
    assert len(res.grasps) >= 1, res.message
    results = [g.sim_result for g in res.grasps]
    # the decomposition or the simulation ran out of time: what was not simulated says so
    assert -1 in results, (results, res.message)
    assert 'not simulated' in res.message or 'simulation stopped' in res.message, res.message
    assert status == 0, node_out.text()
