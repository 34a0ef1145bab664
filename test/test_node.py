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

from grasp_apso.model import builtin as builtin_objects  # noqa: E402
from grasp_apso.model import objects  # noqa: E402
from grasp_apso.ros.conversions import arrays_to_mesh, arrays_to_packed  # noqa: E402
from grasp_apso.model.hand import FINGER_NAMES, JOINT_NAMES, load_hand  # noqa: E402
from grasp_apso.ros.node import PARAMETER_NAMES, PARAMETERS, GraspPlannerNode  # noqa: E402
from grasp_apso.ros.parameters import READ_ONLY  # noqa: E402

DEFAULTS = {spec.name: spec.default for spec in PARAMETERS}

SMALL = dict(particles=20, iterations=8, seed=7)
CALL_TIMEOUT = 60.0


class Harness:
    """The nodes and a client node, each spun by its own executor.

    ``main`` is the node most tests use; ``strict`` (max_mesh_triangles 4, mesh files
    disabled, queue_length 0) and ``small_files`` (max_mesh_bytes 100) hold the read-only
    limits other cases need. Every entity of the client node lives as long as the module
    (see :class:`node_helpers.SpinningNode` for why nothing is destroyed while it spins);
    tests that need short-lived entities make a ``SpinningNode`` of their own.
    """

    def __init__(self, context, servers, client, mesh_dir):
        from rcl_interfaces.srv import GetParameters, SetParameters

        self.context = context
        self.servers = servers
        self.server = servers['main']
        self.node = self.server.node
        self.nodes = {k: v.node for k, v in servers.items()}
        self.client_spinner = client
        self.client_node = client.node
        self.mesh_dir = mesh_dir
        self.clients = {k: self.client_node.create_client(PlanGrasp, f'/{v.node.get_name()}/plan_grasp')
                        for k, v in servers.items()}
        self.client = self.clients['main']
        self.set_params_client = self.client_node.create_client(SetParameters, '/grasp_apso/set_parameters')
        self.get_params_client = self.client_node.create_client(GetParameters, '/grasp_apso/get_parameters')
        self.action_clients = {k: ActionClient(self.client_node, PlanGraspAction, f'/{v.node.get_name()}/plan_grasp')
                               for k, v in servers.items()}
        self.action_client = self.action_clients['main']
        self.progress = ProgressCounter()
        self.progress_sub = self.client_node.create_subscription(
            GraspProgress, '/grasp_apso/progress', self.progress,
            QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))

    def wait(self, future, timeout=CALL_TIMEOUT, extra=()):
        """The future's result; fails at once when an executor of the harness died."""
        return wait_future(future, timeout, spinners=(*self.servers.values(), self.client_spinner, *extra))

    def call(self, request, timeout=CALL_TIMEOUT, node='main'):
        return self.wait(self.clients[node].call_async(request), timeout)

    def set_parameters(self, node='main', **values):
        """Set node parameters through the node API (the same callbacks as over ROS)."""
        results = self.nodes[node].set_parameters([Parameter(k, value=v) for k, v in values.items()])
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


#: The extra nodes of the module and their (read-only) limits.
EXTRA_NODES = {
    'strict': dict(max_mesh_triangles=4, allowed_mesh_dir='', queue_length=0),
    'small_files': dict(max_mesh_bytes=100, allowed_mesh_dir=None),  # None: the mesh dir
    'pair': dict(workers=2, queue_length=0),
}


@pytest.fixture(scope='module')
def ros(mesh_dir):
    context = rclpy.context.Context()
    rclpy.init(context=context)
    common = dict(particles=20, iterations=8)
    configs = {'main': dict(queue_length=2, allowed_mesh_dir=str(mesh_dir)), **EXTRA_NODES}
    servers = {}
    for key, config in configs.items():
        values = {**common, **{k: (str(mesh_dir) if v is None else v) for k, v in config.items()}}
        name = 'grasp_apso' if key == 'main' else f'grasp_apso_{key}'
        node = GraspPlannerNode(name, context=context,
                                parameter_overrides=[Parameter(k, value=v) for k, v in values.items()])
        servers[key] = SpinningNode(context, name, num_threads=4, node=node)
    client = SpinningNode(context, 'grasp_apso_test_client')
    harness = Harness(context, servers, client, mesh_dir)  # entities first, then spin
    for server in servers.values():
        server.start()
    client.start()
    try:
        for key in servers:
            assert harness.clients[key].wait_for_service(timeout_sec=DISCOVERY_TIMEOUT), f'{key}: service not found'
            assert harness.action_clients[key].wait_for_server(timeout_sec=DISCOVERY_TIMEOUT), f'{key}: no action'
        # Progress is volatile: make sure the node's publisher has matched our subscriber.
        node = harness.node
        assert wait_for(lambda: node._progress_pub.get_subscription_count() >= 1
                        and harness.progress_sub.get_publisher_count() >= 1, DISCOVERY_TIMEOUT)
        yield harness
    finally:
        for server in servers.values():
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


