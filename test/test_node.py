"""The grasp_apso node in this process, clients in this process, over real DDS (no launch).

The node spins in a MultiThreadedExecutor on a background thread, the clients in
another executor on another thread (``node_helpers.SpinningNode``: no entity is destroyed
while its executor spins); the test thread waits on futures and events with timeouts. Plans are kept small (20 particles, <= 8 iterations) so the module runs in
well under a minute on 2 cores.
"""
import math
import os
import threading
import time

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')

from action_msgs.msg import GoalStatus  # noqa: E402
from rclpy.action import ActionClient  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from visualization_msgs.msg import Marker, MarkerArray  # noqa: E402

from grasp_apso_interfaces.action import PlanGrasp as PlanGraspAction  # noqa: E402
from grasp_apso_interfaces.msg import GraspProgress  # noqa: E402
from grasp_apso_interfaces.srv import PlanGrasp  # noqa: E402

from node_helpers import (  # noqa: E402
    DISCOVERY_TIMEOUT, ProgressCounter, SpinningNode, identity_pose, table_pose, wait_for, wait_future)

from grasp_apso import objects  # noqa: E402
from grasp_apso.ros.conversions import arrays_to_mesh, arrays_to_packed  # noqa: E402
from grasp_apso.model.hand import FINGER_NAMES, JOINT_NAMES, load_hand  # noqa: E402
from grasp_apso.ros.node import PARAMETER_NAMES, PARAMETERS, GraspPlannerNode  # noqa: E402

DEFAULTS = {spec.name: spec.default for spec in PARAMETERS}

SMALL = dict(particles=20, iterations=8, seed=7)
CALL_TIMEOUT = 60.0


class Harness:
    """The node and a client node, each spun by its own executor.

    Every entity of the client node lives as long as the module (see
    :class:`node_helpers.SpinningNode` for why nothing is destroyed while it spins);
    tests that need short-lived entities make a ``SpinningNode`` of their own.
    """

    def __init__(self, context, server, client, mesh_dir):
        from rcl_interfaces.srv import GetParameters, SetParameters

        self.context = context
        self.server = server
        self.node = server.node
        self.client_spinner = client
        self.client_node = client.node
        self.mesh_dir = mesh_dir
        self.client = self.client_node.create_client(PlanGrasp, '/grasp_apso/plan_grasp')
        self.set_params_client = self.client_node.create_client(SetParameters, '/grasp_apso/set_parameters')
        self.get_params_client = self.client_node.create_client(GetParameters, '/grasp_apso/get_parameters')
        self.action_client = ActionClient(self.client_node, PlanGraspAction, '/grasp_apso/plan_grasp')
        self.progress = ProgressCounter()
        self.progress_sub = self.client_node.create_subscription(
            GraspProgress, '/grasp_apso/progress', self.progress,
            QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))

    def wait(self, future, timeout=CALL_TIMEOUT, extra=()):
        """The future's result; fails at once when an executor of the harness died."""
        return wait_future(future, timeout, spinners=(self.server, self.client_spinner, *extra))

    def call(self, request, timeout=CALL_TIMEOUT):
        return self.wait(self.client.call_async(request), timeout)

    def set_parameters(self, **values):
        """Set node parameters through the node API (the same callbacks as over ROS)."""
        results = self.node.set_parameters([Parameter(k, value=v) for k, v in values.items()])
        assert all(r.successful for r in results), [r.reason for r in results]


def sphere_request(pose=None, packed=False, **fields):
    """A request with the built-in sphere sent inline, as shape_msgs/Mesh or packed."""
    sphere = builtin_objects.builtin('sphere')
    req = PlanGrasp.Request()
    if packed:
        req.mesh_vertices, req.mesh_triangles = arrays_to_packed(sphere.mesh.vertices, sphere.mesh.faces)
    else:
        req.mesh = arrays_to_mesh(sphere.mesh.vertices, sphere.mesh.faces)
    req.object_pose = pose if pose is not None else identity_pose()
    for key, value in {**SMALL, **fields}.items():
        setattr(req, key, value)
    return req


