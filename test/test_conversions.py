"""grasp_apso.ros.conversions: messages <-> numpy, with real planner results (no DDS)."""
import math

import numpy as np
import pytest

pytest.importorskip('rclpy')

from geometry_msgs.msg import PoseStamped  # noqa: E402
from grasp_apso_interfaces.action import PlanGrasp as PlanGraspAction  # noqa: E402
from grasp_apso_interfaces.srv import PlanGrasp  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from std_msgs.msg import Header  # noqa: E402
from visualization_msgs.msg import Marker  # noqa: E402

from grasp_apso.model import builtin as builtin_objects  # noqa: E402
from grasp_apso.model import poses  # noqa: E402
from grasp_apso.ros import conversions, markers as ros_markers  # noqa: E402
from grasp_apso.model.scene import BOX, Scene  # noqa: E402
from grasp_apso.model.hand import JOINT_NAMES, load_hand  # noqa: E402
from grasp_apso.errors import ObjectError  # noqa: E402
from grasp_apso.search.planner import IterationStats, PlanOptions, plan  # noqa: E402


@pytest.fixture(scope='module')
def planned():
    pose = poses.pose_to_matrix((0.4, -0.1, 0.8), (0.0, 0.0, math.sin(0.3), math.cos(0.3)))
    result = plan(builtin_objects.builtin('cube'), pose=pose, options=PlanOptions(particles=20, iterations=4),
                  rng=np.random.default_rng(5))
    return pose, result


def test_mesh_roundtrip_through_serialisation():
    sphere = builtin_objects.builtin('sphere')
    msg = conversions.arrays_to_mesh(sphere.mesh.vertices, sphere.mesh.faces)
    back = deserialize_message(serialize_message(msg), type(msg))
    vertices, triangles = conversions.mesh_to_arrays(back)
    assert vertices.dtype == np.float64 and triangles.dtype == np.int64
    assert np.array_equal(vertices, sphere.mesh.vertices)
    assert np.array_equal(triangles, sphere.mesh.faces)


def test_packed_mesh_roundtrip_through_a_serialised_request():
    fish = builtin_objects.builtin('fish')
    req = PlanGrasp.Request()
    req.mesh_vertices, req.mesh_triangles = conversions.arrays_to_packed(fish.mesh.vertices, fish.mesh.faces)
    back = deserialize_message(serialize_message(req), PlanGrasp.Request)
    vertices, triangles = conversions.packed_mesh_to_arrays(back.mesh_vertices, back.mesh_triangles)
    assert vertices.dtype == np.float64 and triangles.dtype == np.int64
    assert np.array_equal(vertices, fish.mesh.vertices)
    assert np.array_equal(triangles, fish.mesh.faces)
    assert len(back.mesh.vertices) == 0  # the shape_msgs/Mesh field stays empty


@pytest.mark.parametrize('vertices, triangles, field', [
    ([0.0] * 8, [0, 1, 2], 'mesh_vertices'),
    ([0.0] * 9, [0, 1, 2, 0], 'mesh_triangles'),
])
def test_packed_lengths_must_be_triples(vertices, triangles, field):
    with pytest.raises(ValueError, match=field):
        conversions.packed_mesh_to_arrays(vertices, triangles)


def test_arrays_to_packed_refuses_bad_shapes_and_indices():
    with pytest.raises(ValueError, match='vertices'):
        conversions.arrays_to_packed(np.zeros((4, 2)), np.zeros((1, 3), int))
    with pytest.raises(ValueError, match='triangles'):
        conversions.arrays_to_packed(np.zeros((4, 3)), np.array([[0, 1, -1]]))
    with pytest.raises(ValueError, match='triangles'):
        conversions.arrays_to_packed(np.zeros((4, 3)), np.array([[0, 1, 2**32]]))
    with pytest.raises(ValueError, match='whole numbers'):
        conversions.arrays_to_packed(np.zeros((4, 3)), np.array([[0, 1, 2.5]]))
    # Floats that hold whole numbers are indices too.
    assert list(conversions.arrays_to_packed(np.zeros((4, 3)), np.array([[0.0, 1.0, 3.0]]))[1]) == [0, 1, 3]


def test_empty_mesh_gives_empty_arrays():
    vertices, triangles = conversions.mesh_to_arrays(PlanGrasp.Request().mesh)
    assert vertices.shape == (0, 3) and triangles.shape == (0, 3)


