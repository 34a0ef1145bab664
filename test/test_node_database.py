"""The node answers stored objects from a grasp database (parameter ``grasp_database``).

A real database, written by the batch tool (``grasp_apso_batch``, one local worker) from
the built-in cube exported to STL; a real node in this process over real DDS, a client
in another executor (``node_helpers.SpinningNode``). No mocks.
"""
import time

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
pytest.importorskip('pyarrow')

from rclpy.parameter import Parameter  # noqa: E402
from geometry_msgs.msg import Pose  # noqa: E402
from shape_msgs.msg import Plane, SolidPrimitive  # noqa: E402

from grasp_apso_interfaces.srv import PlanGrasp  # noqa: E402

from node_helpers import DISCOVERY_TIMEOUT, SpinningNode, table_pose, wait_future  # noqa: E402

from grasp_apso.errors import DatabaseError  # noqa: E402
from grasp_apso.model import builtin as builtin_objects  # noqa: E402
from grasp_apso.model import mesh_files  # noqa: E402
from grasp_apso.ros.conversions import arrays_to_packed  # noqa: E402
from grasp_apso.ros.node import GraspPlannerNode  # noqa: E402

CALL_TIMEOUT = 60.0
SMALL = dict(particles=20, iterations=8, seed=3)


@pytest.fixture(scope='module')
def database(tmp_path_factory):
    """A grasp database of the cube (3 grasps) and the cube as the batch read it."""
    from grasp_apso.tools.batch_cli import main as batch_main

    root = tmp_path_factory.mktemp('graspdb')
    stl = root / 'cube.stl'
    builtin_objects.builtin('cube').mesh.export(str(stl))
    status = batch_main([str(stl), '--out', str(root / 'db'), '--grasps', '3', '--workers', '1',
                         '--particles', '20', '--iterations', '10', '--progress', 'none'])
    assert status == 0
    obj = mesh_files.from_file(str(stl), allowed_dir=str(root))
    return root / 'db', obj


@pytest.fixture(scope='module')
def ros(database):
    path, obj = database
    context = rclpy.context.Context()
    rclpy.init(context=context)
    node = GraspPlannerNode('grasp_apso_db', context=context, parameter_overrides=[
        Parameter('grasp_database', value=str(path)), Parameter('particles', value=20)])
    server = SpinningNode(context, 'grasp_apso_db', num_threads=4, node=node)
    client = SpinningNode(context, 'grasp_apso_db_client')
    plan_client = client.node.create_client(PlanGrasp, '/grasp_apso_db/plan_grasp')
    server.start()
    client.start()
    try:
        assert plan_client.wait_for_service(timeout_sec=DISCOVERY_TIMEOUT), 'service not found'

        def call(req):
            return wait_future(plan_client.call_async(req), CALL_TIMEOUT, spinners=(server, client))
        yield dict(context=context, node=node, call=call, obj=obj)
    finally:
        server.close()
        client.close()
        rclpy.shutdown(context=context)


def cube_request(obj, pose=None, **fields):
    """The cube as the database stored it (the STL's mesh, packed inline)."""
    req = PlanGrasp.Request()
    req.mesh_vertices, req.mesh_triangles = arrays_to_packed(obj.mesh.vertices, obj.mesh.faces)
    req.object_pose = pose if pose is not None else table_pose(position=(0.5, 0.0, 0.8), rpy=(0.0, 0.0, 0.4),
                                                               frame='base')[0]
    for key, value in {**SMALL, **fields}.items():
        setattr(req, key, value)
    return req