def builtin_request(name='sphere', **fields):
    req = PlanGrasp.Request()
    req.object_name = name
    req.object_pose = identity_pose()
    for key, value in {**SMALL, **fields}.items():
        setattr(req, key, value)
    return req


@pytest.fixture(scope='module')
def mesh_dir(tmp_path_factory):
    """An allowed mesh directory with good and bad files, and a file outside it."""
    root = tmp_path_factory.mktemp('meshes')
    allowed = root / 'allowed'
    allowed.mkdir()
    outside = root / 'outside'
    outside.mkdir()
    box = builtin_objects.builtin('cube').mesh.copy()
    box.export(str(allowed / 'cube.stl'))
    box.export(str(outside / 'secret.stl'))
    (allowed / 'garbage.stl').write_bytes(b'\x00\x01 this is not an STL file at all \xff' * 3)
    (allowed / 'cube.xyz').write_text('0 0 0\n1 1 1\n')
    (allowed / 'folder.stl').mkdir()
    (allowed / 'empty.obj').write_text('')
    os.symlink(str(outside / 'secret.stl'), str(allowed / 'link.stl'))
    return allowed


@pytest.fixture(scope='module')
def ros(mesh_dir):
    context = rclpy.context.Context()
    rclpy.init(context=context)
    node = GraspPlannerNode(context=context, parameter_overrides=[
        Parameter('queue_length', value=2),
        Parameter('allowed_mesh_dir', value=str(mesh_dir)),
        Parameter('particles', value=20),
        Parameter('iterations', value=8),
    ])
    server = SpinningNode(context, 'grasp_apso', num_threads=4, node=node)
    client = SpinningNode(context, 'grasp_apso_test_client')
    harness = Harness(context, server, client, mesh_dir)  # entities first, then spin
    server.start()
    client.start()
    try:
        assert harness.client.wait_for_service(timeout_sec=DISCOVERY_TIMEOUT), 'service not found'
        assert harness.action_client.wait_for_server(timeout_sec=DISCOVERY_TIMEOUT), 'action not found'
        # Progress is volatile: make sure the node's publisher has matched our subscriber.
        assert wait_for(lambda: node._progress_pub.get_subscription_count() >= 1
                        and harness.progress_sub.get_publisher_count() >= 1, DISCOVERY_TIMEOUT)
        yield harness
    finally:
        server.close()
        client.close()
        rclpy.shutdown(context=context)


def _distance_to_surface(mesh, points):
    """Exact distance (m) of each point to the mesh's triangles (brute force)."""
    tris = np.asarray(mesh.triangles)
    out = []
    for point in points:
        closest = objects.trimesh.triangles.closest_point(tris, np.repeat(point[None], len(tris), 0))
        out.append(np.min(np.linalg.norm(closest - point, axis=1)))
    return np.array(out)


# --- a real mesh, a non-identity pose --------------------------------------------------------