def test_pose_stamped_to_matrix():
    pose = PoseStamped()
    pose.header.frame_id = 'table'
    pose.pose.position.x, pose.pose.position.z = 0.5, 0.2
    pose.pose.orientation.z, pose.pose.orientation.w = math.sin(0.25), math.cos(0.25)
    frame, matrix = conversions.pose_stamped_to_matrix(pose)
    assert frame == 'table'
    assert np.allclose(matrix[:3, 3], (0.5, 0.0, 0.2))
    assert np.allclose(matrix[:3, :3] @ (1, 0, 0), (math.cos(0.5), math.sin(0.5), 0.0))
    back = conversions.matrix_to_pose_msg(matrix)
    assert math.isclose(back.orientation.z, math.sin(0.25)) and math.isclose(back.position.x, 0.5)


@pytest.mark.parametrize('quat, words', [((0, 0, 0, 0), 'zero quaternion'), ((0, 0, 1, 1), 'not unit')])
def test_bad_quaternions_name_object_pose(quat, words):
    pose = PoseStamped()
    q = pose.pose.orientation
    q.x, q.y, q.z, q.w = quat
    with pytest.raises(ObjectError, match=f'object_pose: .*{words}'):
        conversions.pose_stamped_to_matrix(pose)


@pytest.mark.parametrize('msg_type', [PlanGrasp.Response, PlanGraspAction.Result])
def test_fill_result(planned, msg_type):
    pose, result = planned
    header = Header(frame_id='table')
    header.stamp.sec = 7
    msg = conversions.fill_result(msg_type(), result, header)
    assert list(msg.configuration.name) == list(JOINT_NAMES)
    assert np.allclose(msg.configuration.position, result.joint_positions)
    assert msg.configuration.header.frame_id == 'table' and msg.configuration.header.stamp.sec == 7
    assert msg.wrist_pose.header.frame_id == 'table'
    p = msg.wrist_pose.pose.position
    assert np.allclose([p.x, p.y, p.z], result.wrist_pose[:3, 3])
    back = poses.pose_to_matrix([p.x, p.y, p.z], [getattr(msg.wrist_pose.pose.orientation, a) for a in 'xyzw'])
    assert np.allclose(back, result.wrist_pose, atol=1e-9)
    assert len(msg.contact_points) == result.n_contacts == len(msg.contact_fingers)
    assert msg.contact_fingers == [c.finger for c in result.contacts]
    assert msg.fitness == result.fitness and msg.epsilon_quality == result.epsilon
    assert msg.force_closure == result.force_closure and msg.iterations_run == result.iterations_run
    assert math.isclose(msg.planning_time, result.planning_time + result.preparation_time)
    serialize_message(msg)  # every field has the right type


def test_progress_msg():
    stats = IterationStats(iteration=3, iterations=10, best_fitness=0.5, mean_fitness=-float('inf'),
                           active_particles=7, best_contacts=4, evaluations=60, elapsed=0.25)
    msg = conversions.progress_msg(stats, 'abc', 'pso', Header(frame_id='world'))
    assert (msg.request_id, msg.algorithm, msg.iteration, msg.iterations) == ('abc', 'pso', 3, 10)
    assert msg.active_particles == 7 and msg.best_contacts == 4 and msg.elapsed == 0.25
    assert msg.mean_fitness == -float('inf')
    serialize_message(msg)


def test_grasp_markers(planned):
    _, result = planned
    header = Header(frame_id='table')
    markers = ros_markers.grasp_markers(result, header, load_hand()).markers
    assert markers[0].action == Marker.DELETEALL
    assert all(m.header.frame_id == 'table' for m in markers)
    ids = [(m.ns, m.id) for m in markers[1:]]
    assert len(ids) == len(set(ids))
    links = [m for m in markers if m.ns == 'grasp_apso/links']
    assert len(links) == 5 and all(m.type == Marker.LINE_LIST and len(m.points) == 8 for m in links)
    tips = [m for m in markers if m.ns == 'grasp_apso/fingertips'][0]
    assert tips.type == Marker.SPHERE_LIST and len(tips.points) == 5 == len(tips.colors)
    assert np.allclose([[p.x, p.y, p.z] for p in tips.points], result.joints[:, -1])
    normals = [m for m in markers if m.ns == 'grasp_apso/normals']
    assert len(normals) == result.n_contacts and all(m.type == Marker.ARROW for m in normals)
    serialize_message(ros_markers.grasp_markers(result, header, load_hand()))