def test_a_stored_object_is_answered_from_the_database(ros):
    req = cube_request(ros['obj'], max_grasps=3)
    ros['call'](req)  # the first call loads the object into the node's cache
    t0 = time.perf_counter()
    res = ros['call'](req)
    elapsed = time.perf_counter() - t0
    print(f'\nround trip of a stored object: {1000 * elapsed:.1f} ms (planning_time {1000 * res.planning_time:.1f} ms)')
    assert res.success, res.message
    assert res.grasp_source == 'database', res.message
    assert 'from the grasp database (3 stored, ' in res.message, res.message
    assert 1 <= len(res.grasps) <= 3
    assert res.iterations_run == 0
    first = res.grasps[0]
    assert res.wrist_pose == first.grasp_pose and res.fitness == first.fitness
    assert first.grasp_pose.header.frame_id == 'base'
    # The stored grasps were moved to the request's pose: contacts lie on the moved cube.
    _, matrix = table_pose(position=(0.5, 0.0, 0.8), rpy=(0.0, 0.0, 0.4), frame='base')
    local = [np.linalg.solve(matrix, [p.x, p.y, p.z, 1.0])[:3] for p in first.contact_points]
    half = np.abs(np.asarray(ros['obj'].mesh.vertices)).max(axis=0)
    assert all(np.all(np.abs(q) <= half + 0.005) for q in local), local


def test_a_scene_that_rules_out_every_stored_grasp_falls_back_to_planning(ros, database):
    """A 4 cm box where each stored grasp puts the palm (clear of the cube) and a table
    under the cube leave no stored grasp: the node plans instead, and says why."""
    from grasp_apso.database.lookup import GraspDatabase

    pose, matrix = table_pose(position=(0.5, 0.0, 0.8), rpy=(0.0, 0.0, 0.4), frame='base')
    obj = ros['obj']
    db = GraspDatabase.open(database[0])
    stored = db.lookup(obj.mesh_hash, db.hand.name, matrix, None, max_grasps=50)
    assert len(stored) == 3
    req = cube_request(obj, pose=pose, iterations=4)
    obstacles, poses = [], []
    for grasp in stored:
        p = Pose()
        p.position.x, p.position.y, p.position.z = (float(v) for v in grasp.wrist_pose[:3, 3])
        p.orientation.w = 1.0
        obstacles.append(SolidPrimitive(type=SolidPrimitive.BOX, dimensions=[0.04, 0.04, 0.04]))
        poses.append(p)
    req.obstacles, req.obstacle_poses = obstacles, poses
    half = np.abs(np.asarray(obj.mesh.vertices)).max(axis=0)
    req.support_planes = [Plane(coef=[0.0, 0.0, 1.0, -(0.8 - half[2])])]
    res = ros['call'](req)
    print(f'\nfallback: {res.message}')
    assert 'the grasp database holds 3 grasp(s) of this object, none kept after the scene check' in res.message
    assert res.grasp_source == 'planned', res.message
    assert res.iterations_run >= 1


def test_an_unknown_object_is_planned(ros):
    req = PlanGrasp.Request()
    req.object_name = 'sphere'
    req.object_pose.header.frame_id = 'world'
    req.object_pose.pose.orientation.w = 1.0
    for key, value in {**SMALL, 'iterations': 2}.items():
        setattr(req, key, value)
    res = ros['call'](req)
    assert res.grasp_source == 'planned', res.message
    assert 'database' not in res.message


def test_grasp_database_is_read_only(ros, tmp_path):
    node = ros['node']
    assert node.describe_parameter('grasp_database').read_only
    (result,) = node.set_parameters([Parameter('grasp_database', value=str(tmp_path))])
    assert not result.successful and 'read-only' in result.reason.lower(), result.reason


@pytest.mark.parametrize('kind', ['corrupt_file', 'corrupt_part', 'missing'])
def test_a_bad_database_stops_the_node_naming_the_parameter(ros, database, tmp_path, kind):
    if kind == 'corrupt_file':
        path = tmp_path / 'grasps.parquet'
        path.write_bytes(b'PAR1 this is not a parquet file \x00\xff' * 20)
    elif kind == 'corrupt_part':
        import shutil
        path = tmp_path / 'db'
        shutil.copytree(database[0], path)
        part = next((path / 'grasps').glob('*.parquet'))
        part.write_bytes(part.read_bytes()[: len(part.read_bytes()) // 2])
    else:
        path = tmp_path / 'nowhere'
    with pytest.raises(DatabaseError) as info:
        GraspPlannerNode(f'grasp_apso_bad_{kind}', context=ros['context'],
                         parameter_overrides=[Parameter('grasp_database', value=str(path))])
    assert str(info.value).startswith('grasp_database: '), str(info.value)