@pytest.mark.parametrize('packed', [False, True], ids=['shape_msgs_mesh', 'packed_mesh'])
def test_mesh_request_in_table_frame(ros, packed):
    pose, matrix = table_pose()
    res = ros.call(sphere_request(pose, packed=packed))
    assert res.success, res.message
    assert res.request_id

    # 18 named joints in radians within the hand's limits.
    hand = load_hand()
    assert list(res.configuration.name) == list(JOINT_NAMES)
    q = np.array(res.configuration.position)
    assert q.shape == (18,) and np.all(np.isfinite(q))
    assert np.all(q >= hand.lower - 1e-9) and np.all(q <= hand.upper + 1e-9)
    assert res.configuration.header.frame_id == 'table'
    assert res.configuration.header.stamp.sec == 42

    # Wrist pose in the request's frame, a unit quaternion, near the object.
    assert res.wrist_pose.header.frame_id == 'table'
    o = res.wrist_pose.pose.orientation
    assert math.isclose(math.sqrt(o.x ** 2 + o.y ** 2 + o.z ** 2 + o.w ** 2), 1.0, abs_tol=1e-6)
    wp = res.wrist_pose.pose.position
    assert np.linalg.norm(np.array([wp.x, wp.y, wp.z]) - matrix[:3, 3]) < 0.3

    # Contacts on the object's surface, transformed by the pose (within 3 mm).
    assert len(res.contact_points) == len(res.contact_normals) == len(res.contact_fingers) >= 2
    assert set(res.contact_fingers) <= set(FINGER_NAMES)
    points = np.array([[p.x, p.y, p.z] for p in res.contact_points])
    in_object = (points - matrix[:3, 3]) @ matrix[:3, :3]
    distance = _distance_to_surface(builtin_objects.builtin('sphere').mesh, in_object)
    assert np.all(distance < 0.003), distance
    normals = np.array([[n.x, n.y, n.z] for n in res.contact_normals])
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-6)

    assert res.fitness > -1e9 and res.epsilon_quality >= 0.0
    assert 1 <= res.iterations_run <= SMALL['iterations']
    assert res.planning_time > 0.0

    # One progress message per iteration, tagged with the request id.
    n = ros.progress.wait_count(res.request_id, res.iterations_run, timeout=10.0)
    assert n == res.iterations_run
    assert ros.progress.iterations[res.request_id] == list(range(1, res.iterations_run + 1))


def test_markers_for_rviz_are_latched(ros):
    """A late subscriber (transient local) gets the last grasp, DELETEALL first."""
    pose, _ = table_pose(frame='table')
    res = ros.call(builtin_request('cube', object_pose=pose))
    assert res.success, res.message
    received = []
    got = threading.Event()

    def on_markers(msg):
        received.append(msg)
        got.set()

    # A late joiner: a node of its own, created after the grasp was published.
    late = SpinningNode(ros.context, 'grasp_apso_test_rviz')
    late.node.create_subscription(
        MarkerArray, '/grasp_apso/grasp_markers', on_markers,
        QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                   durability=DurabilityPolicy.TRANSIENT_LOCAL))
    with late:
        assert got.wait(DISCOVERY_TIMEOUT), 'no latched MarkerArray'
        markers = received[-1].markers
        assert markers[0].action == Marker.DELETEALL
        assert all(m.header.frame_id == 'table' for m in markers)
        namespaces = {m.ns for m in markers[1:]}
        assert {'grasp_apso/palm', 'grasp_apso/links', 'grasp_apso/fingertips',
                'grasp_apso/contacts', 'grasp_apso/normals'} <= namespaces
        contacts = [m for m in markers if m.ns == 'grasp_apso/contacts'][0]
        assert len(contacts.points) == len(res.contact_points)
        assert len([m for m in markers if m.ns == 'grasp_apso/normals']) == len(res.contact_points)


def test_fixed_wrist_position_is_in_the_request_frame(ros):
    pose, matrix = table_pose(rpy=(0.0, 0.0, 0.7))
    wrist = matrix[:3, :3] @ np.array([0.0, 0.0, 0.09]) + matrix[:3, 3]  # 9 cm above the centre
    req = sphere_request(pose, fix_wrist_position=True)
    req.wrist_position.x, req.wrist_position.y, req.wrist_position.z = (float(v) for v in wrist)
    res = ros.call(req)
    assert res.configuration.name, res.message
    p = res.wrist_pose.pose.position
    assert np.allclose([p.x, p.y, p.z], wrist, atol=1e-6)


# --- bad input ----------------------------------------------------------------------------

def _mesh(vertices, triangles):
    return arrays_to_mesh(np.asarray(vertices, float), np.asarray(triangles))


TETRA_V = [(0, 0, 0), (0.05, 0, 0), (0, 0.05, 0), (0, 0, 0.05)]
TETRA_T = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]