def _plane(a, b, c, d):
    from shape_msgs.msg import Plane
    return Plane(coef=[float(a), float(b), float(c), float(d)])


def _obstacle(kind, dims, position=(0.3, 0.0, 0.0), quat=(0.0, 0.0, 0.0, 1.0)):
    from geometry_msgs.msg import Pose
    from shape_msgs.msg import SolidPrimitive
    pose = Pose()
    pose.position.x, pose.position.y, pose.position.z = (float(v) for v in position)
    pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = (float(v) for v in quat)
    return SolidPrimitive(type=kind, dimensions=[float(d) for d in dims]), pose


def _with_scene(planes=(), obstacles=(), poses=None, **fields):
    """The built-in cube (edge 7 cm, centred at the origin) in a scene."""
    def edit(req, _dir):
        req.object_name = 'cube'
        req.support_planes = [_plane(*p) for p in planes]
        built = [_obstacle(*o) for o in obstacles]
        req.obstacles = [b[0] for b in built]
        req.obstacle_poses = [b[1] for b in built] if poses is None else poses(built)
        for key, value in fields.items():
            setattr(req, key, value)
    return edit


TABLE = (0.0, 0.0, 1.0, 0.035)  # the cube's bottom face rests on it
NAN, INF = float('nan'), float('inf')
BOX, SPHERE, CYLINDER, CONE = 1, 2, 3, 4