def test_grasps_field_by_field_and_top_level_is_the_first(planned):
    pose, result = planned
    header = Header(frame_id='table')
    msg = conversions.fill_result(PlanGrasp.Response(), result, header)
    assert msg.grasp_source == 'planned'
    assert len(msg.grasps) == len(result.candidates) >= 1
    for g, c in zip(msg.grasps, result.candidates):
        assert g.id == c.id
        assert list(g.grasp_posture.name) == list(JOINT_NAMES) == list(g.pre_grasp_posture.name)
        assert np.allclose(g.grasp_posture.position, c.joint_positions)
        assert np.allclose(g.pre_grasp_posture.position, c.pre_grasp_positions)
        for stamped, matrix in ((g.grasp_pose, c.wrist_pose), (g.pre_grasp_pose, c.pre_grasp_pose)):
            assert stamped.header.frame_id == 'table'
            p, q = stamped.pose.position, stamped.pose.orientation
            assert np.allclose(poses.pose_to_matrix([p.x, p.y, p.z], [q.x, q.y, q.z, q.w]), matrix, atol=1e-9)
        v = g.approach_direction.vector
        assert g.approach_direction.header.frame_id == 'table'
        assert np.allclose([v.x, v.y, v.z], c.approach) and math.isclose(np.linalg.norm([v.x, v.y, v.z]), 1.0)
        # The pre-grasp lies approach_distance back along the approach.
        back = np.array([g.grasp_pose.pose.position.x - g.pre_grasp_pose.pose.position.x,
                         g.grasp_pose.pose.position.y - g.pre_grasp_pose.pose.position.y,
                         g.grasp_pose.pose.position.z - g.pre_grasp_pose.pose.position.z])
        assert np.allclose(back, g.approach_distance * np.array([v.x, v.y, v.z]), atol=1e-9)
        assert g.sim_result == c.sim_result and g.contact_fingers == [x.finger for x in c.contacts]
    first = msg.grasps[0]
    assert list(msg.configuration.position) == list(first.grasp_posture.position)
    assert msg.wrist_pose == first.grasp_pose
    assert msg.fitness == first.fitness and msg.epsilon_quality == first.epsilon_quality
    assert msg.contact_points == first.contact_points
    serialize_message(msg)


def test_markers_show_scene_approach_and_pre_grasp(planned):
    _, result = planned
    scene = Scene.from_primitives(planes=[(0, 0, 1, 0.0)], obstacles=[(BOX, (0.1, 0.1, 0.1))],
                                  obstacle_poses=[np.eye(4)])
    markers = ros_markers.grasp_markers(result, Header(frame_id='table'), load_hand(), scene).markers
    by_ns = {}
    for m in markers[1:]:
        by_ns.setdefault(m.ns, []).append(m)
    assert len(by_ns['grasp_apso/scene']) == 1 and by_ns['grasp_apso/scene'][0].type == Marker.CUBE
    table = by_ns['grasp_apso/scene'][0]
    assert table.scale.z == ros_markers.PLANE_THICKNESS and table.scale.x >= 0.5
    assert math.isclose(table.pose.position.z, -ros_markers.PLANE_THICKNESS / 2)  # on the solid side
    assert len(by_ns['grasp_apso/obstacles']) == 1
    assert len(by_ns['grasp_apso/approach']) == len(result.candidates)
    assert {'grasp_apso/pre_grasp_palm', 'grasp_apso/pre_grasp_links'} <= set(by_ns)
    assert all(m.color.a < 0.5 for m in by_ns['grasp_apso/pre_grasp_links'])
    # One palette with the pictures.
    from grasp_apso.presentation import palette
    from grasp_apso.tools import plotting
    assert plotting.FINGER_COLORS is palette.FINGER_COLORS
    thumb = by_ns['grasp_apso/links'][4].color
    assert np.allclose([thumb.r, thumb.g, thumb.b], palette.rgb(palette.FINGER_COLORS['thumb']))
    serialize_message(ros_markers.grasp_markers(result, Header(frame_id='table'), load_hand(), scene))


def test_progress_msg_distinct_candidates():
    stats = IterationStats(iteration=1, iterations=2, best_fitness=0.5, mean_fitness=0.1,
                           active_particles=3, best_contacts=3, evaluations=6, elapsed=0.1)
    expected = int(getattr(stats, 'distinct_candidates', 0))
    assert conversions.progress_msg(stats, 'a', 'apso', Header()).distinct_candidates == expected


def _seconds(duration):
    return duration.sec + duration.nanosec * 1e-9