def _with_mesh(vertices, triangles):
    def edit(req, _dir):
        req.mesh = _mesh(vertices, triangles)
    return edit


def _with(**fields):
    def edit(req, _dir):
        for key, value in fields.items():
            setattr(req, key, value)
    return edit


def _with_uri(name, absolute=False):
    def edit(req, mesh_dir):
        req.mesh_uri = str(mesh_dir / name) if absolute else name
    return edit


def _with_quaternion(x, y, z, w):
    def edit(req, _dir):
        req.object_name = 'sphere'
        q = req.object_pose.pose.orientation
        q.x, q.y, q.z, q.w = x, y, z, w
    return edit


def _with_position(x, y, z):
    def edit(req, _dir):
        req.object_name = 'sphere'
        p = req.object_pose.pose.position
        p.x, p.y, p.z = x, y, z
    return edit


def _box(extents):
    box = objects.trimesh.creation.box(extents=extents)
    return _with_mesh(box.vertices, box.faces)


def _nan_wrist(req, _dir):
    req.fix_wrist_position = True
    req.wrist_position.x = float('nan')


def _with_packed(vertices, triangles):
    """Packed fields given as flat lists (lengths need not be multiples of 3)."""
    def edit(req, _dir):
        req.mesh_vertices = [float(v) for v in np.ravel(vertices)]
        req.mesh_triangles = [int(i) for i in np.ravel(triangles)]
    return edit


_BOX = objects.trimesh.creation.box(extents=(0.05, 0.05, 0.05))
_BOX_V, _BOX_T = _BOX.vertices, _BOX.faces


def _packed_and_mesh(req, d):
    _with_packed(TETRA_V, TETRA_T)(req, d)
    req.mesh = _mesh(TETRA_V, TETRA_T)


def _both_sources(req, _dir):
    req.mesh = _mesh(TETRA_V, TETRA_T)
    req.object_name = 'cube'