# (id, edit of a request that starts with no object, key words of the message,
#  node parameters set for the case)
BAD_INPUT = [
    ('no_object_empty_mesh', lambda req, d: None, ['empty', 'exactly one'], 'main'),
    ('two_sources', _both_sources, ['exactly one', 'mesh', 'object_name'], 'main'),
    ('mesh_without_triangles', _with_mesh(TETRA_V, np.zeros((0, 3), int)), ['mesh', 'empty'], 'main'),
    ('nan_vertex', _with_mesh([(float('nan'), 0, 0)] + TETRA_V[1:], TETRA_T), ['mesh', 'NaN'], 'main'),
    ('inf_vertex', _with_mesh(TETRA_V[:3] + [(0, 0, float('inf'))], TETRA_T), ['mesh', 'infinite'], 'main'),
    ('index_out_of_range', _with_mesh(TETRA_V, TETRA_T[:3] + [(1, 2, 99)]), ['mesh', 'out of range'], 'main'),
    ('degenerate_mesh', _with_mesh([(0, 0, 0), (0.01, 0, 0), (0.02, 0, 0), (0.03, 0, 0)],
                                   [(0, 1, 2), (1, 2, 3)]), ['mesh', 'degenerate'], 'main'),
    ('flat_mesh', _with_mesh([(0, 0, 0), (0.05, 0, 0), (0.05, 0.05, 0), (0, 0.05, 0)],
                             [(0, 1, 2), (0, 2, 3)]), ['mesh', 'flat'], 'main'),
    ('mesh_over_size_limit', _box((0.05, 0.05, 0.05)), ['mesh', '12 triangles', 'limit', 'max_mesh_triangles'],
     'strict'),
    ('zero_quaternion', _with_quaternion(0.0, 0.0, 0.0, 0.0), ['object_pose', 'zero quaternion'], 'main'),
    ('non_unit_quaternion', _with_quaternion(0.0, 0.0, 0.5, 0.5), ['object_pose', 'not unit'], 'main'),
    ('nan_position', _with_position(float('nan'), 0.0, 0.0), ['object_pose', 'not finite'], 'main'),
    ('mesh_file_missing', _with_uri('missing.stl'), ['mesh_uri', 'not found'], 'main'),
    ('mesh_file_unreadable', _with_uri('garbage.stl'), ['mesh_uri', 'garbage.stl'], 'main'),  # cannot parse or no triangles
    ('mesh_file_is_a_directory', _with_uri('folder.stl'), ['mesh_uri', 'not a regular file'], 'main'),
    ('mesh_file_empty', _with_uri('empty.obj'), ['mesh_uri', 'empty'], 'main'),
    ('mesh_file_unknown_format', _with_uri('cube.xyz'), ['mesh_uri', 'unknown format'], 'main'),
    ('mesh_file_outside_allowed_dir', _with(mesh_uri='/etc/hostname.stl'), ['mesh_uri', 'outside'], 'main'),
    ('mesh_file_path_traversal', _with(mesh_uri='../outside/secret.stl'), ['mesh_uri', 'outside'], 'main'),
    ('mesh_file_symlink_out', _with_uri('link.stl'), ['mesh_uri', 'outside'], 'main'),
    ('mesh_file_uri_scheme', _with(mesh_uri='http://example.com/cube.stl'), ['mesh_uri', 'scheme'], 'main'),
    ('mesh_file_over_byte_limit', _with_uri('cube.stl'), ['mesh_uri', 'exceeds the limit'], 'small_files'),
    ('mesh_files_disabled', _with_uri('cube.stl'), ['mesh_uri', 'allowed_mesh_dir'], 'strict'),
    ('particles_too_few', _with(object_name='sphere', particles=1), ['particles', 'range'], 'main'),
    ('particles_too_many', _with(object_name='sphere', particles=5000), ['particles', 'range'], 'main'),
    ('iterations_too_many', _with(object_name='sphere', iterations=20000), ['iterations', 'range'], 'main'),
    ('unknown_algorithm', _with(object_name='sphere', algorithm='genetic'), ['algorithm', 'genetic'], 'main'),
    ('unknown_object_name', _with(object_name='banana'), ['object_name', 'banana'], 'main'),
    ('negative_seed', _with(object_name='sphere', seed=-5), ['seed'], 'main'),
    ('nan_wrist_position', lambda req, d: (_with(object_name='sphere')(req, d), _nan_wrist(req, d)),
     ['wrist_position', 'not finite'], 'main'),
    ('packed_vertices_not_triples', _with_packed(np.ravel(TETRA_V)[:-1], TETRA_T),
     ['mesh_vertices', 'multiple of 3'], 'main'),
    ('packed_triangles_not_triples', _with_packed(TETRA_V, np.ravel(TETRA_T)[:-2]),
     ['mesh_triangles', 'multiple of 3'], 'main'),
    ('packed_vertices_without_triangles', _with_packed(TETRA_V, []), ['mesh_triangles', 'empty'], 'main'),
    ('packed_triangles_without_vertices', _with_packed([], TETRA_T), ['mesh_vertices', 'empty'], 'main'),
    ('packed_and_mesh', _packed_and_mesh, ['exactly one', 'mesh and mesh_vertices/mesh_triangles'], 'main'),
    ('packed_nan_vertex', _with_packed([(float('nan'), 0, 0)] + TETRA_V[1:], TETRA_T),
     ['mesh_vertices (packed mesh)', 'vertex 0 is NaN'], 'main'),
    ('packed_index_out_of_range', _with_packed(TETRA_V, TETRA_T[:3] + [(1, 2, 99)]),
     ['mesh_triangles (packed mesh)', 'index 99 out of range'], 'main'),
    ('packed_flat', _with_packed([(0, 0, 0), (0.05, 0, 0), (0.05, 0.05, 0), (0, 0.05, 0)], [(0, 1, 2), (0, 2, 3)]),
     ['mesh_vertices/mesh_triangles (packed mesh)', 'flat'], 'main'),
    ('packed_over_size_limit', _with_packed(_BOX_V, _BOX_T), ['mesh_triangles', '12 triangles', 'max_mesh_triangles'],
     'strict'),
    ('object_too_large', _box((0.5, 0.4, 0.3)), ['too large'], 'main'),
    ('mesh_too_many_vertices', _with_mesh(TETRA_V + [(0.01 * i, 0.02, 0.03) for i in range(9)], TETRA_T),
     ['mesh', '13 vertices', 'limit', 'max_mesh_triangles'], 'strict'),
    ('packed_too_many_vertices', _with_packed(TETRA_V + [(0.01 * i, 0.02, 0.03) for i in range(9)], TETRA_T),
     ['mesh_vertices', '13 vertices', 'limit'], 'strict'),
    ('open_surface_hinge', _with_mesh([(0, 0, 0), (0.05, 0, 0), (0, 0.05, 0), (0, 0, 0.05)], [(0, 1, 2), (0, 1, 3)]),
     ['mesh', 'open surface', 'without volume'], 'main'),
    ('two_bodies_far_apart', _with_mesh(np.vstack([_BOX_V * 0.6, _BOX_V * 0.6 + (0.3, 0, 0)]),
                                        np.vstack([_BOX_T, _BOX_T + len(_BOX_V)])),
     ['mesh', '2 separate bodies', 'one object'], 'main'),
    ('plane_zero_coefficients', _with_scene(planes=[(0, 0, 0, 0)]), ['support_planes[0]', 'zero'], 'main'),
    ('plane_nan_coefficient', _with_scene(planes=[TABLE, (0, 0, NAN, 1)]), ['support_planes[1]', 'finite'], 'main'),
    ('plane_inf_coefficient', _with_scene(planes=[(0, INF, 1, 1)]), ['support_planes[0]', 'finite'], 'main'),
    ('obstacles_and_poses_differ', _with_scene(obstacles=[(BOX, (0.1, 0.1, 0.1))], poses=lambda b: []),
     ['obstacle_poses', '1 obstacles but 0'], 'main'),
    ('obstacle_unknown_type', _with_scene(obstacles=[(CONE, (0.1, 0.05))]), ['obstacles[0]', 'unknown primitive type'],
     'main'),
    ('obstacle_wrong_dimension_count', _with_scene(obstacles=[(BOX, (0.1, 0.1))]), ['obstacles[0]', 'BOX needs 3'],
     'main'),
    ('obstacle_zero_dimension', _with_scene(obstacles=[(SPHERE, (0.0,))]), ['obstacles[0]', 'positive'], 'main'),
    ('obstacle_negative_dimension', _with_scene(obstacles=[(CYLINDER, (0.1, -0.02))]), ['obstacles[0]', 'positive'],
     'main'),
    ('obstacle_nan_dimension', _with_scene(obstacles=[(BOX, (0.1, NAN, 0.1))]), ['obstacles[0]', 'finite'], 'main'),
    ('obstacle_pose_zero_quaternion', _with_scene(obstacles=[(BOX, (0.1, 0.1, 0.1), (0.3, 0, 0), (0, 0, 0, 0))]),
     ['obstacle_poses[0]', 'zero quaternion'], 'main'),
    ('obstacle_pose_non_unit_quaternion', _with_scene(obstacles=[(BOX, (0.1, 0.1, 0.1), (0.3, 0, 0), (0, 0, 1, 1))]),
     ['obstacle_poses[0]', 'not unit'], 'main'),
    ('negative_clearance', _with_scene(planes=[TABLE], clearance=-0.01), ['clearance', '>= 0'], 'main'),
    ('nan_clearance', _with_scene(planes=[TABLE], clearance=NAN), ['clearance', 'finite'], 'main'),
    ('negative_approach_distance', _with_scene(approach_distance=-0.1), ['approach_distance', '>= 0'], 'main'),
    ('inf_approach_distance', _with_scene(approach_distance=INF), ['approach_distance', 'finite'], 'main'),
    ('max_grasps_too_many', _with_scene(max_grasps=51), ['max_grasps', 'range'], 'main'),
    ('object_inside_an_obstacle', _with_scene(obstacles=[(BOX, (0.2, 0.2, 0.2), (0.0, 0.0, 0.0))]),
     ['object_pose', 'obstacles[0]', 'penetrates'], 'main'),
    ('object_sunk_into_the_table', _with_scene(planes=[(0, 0, 1, 0.0)]), ['object_pose', 'support_planes[0]', 'sinks'],
     'main'),
    ('object_too_small', _box((0.003, 0.003, 0.003)), ['too small'], 'main'),
]


