"""The node with a general hand (issue 21): ``hand_description`` = the Allegro-like URDF.

Real rclpy and DDS, the real planner. A node started with the URDF answers with the hand's
actuated joints (the JointStates and every grasp's ``hand_trajectory``: pre-grasp, grasp,
squeeze), ``grasp_pose`` its root link; a grasp database written for that hand answers a
node of that hand and is refused by a node of another hand.
"""
import datetime as dt

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

rclpy = pytest.importorskip('rclpy')

from rclpy.parameter import Parameter  # noqa: E402

from grasp_apso_interfaces.srv import PlanGrasp  # noqa: E402
from hand_files import urdf_actuated_joints as _urdf_actuated, write_allegro_like  # noqa: E402
from node_helpers import DISCOVERY_TIMEOUT, SpinningNode, identity_pose, wait_future  # noqa: E402

from grasp_apso.database.schema import GRASP_SCHEMA, candidate_rows  # noqa: E402
from grasp_apso.model import poses  # noqa: E402
from grasp_apso.model.builtin import builtin  # noqa: E402
from grasp_apso.model.planning_hand import load_planning_hand  # noqa: E402
from grasp_apso.ros.node import GraspPlannerNode  # noqa: E402
from grasp_apso.search.options import PlanOptions  # noqa: E402
from grasp_apso.search.planner import plan  # noqa: E402

SMALL = dict(particles=30, iterations=6)
CALL_TIMEOUT = 240.0


def _allegro_database(path, hand):
    """A one-file grasp database of the cube planned with the Allegro-like hand."""
    obj = builtin('cube')
    result = plan(obj, np.eye(4), PlanOptions(particles=30, iterations=6, max_grasps=3), rng=np.random.default_rng(3),
                  hand=hand.hand)
    assert any(c.valid for c in result.candidates)
    common = {'object_id': 'cube', 'source_path': 'cube.stl', 'source_sha256': '0' * 64, 'scale': 1.0,
              'mesh_hash': obj.mesh_hash, 'hand_name': hand.name, 'hand_hash': hand.hash, 'options_key': 'k' * 16,
              'options': '{}', 'seed': 3, 'package_version': 'test', 'planning_time': 0.1,
              'created': dt.datetime.now(dt.timezone.utc)}
    cols = candidate_rows(result.candidates, np.eye(4), common, wrist_angles=False)
    pq.write_table(pa.Table.from_pydict(cols, schema=GRASP_SCHEMA), path)
    return path


@pytest.fixture(scope='module')
def ros(tmp_path_factory):
    folder = tmp_path_factory.mktemp('any_hand_node')
    urdf = write_allegro_like(folder)
    hand = load_planning_hand(str(urdf))
    database = _allegro_database(folder / 'allegro.parquet', hand)
    context = rclpy.context.Context()
    rclpy.init(context=context)
    configs = {
        'allegro': dict(hand_description=str(urdf)),
        'allegro_db': dict(hand_description=str(urdf), grasp_database=str(database)),
        'paper_db': dict(grasp_database=str(database)),
    }
    servers = {}
    for key, config in configs.items():
        values = {**SMALL, **config}
        node = GraspPlannerNode(f'grasp_apso_{key}', context=context,
                                parameter_overrides=[Parameter(k, value=v) for k, v in values.items()])
        servers[key] = SpinningNode(context, key, num_threads=4, node=node)
    client = SpinningNode(context, 'grasp_apso_any_hand_client')
    clients = {k: client.node.create_client(PlanGrasp, f'/grasp_apso_{k}/plan_grasp') for k in servers}
    for spinner in (*servers.values(), client):
        spinner.start()
    try:
        for key, c in clients.items():
            assert c.wait_for_service(timeout_sec=DISCOVERY_TIMEOUT), key

        def call(key, request):
            return wait_future(clients[key].call_async(request), CALL_TIMEOUT, spinners=(*servers.values(), client))

        yield call, urdf, hand, {k: s.node for k, s in servers.items()}
    finally:
        for spinner in servers.values():
            spinner.close()
        client.close()
        rclpy.shutdown(context=context)


def _cube_request(seed=5):
    req = PlanGrasp.Request()
    req.object_name = 'cube'
    req.object_pose = identity_pose(frame='world')
    req.seed = seed
    for key, value in SMALL.items():
        setattr(req, key, value)
    return req


def _seconds(duration):
    return duration.sec + duration.nanosec * 1e-9


def test_a_urdf_node_answers_with_the_hand_s_actuated_joints(ros):
    call, urdf, hand, nodes = ros
    assert nodes['allegro'].parameters.planning_hand.hash == hand.hash
    res = call('allegro', _cube_request())
    assert res.success, res.message
    names = _urdf_actuated(urdf)
    assert len(names) == 16 and list(res.configuration.name) == names
    q = np.array(res.configuration.position)
    assert np.all(q >= hand.hand.lower - 1e-9) and np.all(q <= hand.hand.upper + 1e-9)
    assert res.grasps and res.grasp_source == 'planned'
    closing = np.zeros(len(names))
    for finger in hand.hand.fingers:
        for joint, sense in zip(finger.joints, finger.closing):
            closing[names.index(joint)] = sense
    for g in res.grasps:
        assert list(g.grasp_posture.name) == list(g.pre_grasp_posture.name) == names
        traj = g.hand_trajectory
        assert list(traj.joint_names) == names and len(traj.points) == 3
        times = [_seconds(p.time_from_start) for p in traj.points]
        assert times[0] == 0.0 < times[1] < times[2]
        pts = np.array([p.positions for p in traj.points])
        assert np.allclose(pts[0], g.pre_grasp_posture.position) and np.allclose(pts[1], g.grasp_posture.position)
        # The squeeze presses the pads into the object (q + J^T f / kp over every joint, the
        # pads' gaps taken up: grasp_apso.quality.closing), so it closes on the whole, within
        # the limits; single joints (a pre-shape joint, a distal joint) may move either way.
        step = pts[2] - pts[1]
        assert np.sum(step * closing) > 0.0 and np.any(step != 0)
        assert np.all(pts[2] >= hand.hand.lower - 1e-9) and np.all(pts[2] <= hand.hand.upper + 1e-9)
    # grasp_pose is the root link: the contacts lie where link_transforms puts the pads.
    best = res.grasps[0]
    p, o = best.grasp_pose.pose.position, best.grasp_pose.pose.orientation
    root = poses.pose_to_matrix([p.x, p.y, p.z], [o.x, o.y, o.z, o.w])
    links = hand.hand.link_transforms(np.array(best.grasp_posture.position))
    pads = {f.name: (root @ links[f.pad_link] @ np.r_[f.pad_center, 1.0])[:3] for f in hand.hand.fingers}
    for point, finger in zip(best.contact_points, best.contact_fingers):
        assert np.linalg.norm(np.array([point.x, point.y, point.z]) - pads[finger]) < 0.03


def test_a_database_answers_only_the_hand_it_was_written_for(ros):
    call, urdf, hand, nodes = ros
    res = call('allegro_db', _cube_request())
    assert res.success, res.message
    assert res.grasp_source == 'database', res.message
    assert list(res.configuration.name) == _urdf_actuated(urdf)
    assert all(len(g.hand_trajectory.points) == 3 for g in res.grasps)
    other = call('paper_db', _cube_request())
    assert other.success, other.message
    assert other.grasp_source == 'planned' and len(other.configuration.name) == 18
    assert nodes['paper_db'].parameters.database.other_rows > 0 and len(nodes['paper_db'].parameters.database) == 0