# (id, edit of a request that starts with no object, key words of the message,
#  node parameters set for the case)
BAD_INPUT = [
    ('no_object_empty_mesh', lambda req, d: None, ['empty', 'exactly one'], {}),
    ('two_sources', _both_sources, ['exactly one', 'mesh', 'object_name'], {}),
    ('mesh_without_triangles', _with_mesh(TETRA_V, np.zeros((0, 3), int)), ['mesh', 'empty'], {}),
    ('nan_vertex', _with_mesh([(float('nan'), 0, 0)] + TETRA_V[1:], TETRA_T), ['mesh', 'NaN'], {}),
    ('inf_vertex', _with_mesh(TETRA_V[:3] + [(0, 0, float('inf'))], TETRA_T), ['mesh', 'infinite'], {}),
    ('index_out_of_range', _with_mesh(TETRA_V, TETRA_T[:3] + [(1, 2, 99)]), ['mesh', 'out of range'], {}),
    ('degenerate_mesh', _with_mesh([(0, 0, 0), (0.01, 0, 0), (0.02, 0, 0), (0.03, 0, 0)],
                                   [(0, 1, 2), (1, 2, 3)]), ['mesh', 'degenerate'], {}),
    ('flat_mesh', _with_mesh([(0, 0, 0), (0.05, 0, 0), (0.05, 0.05, 0), (0, 0.05, 0)],
                             [(0, 1, 2), (0, 2, 3)]), ['mesh', 'flat'], {}),
    ('mesh_over_size_limit', _box((0.05, 0.05, 0.05)), ['mesh', '12 triangles', 'limit', 'max_mesh_triangles'],
     {'max_mesh_triangles': 4}),
    ('zero_quaternion', _with_quaternion(0.0, 0.0, 0.0, 0.0), ['object_pose', 'zero quaternion'], {}),
    ('non_unit_quaternion', _with_quaternion(0.0, 0.0, 0.5, 0.5), ['object_pose', 'not unit'], {}),
    ('nan_position', _with_position(float('nan'), 0.0, 0.0), ['object_pose', 'not finite'], {}),
    ('mesh_file_missing', _with_uri('missing.stl'), ['mesh_uri', 'not found'], {}),
    ('mesh_file_unreadable', _with_uri('garbage.stl'), ['mesh_uri', 'cannot parse'], {}),
    ('mesh_file_is_a_directory', _with_uri('folder.stl'), ['mesh_uri', 'not a regular file'], {}),
    ('mesh_file_empty', _with_uri('empty.obj'), ['mesh_uri', 'empty'], {}),
    ('mesh_file_unknown_format', _with_uri('cube.xyz'), ['mesh_uri', 'unknown format'], {}),
    ('mesh_file_outside_allowed_dir', _with(mesh_uri='/etc/hostname.stl'), ['mesh_uri', 'outside'], {}),
    ('mesh_file_path_traversal', _with(mesh_uri='../outside/secret.stl'), ['mesh_uri', 'outside'], {}),
    ('mesh_file_symlink_out', _with_uri('link.stl'), ['mesh_uri', 'outside'], {}),
    ('mesh_file_uri_scheme', _with(mesh_uri='http://example.com/cube.stl'), ['mesh_uri', 'scheme'], {}),
    ('mesh_file_over_byte_limit', _with_uri('cube.stl'), ['mesh_uri', 'exceeds the limit'],
     {'max_mesh_bytes': 100}),
    ('mesh_files_disabled', _with_uri('cube.stl'), ['mesh_uri', 'allowed_mesh_dir'],
     {'allowed_mesh_dir': ''}),
    ('particles_too_few', _with(object_name='sphere', particles=1), ['particles', 'range'], {}),
    ('particles_too_many', _with(object_name='sphere', particles=5000), ['particles', 'range'], {}),
    ('iterations_too_many', _with(object_name='sphere', iterations=20000), ['iterations', 'range'], {}),
    ('unknown_algorithm', _with(object_name='sphere', algorithm='genetic'), ['algorithm', 'genetic'], {}),
    ('unknown_object_name', _with(object_name='banana'), ['object_name', 'banana'], {}),
    ('negative_seed', _with(object_name='sphere', seed=-5), ['seed'], {}),
    ('nan_wrist_position', lambda req, d: (_with(object_name='sphere')(req, d), _nan_wrist(req, d)),
     ['wrist_position', 'not finite'], {}),
    ('packed_vertices_not_triples', _with_packed(np.ravel(TETRA_V)[:-1], TETRA_T),
     ['mesh_vertices', 'multiple of 3'], {}),
    ('packed_triangles_not_triples', _with_packed(TETRA_V, np.ravel(TETRA_T)[:-2]),
     ['mesh_triangles', 'multiple of 3'], {}),
    ('packed_vertices_without_triangles', _with_packed(TETRA_V, []), ['mesh_triangles', 'empty'], {}),
    ('packed_triangles_without_vertices', _with_packed([], TETRA_T), ['mesh_vertices', 'empty'], {}),
    ('packed_and_mesh', _packed_and_mesh, ['exactly one', 'mesh and mesh_vertices/mesh_triangles'], {}),
    ('packed_nan_vertex', _with_packed([(float('nan'), 0, 0)] + TETRA_V[1:], TETRA_T),
     ['mesh_vertices (packed mesh)', 'vertex 0 is NaN'], {}),
    ('packed_index_out_of_range', _with_packed(TETRA_V, TETRA_T[:3] + [(1, 2, 99)]),
     ['mesh_triangles (packed mesh)', 'index 99 out of range'], {}),
    ('packed_flat', _with_packed([(0, 0, 0), (0.05, 0, 0), (0.05, 0.05, 0), (0, 0.05, 0)], [(0, 1, 2), (0, 2, 3)]),
     ['mesh_vertices/mesh_triangles (packed mesh)', 'flat'], {}),
    ('packed_over_size_limit', _with_packed(_BOX_V, _BOX_T), ['mesh_triangles', '12 triangles', 'max_mesh_triangles'],
     {'max_mesh_triangles': 4}),
    ('object_too_large', _box((0.5, 0.4, 0.3)), ['too large'], {}),
    ('object_too_small', _box((0.003, 0.003, 0.003)), ['too small'], {}),
]