@pytest.mark.parametrize('edit, words, node', [c[1:] for c in BAD_INPUT], ids=[c[0] for c in BAD_INPUT])
def test_bad_input_is_refused_and_the_node_keeps_serving(ros, edit, words, node):
    req = PlanGrasp.Request()
    req.object_pose = identity_pose()
    req.particles, req.iterations, req.seed = 20, 4, 1
    edit(req, ros.mesh_dir)
    t0 = time.monotonic()
    res = ros.call(req, node=node)
    elapsed = time.monotonic() - t0
    assert not res.success
    for word in words:
        assert word in res.message, f'{word!r} not in {res.message!r}'
    assert 'internal error' not in res.message
    assert str(ros.mesh_dir) not in res.message  # never the node's own directory
    assert elapsed < 15.0
    # ... and the node still serves a valid request.
    ok = ros.call(builtin_request('sphere', iterations=3), node=node)
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

    # 200 particles: an iteration long enough (about 10 ms) that the cancel's trip through
    # DDS spans a few of them even on a loaded machine (20 particles: 12 iterations once,
    # with benchmarks running beside the tests)
    goal_handle = ros.wait(
        action_client.send_goal_async(_goal(iterations=2000, particles=200), feedback_callback=on_feedback), 10.0)
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


def test_busy_action_goal_is_rejected(ros):
    """queue_length 0: while a plan runs, a goal is rejected in goal_callback (not accepted
    and then aborted), and the running plan is not disturbed."""
    ros.set_parameters(node='strict', plan_timeout=2.0)
    strict = ros.nodes['strict']
    try:
        running = ros.clients['strict'].call_async(builtin_request('sphere', iterations=10000))
        assert wait_for(lambda: strict.worker.pending >= 1, 30.0)
        goal_handle = ros.wait(ros.action_clients['strict'].send_goal_async(_goal(iterations=3)), 10.0)
        assert not goal_handle.accepted
        answer = ros.wait(running, CALL_TIMEOUT)
        assert not answer.success and 'timed out' in answer.message and 'planning' in answer.message
        assert answer.configuration.name  # the best grasp so far is still returned
        assert wait_for(lambda: strict.worker.pending == 0, 10.0)
        goal_handle = ros.wait(ros.action_clients['strict'].send_goal_async(_goal(iterations=2)), 10.0)
        assert goal_handle.accepted
        wrapped = ros.wait(goal_handle.get_result_async(), CALL_TIMEOUT)
        assert wrapped.status == GoalStatus.STATUS_SUCCEEDED, wrapped.result.message
    finally:
        ros.set_parameters(node='strict', plan_timeout=60.0)