def test_paper_hand_replies_carry_the_hand_trajectory(planned):
    _, result = planned
    hand = load_hand()
    msg = conversions.fill_result(PlanGrasp.Response(), result, Header(frame_id='table'), hand=hand)
    squeeze = math.radians(8.0)  # the simulation protocol's squeeze (DESIGN.md Part 2)
    for g, c in zip(msg.grasps, result.candidates):
        traj = g.hand_trajectory
        assert list(traj.joint_names) == list(g.grasp_posture.name) == list(JOINT_NAMES)
        assert traj.header.frame_id == 'table' and len(traj.points) == 3
        times = [_seconds(p.time_from_start) for p in traj.points]
        assert times[0] == 0.0 and times[0] < times[1] < times[2]
        q = np.array([p.positions for p in traj.points])
        assert np.allclose(q[0], c.pre_grasp_positions) and np.allclose(q[1], c.joint_positions)
        # Independent: every flexion (distal, proximal of each finger: indices 0, 1 mod 3 of
        # the 15 finger joints) 8 degrees further, clipped; pivots and wrist angles unchanged.
        flex = np.zeros(18, dtype=bool)
        flex[0:15:3] = flex[1:15:3] = True
        expected = np.array(c.joint_positions, dtype=float)
        expected[flex] = np.minimum(expected[flex] + squeeze, hand.upper[:15][flex[:15]])
        assert np.allclose(q[2], expected)
        assert np.any(q[2][flex] > q[1][flex])  # it does squeeze
    serialize_message(msg)


def test_general_hand_joint_names_in_the_reply(planned, tmp_path):
    """A result over another hand's actuated joints (hand-built from the paper plan's
    numbers) goes through: the JointStates and the trajectory carry those names."""
    import dataclasses

    from hand_files import write_allegro_like

    from grasp_apso.model.hands.load import load_hand as load_any_hand

    hand = load_any_hand(write_allegro_like(tmp_path), spheres=False)
    n = len(hand.actuated_joints)
    rng = np.random.default_rng(3)
    _, result = planned
    grasp = rng.uniform(hand.lower, hand.upper)
    candidates = tuple(dataclasses.replace(c, joint_positions=grasp + i * 1e-3, pre_grasp_positions=hand.lower.copy(),
                                           joints=np.zeros((0, 4, 3)), pre_grasp_joints=np.zeros((0, 4, 3)))
                       for i, c in enumerate(result.candidates))
    general = dataclasses.replace(result, joint_names=hand.actuated_joints, candidates=candidates,
                                  joint_positions=candidates[0].joint_positions)
    msg = conversions.fill_result(PlanGrasp.Response(), general, Header(frame_id='table'), hand=hand)
    assert list(msg.configuration.name) == list(hand.actuated_joints) and len(msg.configuration.position) == n
    assert np.allclose(msg.configuration.position, grasp)
    for g, c in zip(msg.grasps, candidates):
        assert list(g.grasp_posture.name) == list(g.hand_trajectory.joint_names) == list(hand.actuated_joints)
        q = np.array([p.positions for p in g.hand_trajectory.points])
        assert q.shape == (3, n) and np.allclose(q[0], hand.lower) and np.allclose(q[1], c.joint_positions)
    serialize_message(msg)
    markers = ros_markers.grasp_markers(general, Header(frame_id='table'), hand).markers
    drawn = [m for m in markers if m.ns == 'grasp_apso/hand']
    assert drawn and all(m.type == Marker.TRIANGLE_LIST and len(m.points) % 3 == 0 for m in drawn)
    assert not [m for m in markers if m.ns in ('grasp_apso/palm', 'grasp_apso/links')]
    assert sum(len(m.points) for m in drawn) // 3 <= 3500
    # Independent: the drawn hand's points lie where the links are: every link origin placed by
    # wrist_pose @ link_transforms is within the link's own extent of some drawn point.
    points = np.array([[p.x, p.y, p.z] for m in drawn for p in m.points])
    poses_ = hand.link_transforms(general.joint_positions)
    tip = general.wrist_pose @ poses_[hand.fingers[0].pad_link]
    assert np.min(np.linalg.norm(points - tip[:3, 3], axis=1)) < 0.03
    assert {m.ns for m in markers} >= {'grasp_apso/pre_grasp_hand', 'grasp_apso/approach'}
    serialize_message(ros_markers.grasp_markers(general, Header(frame_id='table'), hand))