@pytest.mark.parametrize('edit, words, params', [c[1:] for c in BAD_INPUT], ids=[c[0] for c in BAD_INPUT])
def test_bad_input_is_refused_and_the_node_keeps_serving(ros, edit, words, params):
    before = {k: ros.node.get_parameter(k).value for k in params}
    req = PlanGrasp.Request()
    req.object_pose = identity_pose()
    req.particles, req.iterations, req.seed = 20, 4, 1
    edit(req, ros.mesh_dir)
    if params:
        ros.set_parameters(**params)
    try:
        t0 = time.monotonic()
        res = ros.call(req)
        elapsed = time.monotonic() - t0
    finally:
        if params:
            ros.set_parameters(**before)
    assert not res.success
    for word in words:
        assert word in res.message, f'{word!r} not in {res.message!r}'
    assert 'internal error' not in res.message
    assert elapsed < 15.0
    # ... and the node still serves a valid request.
    ok = ros.call(builtin_request('sphere', iterations=3))
    assert ok.success, ok.message


def test_valid_mesh_file_inside_the_allowed_dir(ros):
    res = ros.call(builtin_request(object_name='', mesh_uri='cube.stl', iterations=4))
    assert res.success, res.message
    res = ros.call(builtin_request(object_name='', mesh_uri=f'file://{ros.mesh_dir}/cube.stl', iterations=4))
    assert res.success, res.message


def test_plan_timeout(ros):
    ros.set_parameters(plan_timeout=0.3)
    try:
        t0 = time.monotonic()
        res = ros.call(builtin_request('sphere', iterations=10000))
        elapsed = time.monotonic() - t0
    finally:
        ros.set_parameters(plan_timeout=60.0)
    assert not res.success and 'timed out' in res.message and 'plan_timeout' in res.message
    assert res.iterations_run < 10000
    assert elapsed < 10.0


# --- parameters -------------------------------------------------------------------------------

def _remote_set(ros, **values):
    """Set parameters through the node's ROS parameter service (a real remote call)."""
    from rcl_interfaces.srv import SetParameters

    client = ros.set_params_client
    assert client.wait_for_service(timeout_sec=DISCOVERY_TIMEOUT)
    req = SetParameters.Request(
        parameters=[Parameter(k, value=v).to_parameter_msg() for k, v in values.items()])
    return ros.wait(client.call_async(req), 10.0).results


def test_parameters_declared_with_descriptors(ros):
    for name in PARAMETER_NAMES:
        assert ros.node.has_parameter(name), name
        desc = ros.node.describe_parameter(name)
        assert desc.description, name
        if isinstance(ros.node.get_parameter(name).value, int):
            assert desc.integer_range, name
        elif isinstance(ros.node.get_parameter(name).value, float):
            assert desc.floating_point_range, name


@pytest.mark.parametrize('name, value, word', [
    ('particles', 0, 'particles'),
    ('friction', -1.0, 'friction'),
    ('friction', 0.0, 'friction'),
    ('contact_tolerance', 0.5, 'contact_tolerance'),
    ('iterations', 0, 'iterations'),
    ('algorithm', 'genetic', 'algorithm'),
    ('allowed_mesh_dir', '/no/such/directory', 'allowed_mesh_dir'),
    ('hand_description', '/no/such/hand.yaml', 'hand_description'),
    ('queue_length', -1, 'queue_length'),
    ('plan_timeout', -2.0, 'plan_timeout'),
    ('c1', 'fast', 'type'),  # wrong type: rclpy's own check
    ('inertia', 1.5, 'inertia'),
    ('closure_candidates', 0, 'closure_candidates'),
])
def test_bad_parameter_values_are_rejected(ros, name, value, word):
    before = ros.node.get_parameter(name).value
    (result,) = _remote_set(ros, **{name: value})
    assert not result.successful
    assert word in result.reason, result.reason
    assert ros.node.get_parameter(name).value == before