# --- scene and candidates (issues 11 and 12) -----------------------------------------------------

def test_cube_on_a_table_returns_ranked_grasps_with_pre_grasps(ros):
    req = builtin_request('cube', iterations=8, max_grasps=3, approach_distance=0.06)
    req.object_pose = table_pose(position=(0.5, 0.0, 0.8), rpy=(0.0, 0.0, 0.4), frame='base')[0]
    req.support_planes = [_plane(0.0, 0.0, 1.0, -(0.8 - 0.035))]  # z = 0.765: the cube's bottom face
    res = ros.call(req)
    assert res.success, res.message
    assert res.grasp_source == 'planned'
    assert 1 <= len(res.grasps) <= 3
    first = res.grasps[0]
    assert list(res.configuration.position) == list(first.grasp_posture.position)
    assert res.wrist_pose == first.grasp_pose and res.fitness == first.fitness
    assert res.contact_fingers == first.contact_fingers
    qualities = [g.grasp_quality for g in res.grasps]
    assert qualities == sorted(qualities, reverse=True)
    for g in res.grasps:
        assert list(g.grasp_posture.name) == list(JOINT_NAMES) == list(g.pre_grasp_posture.name)
        assert g.grasp_pose.header.frame_id == g.pre_grasp_pose.header.frame_id == 'base'
        assert g.approach_direction.header.frame_id == 'base'
        v = g.approach_direction.vector
        approach = np.array([v.x, v.y, v.z])
        assert math.isclose(np.linalg.norm(approach), 1.0, abs_tol=1e-6)
        assert math.isclose(g.approach_distance, 0.06)
        grasp = np.array([getattr(g.grasp_pose.pose.position, a) for a in 'xyz'])
        pre = np.array([getattr(g.pre_grasp_pose.pose.position, a) for a in 'xyz'])
        assert np.allclose(grasp - pre, 0.06 * approach, atol=1e-6)
        assert g.sim_result == -1  # not simulated
    # Progress carries the archive size field.
    assert ros.progress.wait_count(res.request_id, res.iterations_run, 10.0) == res.iterations_run