def test_integer_accepted_for_a_double_parameter(ros):
    (result,) = _remote_set(ros, c1=1)
    try:
        assert result.successful, result.reason
        value = ros.node.get_parameter('c1').value
        assert isinstance(value, float) and value == 1.0
    finally:
        ros.set_parameters(c1=DEFAULTS['c1'])


def test_good_parameter_values_are_accepted_and_used(ros):
    (result,) = _remote_set(ros, particles=12)
    try:
        assert result.successful, result.reason
        assert ros.node.get_parameter('particles').value == 12
        req = builtin_request('cube', iterations=3)
        req.particles = 0  # node parameter
        res = ros.call(req)
        assert res.success, res.message
    finally:
        (result,) = _remote_set(ros, particles=20)
        assert result.successful


# --- concurrency ------------------------------------------------------------------------------

def test_ten_concurrent_callers_all_answered(ros):
    """queue_length 2: one running + two waiting; the others are told busy at once.

    While the plans run the executor keeps serving: parameters are readable and progress
    flows.
    """
    from rcl_interfaces.srv import GetParameters

    callers = SpinningNode(ros.context, 'grasp_apso_test_callers', num_threads=4)
    clients = [callers.node.create_client(PlanGrasp, '/grasp_apso/plan_grasp') for _ in range(10)]
    params = ros.get_params_client
    with callers:
        for c in clients:
            assert c.wait_for_service(timeout_sec=DISCOVERY_TIMEOUT)
        assert params.wait_for_service(timeout_sec=DISCOVERY_TIMEOUT)
        t0 = time.monotonic()
        futures = [c.call_async(builtin_request('sphere', iterations=20)) for c in clients]
        # While the first plan runs: a parameter read is answered.
        reply = ros.wait(params.call_async(GetParameters.Request(names=['particles'])), 10.0)
        assert reply.values[0].integer_value == 20
        answers = [ros.wait(f, CALL_TIMEOUT, extra=(callers,)) for f in futures]
        elapsed = time.monotonic() - t0
    busy = [a for a in answers if a.message.startswith('busy')]
    served = [a for a in answers if not a.message.startswith('busy')]
    assert len(busy) + len(served) == 10
    assert all(a.success for a in served), [a.message for a in served]
    assert 1 <= len(served) and len(busy) >= 1
    assert all(not a.success and 'queued' in a.message for a in busy)
    assert elapsed < 60.0
    for a in served:
        assert ros.progress.wait_count(a.request_id, a.iterations_run, 10.0) == a.iterations_run
    # Nothing is stuck: the next request is served.
    res = ros.call(builtin_request('sphere', iterations=2))
    assert res.success, res.message


# --- action -----------------------------------------------------------------------------------

@pytest.fixture
def action_client(ros):
    return ros.action_client


def _goal(name='sphere', **fields):
    goal = PlanGraspAction.Goal()
    goal.object_name = name
    goal.object_pose = identity_pose('base_link')
    for key, value in {**SMALL, **fields}.items():
        setattr(goal, key, value)
    return goal


def test_action_goal_with_a_packed_mesh(ros, action_client):
    """The action goal goes through the same parser: a packed mesh plans, a bad one aborts."""
    sphere = builtin_objects.builtin('sphere')
    goal = _goal('', iterations=3)
    goal.mesh_vertices, goal.mesh_triangles = arrays_to_packed(sphere.mesh.vertices, sphere.mesh.faces)
    goal_handle = ros.wait(action_client.send_goal_async(goal), 10.0)
    wrapped = ros.wait(goal_handle.get_result_async(), CALL_TIMEOUT)
    assert wrapped.status == GoalStatus.STATUS_SUCCEEDED, wrapped.result.message
    assert len(wrapped.result.configuration.position) == 18

    goal.mesh_triangles = goal.mesh_triangles[:-1]
    goal_handle = ros.wait(action_client.send_goal_async(goal), 10.0)
    wrapped = ros.wait(goal_handle.get_result_async(), CALL_TIMEOUT)
    assert wrapped.status == GoalStatus.STATUS_ABORTED
    assert 'mesh_triangles' in wrapped.result.message and 'multiple of 3' in wrapped.result.message


def test_action_goal_with_feedback(ros, action_client):
    feedback = []
    goal_handle = ros.wait(
        action_client.send_goal_async(_goal(iterations=5), feedback_callback=feedback.append), 10.0)
    assert goal_handle.accepted
    wrapped = ros.wait(goal_handle.get_result_async(), CALL_TIMEOUT)
    result = wrapped.result
    assert wrapped.status == GoalStatus.STATUS_SUCCEEDED, result.message
    assert result.success and list(result.configuration.name) == list(JOINT_NAMES)
    assert result.wrist_pose.header.frame_id == 'base_link'
    assert wait_for(lambda: len(feedback) >= result.iterations_run, 5.0)
    iterations = [m.feedback.progress.iteration for m in feedback]
    assert iterations == list(range(1, result.iterations_run + 1))
    assert all(m.feedback.progress.request_id == result.request_id for m in feedback)
    assert ros.progress.wait_count(result.request_id, result.iterations_run, 5.0) == result.iterations_run


def test_action_cancel_stops_within_one_iteration(ros, action_client):
    first = threading.Event()
    seen = []

    def on_feedback(msg):
        seen.append(msg.feedback.progress.iteration)
        first.set()

    goal_handle = ros.wait(
        action_client.send_goal_async(_goal(iterations=2000), feedback_callback=on_feedback), 10.0)
    assert goal_handle.accepted
    assert first.wait(30.0), 'no feedback'
    cancel = ros.wait(goal_handle.cancel_goal_async(), 10.0)
    assert len(cancel.goals_canceling) == 1
    wrapped = ros.wait(goal_handle.get_result_async(), CALL_TIMEOUT)
    assert wrapped.status == GoalStatus.STATUS_CANCELED
    result = wrapped.result
    assert not result.success and 'cancel' in result.message
    # Cancel was sent after the first feedback; the plan stops at the next iteration check.
    # Allow for the feedback's and the cancel request's trip through DDS.
    assert 1 <= result.iterations_run <= 10, result.iterations_run
    assert max(seen) <= result.iterations_run
    # The node serves the next goal.
    res = ros.call(builtin_request('cube', iterations=2))
    assert res.success, res.message


def test_busy_action_goal_is_aborted_with_a_reason(ros, action_client):
    # One long plan (stopped by plan_timeout, so the test does not depend on planner speed).
    ros.set_parameters(queue_length=0, plan_timeout=2.0)
    try:
        before = ros.progress.total()
        running = ros.client.call_async(builtin_request('sphere', iterations=10000))
        # The service plan is running once its first progress message arrived.
        assert ros.progress.wait_total(before + 1, 30.0) > before
        goal_handle = ros.wait(action_client.send_goal_async(_goal(iterations=3)), 10.0)
        wrapped = ros.wait(goal_handle.get_result_async(), 10.0)
        assert wrapped.status == GoalStatus.STATUS_ABORTED
        assert not wrapped.result.success and wrapped.result.message.startswith('busy')
        answer = ros.wait(running, CALL_TIMEOUT)
        assert not answer.success and 'timed out' in answer.message
        assert answer.configuration.name  # the best grasp so far is still returned
    finally:
        ros.set_parameters(queue_length=2, plan_timeout=60.0)