def test_simulate_fills_the_simulation_fields_of_every_grasp(ros):
    """simulate: every candidate is checked in MuJoCo; held grasps rank first."""
    req = builtin_request('sphere', iterations=10, max_grasps=3, simulate=True)
    req.support_planes = [_plane(0.0, 0.0, 1.0, 0.025)]  # the sphere (radius 25 mm) rests on z = -0.025
    res = ros.call(req, timeout=120.0)
    assert res.success, res.message
    assert len(res.grasps) >= 1
    verdicts = [g.sim_result for g in res.grasps]
    assert all(v in (0, 1) for v in verdicts), verdicts
    assert verdicts == sorted(verdicts, reverse=True)
    for g in res.grasps:
        assert math.isfinite(g.sim_max_shift) and g.sim_max_shift >= 0.0
        assert math.isfinite(g.sim_max_turn) and g.sim_max_turn >= 0.0
        if g.sim_result == 1:
            assert g.sim_max_shift < 0.05 and g.sim_max_turn < math.radians(15.0)


def test_markers_show_the_scene(ros):
    late_msgs = []
    got = threading.Event()
    req = builtin_request('cube', iterations=3)
    req.support_planes = [_plane(*TABLE)]
    solid, pose = _obstacle(BOX, (0.05, 0.05, 0.05), position=(0.0, 0.2, 0.0))
    req.obstacles, req.obstacle_poses = [solid], [pose]
    res = ros.call(req)
    assert res.success, res.message
    late = SpinningNode(ros.context, 'grasp_apso_test_rviz_scene')
    late.node.create_subscription(
        MarkerArray, '/grasp_apso/grasp_markers', lambda m: (late_msgs.append(m), got.set()),
        QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    with late:
        assert got.wait(DISCOVERY_TIMEOUT), 'no latched MarkerArray'
    namespaces = [m.ns for m in late_msgs[-1].markers]
    assert namespaces.count('grasp_apso/scene') == 1 and namespaces.count('grasp_apso/obstacles') == 1
    assert namespaces.count('grasp_apso/approach') == len(res.grasps)
    assert 'grasp_apso/pre_grasp_links' in namespaces


# --- limits and security (issue 14) --------------------------------------------------------------

def test_security_parameters_are_read_only(ros):
    """Nobody can widen the sandbox or the limits at run time; the next request still
    cannot read outside the directory the node was started with."""
    assert READ_ONLY >= {'allowed_mesh_dir', 'max_mesh_triangles', 'max_mesh_bytes', 'hand_description',
                         'queue_length', 'workers'}
    for name in READ_ONLY:
        assert ros.node.describe_parameter(name).read_only, name
    (result,) = _remote_set(ros, allowed_mesh_dir='/')
    assert not result.successful and 'read-only' in result.reason.lower()
    assert ros.node.get_parameter('allowed_mesh_dir').value == str(ros.mesh_dir)
    for name, value in (('max_mesh_triangles', 10_000_000), ('max_mesh_bytes', 2_000_000_000),
                        ('queue_length', 1000), ('workers', 16)):
        (result,) = _remote_set(ros, **{name: value})
        assert not result.successful and 'read-only' in result.reason.lower(), (name, result.reason)
    for uri in ('/etc/hostname.stl', '../outside/secret.stl', f'file://{ros.mesh_dir.parent}/outside/secret.stl'):
        res = ros.call(builtin_request(object_name='', mesh_uri=uri))
        assert not res.success and 'outside the allowed mesh directory' in res.message, res.message
        assert str(ros.mesh_dir) not in res.message


def test_a_bad_hand_description_stops_the_node_without_echoing_the_file(ros, tmp_path):
    from grasp_apso.errors import HandDescriptionError

    for name, text in (('broken.yaml', 'SECRET_TOKEN_1234: [unclosed, list\n'),
                       ('not_a_hand.yaml', 'password: SECRET_TOKEN_1234\nfingers: SECRET_TOKEN_1234\n'),
                       ('bad_values.yaml', 'fingers: [{name: SECRET_TOKEN_1234}]\n')):
        path = tmp_path / name
        path.write_text(text)
        with pytest.raises(HandDescriptionError) as info:
            GraspPlannerNode(f'grasp_apso_hand_{name[:3]}', context=ros.context,
                             parameter_overrides=[Parameter('hand_description', value=str(path))])
        assert 'hand_description' in str(info.value)
        assert 'SECRET_TOKEN' not in str(info.value), str(info.value)
    (result,) = _remote_set(ros, hand_description=str(tmp_path / 'broken.yaml'))
    assert not result.successful and 'read-only' in result.reason.lower()


def _badly_wound_sphere():
    """A sphere of 5,120 triangles, half of them wound the wrong way: about 1 s to repair."""
    mesh = objects.trimesh.creation.icosphere(subdivisions=4, radius=0.03)
    faces = np.array(mesh.faces)
    flip = np.random.default_rng(0).random(len(faces)) < 0.5
    faces[flip] = faces[flip][:, ::-1]
    return mesh.vertices, faces


def test_timeout_covers_loading_names_the_stage_and_the_object_is_cached(ros):
    vertices, faces = _badly_wound_sphere()
    req = sphere_request(iterations=2)
    req.mesh = arrays_to_mesh(vertices, faces)
    ros.set_parameters(plan_timeout=0.05)
    try:
        t0 = time.monotonic()
        res = ros.call(req)
        elapsed = time.monotonic() - t0
    finally:
        ros.set_parameters(plan_timeout=60.0)
    assert not res.success and 'timed out' in res.message and 'plan_timeout' in res.message
    assert 'during validation' in res.message, res.message
    assert elapsed < 0.8, elapsed
    # The object is finished in the background and kept: the repeat skips the validation.
    assert wait_for(lambda: ros.node.worker.pending == 0, 30.0)
    hits = ros.node.worker.objects.stats().hits
    res = ros.call(req)
    assert res.success, res.message
    assert ros.node.worker.objects.stats().hits == hits + 1


def test_mesh_files_are_cached_like_inline_meshes(ros):
    req = builtin_request(object_name='', mesh_uri='cube.stl', iterations=2)
    assert ros.call(req).success
    stats = ros.node.worker.objects.stats()
    assert ros.call(req).success
    after = ros.node.worker.objects.stats()
    assert after.hits == stats.hits + 1 and after.entries == stats.entries
    assert 0 < after.nbytes <= ros.node.worker.objects.max_bytes


def test_cancelling_a_queued_goal_answers_at_once(ros):
    ros.set_parameters(plan_timeout=3.0)
    try:
        running = ros.client.call_async(builtin_request('sphere', iterations=10000))
        # Started, not only admitted (a place is reserved before the job reaches the worker).
        assert wait_for(lambda: ros.node.worker.admission.select(lambda job: job.started), 30.0)
        # Cancelled right after acceptance, each goal may reach the node before its execute
        # callback has registered its job (one in five did): it must still be answered now,
        # not when the running plan ends.
        for _ in range(4):
            goal_handle = ros.wait(ros.action_client.send_goal_async(_goal(iterations=3)), 10.0)
            assert goal_handle.accepted
            t0 = time.monotonic()
            ros.wait(goal_handle.cancel_goal_async(), 10.0)
            wrapped = ros.wait(goal_handle.get_result_async(), 10.0)
            elapsed = time.monotonic() - t0
            assert wrapped.status == GoalStatus.STATUS_CANCELED, wrapped.result.message
            assert 'cancelled while queued' in wrapped.result.message
            assert elapsed < 1.0, elapsed
        assert not running.done()  # the running plan was not waited for
        answer = ros.wait(running, CALL_TIMEOUT)
        assert 'timed out' in answer.message
    finally:
        ros.set_parameters(plan_timeout=60.0)
    assert wait_for(lambda: ros.node.worker.pending == 0, 10.0)


def test_two_workers_plan_two_requests_at_once(ros):
    """workers 2, queue_length 0: two plans run together, a third caller is told busy."""
    pair = ros.nodes['pair']
    ros.set_parameters(node='pair', plan_timeout=1.5)
    try:
        first = ros.clients['pair'].call_async(builtin_request('sphere', iterations=10000))
        second = ros.clients['pair'].call_async(builtin_request('cube', iterations=10000))
        assert wait_for(lambda: pair.worker.pending == 2, 30.0)
        third = ros.call(builtin_request('barrel', iterations=2), node='pair')
        assert not third.success and third.message.startswith('busy') and 'workers 2' in third.message
        answers = [ros.wait(f, CALL_TIMEOUT) for f in (first, second)]
    finally:
        ros.set_parameters(node='pair', plan_timeout=60.0)
    # Both ran in parallel: each was stopped by the timeout while planning, with a grasp so far.
    assert all('timed out' in a.message and 'planning' in a.message for a in answers), [a.message for a in answers]
    assert all(a.configuration.name for a in answers)
    assert all(a.planning_time < 1.5 + 1.5 for a in answers)
    ok = ros.call(builtin_request('cube', iterations=2), node='pair')
    assert ok.success, ok.message
