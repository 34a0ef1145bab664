"""The generated ROS 2 interfaces of grasp_apso_interfaces (srv_defs/).

Checks the field names and types of GraspProgress, the PlanGrasp service and the
PlanGrasp action against the interface definitions, serialises and deserialises
messages with rclpy, and sends a request and an action goal through the middleware.
"""
import math
import threading

import pytest

rclpy = pytest.importorskip('rclpy')
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402

from geometry_msgs.msg import Point, Pose, PoseStamped, Vector3  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from shape_msgs.msg import Mesh, MeshTriangle  # noqa: E402

from grasp_apso_interfaces.action import PlanGrasp as PlanGraspAction  # noqa: E402
from grasp_apso_interfaces.msg import GraspProgress  # noqa: E402
from grasp_apso_interfaces.srv import PlanGrasp  # noqa: E402

REQUEST_FIELDS = {
    'mesh': 'shape_msgs/Mesh',
    'mesh_vertices': 'sequence<double>',
    'mesh_triangles': 'sequence<uint32>',
    'mesh_uri': 'string',
    'object_name': 'string',
    'object_pose': 'geometry_msgs/PoseStamped',
    'algorithm': 'string',
    'particles': 'uint32',
    'iterations': 'uint32',
    'seed': 'int64',
    'fix_wrist_position': 'boolean',
    'wrist_position': 'geometry_msgs/Point',
    # Part 2: the scene, the approach, candidates and the simulation check.
    'support_planes': 'sequence<shape_msgs/Plane>',
    'obstacles': 'sequence<shape_msgs/SolidPrimitive>',
    'obstacle_poses': 'sequence<geometry_msgs/Pose>',
    'clearance': 'double',
    'approach_distance': 'double',
    'max_grasps': 'uint32',
    'simulate': 'boolean',
}
RESPONSE_FIELDS = {
    'success': 'boolean',
    'message': 'string',
    'request_id': 'string',
    'configuration': 'sensor_msgs/JointState',
    'wrist_pose': 'geometry_msgs/PoseStamped',
    'fitness': 'double',
    'epsilon_quality': 'double',
    'force_closure': 'boolean',
    'contact_points': 'sequence<geometry_msgs/Point>',
    'contact_normals': 'sequence<geometry_msgs/Vector3>',
    'contact_fingers': 'sequence<string>',
    'iterations_run': 'uint32',
    'planning_time': 'double',
    'grasps': 'sequence<grasp_apso_interfaces/Grasp>',
    'grasp_source': 'string',
}
PROGRESS_FIELDS = {
    'header': 'std_msgs/Header',
    'request_id': 'string',
    'algorithm': 'string',
    'iteration': 'uint32',
    'iterations': 'uint32',
    'best_fitness': 'double',
    'mean_fitness': 'double',
    'active_particles': 'uint32',
    'best_contacts': 'uint32',
    'elapsed': 'double',
    'distinct_candidates': 'uint32',
}
FINGERS = ('little', 'ring', 'middle', 'index', 'thumb')
JOINT_NAMES = [f'{f}_{j}' for f in FINGERS for j in ('distal', 'proximal', 'pivot')] + [
    'wrist_x', 'wrist_y', 'wrist_z']


def tetrahedron_mesh(edge=0.05):
    """A closed tetrahedron (metres) as shape_msgs/Mesh."""
    h = edge / math.sqrt(2.0)
    verts = [(h, 0.0, -h / math.sqrt(2)), (-h, 0.0, -h / math.sqrt(2)),
             (0.0, h, h / math.sqrt(2)), (0.0, -h, h / math.sqrt(2))]
    mesh = Mesh()
    mesh.vertices = [Point(x=x, y=y, z=z) for x, y, z in verts]
    mesh.triangles = [MeshTriangle(vertex_indices=list(t))
                      for t in ((0, 1, 2), (0, 3, 1), (0, 2, 3), (1, 3, 2))]
    return mesh


def make_request():
    req = PlanGrasp.Request()
    req.mesh = tetrahedron_mesh()
    req.object_pose = PoseStamped()
    req.object_pose.header.frame_id = 'table'
    req.object_pose.pose = Pose()
    req.object_pose.pose.position = Point(x=0.4, y=-0.1, z=0.8)
    req.object_pose.pose.orientation.z = math.sin(0.25)
    req.object_pose.pose.orientation.w = math.cos(0.25)
    req.algorithm = 'apso'
    req.particles = 60
    req.iterations = 50
    req.seed = 1234
    req.fix_wrist_position = True
    req.wrist_position = Point(x=0.0, y=0.0, z=0.12)
    return req


def make_response():
    res = PlanGrasp.Response()
    res.success = True
    res.message = 'ok'
    res.request_id = 'req-1'
    res.configuration = JointState(name=JOINT_NAMES,
                                   position=[0.01 * i for i in range(len(JOINT_NAMES))])
    res.configuration.header.frame_id = 'table'
    res.wrist_pose.header.frame_id = 'table'
    res.wrist_pose.pose.position = Point(x=0.4, y=-0.1, z=0.92)
    res.fitness = 0.87
    res.epsilon_quality = 0.12
    res.force_closure = True
    res.contact_points = [Point(x=0.01, y=0.0, z=0.0), Point(x=-0.01, y=0.0, z=0.0),
                          Point(x=0.0, y=0.01, z=0.0)]
    res.contact_normals = [Vector3(x=1.0), Vector3(x=-1.0), Vector3(y=1.0)]
    res.contact_fingers = ['thumb', 'index', 'middle']
    res.iterations_run = 50
    res.planning_time = 3.5
    return res


def make_progress():
    msg = GraspProgress()
    msg.header.frame_id = 'table'
    msg.header.stamp.sec = 12
    msg.header.stamp.nanosec = 345
    msg.request_id = 'req-1'
    msg.algorithm = 'pso'
    msg.iteration = 7
    msg.iterations = 50
    msg.best_fitness = 0.75
    msg.mean_fitness = -0.25
    msg.active_particles = 42
    msg.best_contacts = 4
    msg.elapsed = 1.25
    return msg


# --- field names and types ---------------------------------------------------------------

def test_grasp_progress_fields():
    assert GraspProgress.get_fields_and_field_types() == PROGRESS_FIELDS


def test_service_request_fields():
    assert PlanGrasp.Request.get_fields_and_field_types() == REQUEST_FIELDS


def test_service_response_fields():
    assert PlanGrasp.Response.get_fields_and_field_types() == RESPONSE_FIELDS


def test_action_goal_result_feedback_fields():
    assert PlanGraspAction.Goal.get_fields_and_field_types() == REQUEST_FIELDS
    assert PlanGraspAction.Result.get_fields_and_field_types() == RESPONSE_FIELDS
    assert PlanGraspAction.Feedback.get_fields_and_field_types() == {
        'progress': 'grasp_apso_interfaces/GraspProgress'}
    assert isinstance(PlanGraspAction.Feedback().progress, GraspProgress)


def test_action_wire_types():
    impl = PlanGraspAction.Impl
    assert set(impl.SendGoalService.Request.get_fields_and_field_types()) == {'goal_id', 'goal'}
    assert set(impl.GetResultService.Response.get_fields_and_field_types()) == {'status', 'result'}
    assert set(impl.FeedbackMessage.get_fields_and_field_types()) == {'goal_id', 'feedback'}


def test_request_defaults_mean_node_parameters():
    req = PlanGrasp.Request()
    assert req.algorithm == '' and req.mesh_uri == '' and req.object_name == ''
    assert req.particles == 0 and req.iterations == 0
    assert req.seed == -1, 'seed -1 (the default) means: use the node parameter'
    assert not req.fix_wrist_position
    assert len(req.mesh.vertices) == 0 and len(req.mesh.triangles) == 0
    assert PlanGraspAction.Goal().seed == -1


def test_field_type_checks():
    # Jazzy checks field types only with check_fields=True or ROS_PYTHON_CHECK_FIELDS=1.
    req = PlanGrasp.Request(check_fields=True)
    with pytest.raises((AssertionError, TypeError, ValueError)):
        req.particles = -1          # uint32
    with pytest.raises((AssertionError, TypeError, ValueError)):
        req.seed = 'abc'            # int64
    with pytest.raises((AssertionError, TypeError, ValueError)):
        req.mesh = 'sphere'         # shape_msgs/Mesh
    res = PlanGrasp.Response(check_fields=True)
    with pytest.raises((AssertionError, TypeError, ValueError)):
        res.contact_fingers = [1, 2]
    # Without the checks a bad value still cannot be sent: serialisation fails.
    unchecked = PlanGrasp.Request()
    unchecked.particles = -1
    with pytest.raises(Exception):
        serialize_message(unchecked)


# --- construction and serialisation ------------------------------------------------------

def test_request_with_mesh_roundtrip():
    req = make_request()
    data = serialize_message(req)
    assert isinstance(data, bytes) and len(data) > 0
    back = deserialize_message(data, PlanGrasp.Request)
    assert back == req
    assert len(back.mesh.vertices) == 4 and len(back.mesh.triangles) == 4
    assert list(back.mesh.triangles[1].vertex_indices) == [0, 3, 1]
    assert back.object_pose.header.frame_id == 'table'
    assert back.seed == 1234 and back.fix_wrist_position


def test_response_roundtrip():
    res = make_response()
    back = deserialize_message(serialize_message(res), PlanGrasp.Response)
    assert back == res
    assert list(back.configuration.name) == JOINT_NAMES
    assert len(back.configuration.position) == 18
    assert back.contact_fingers == ['thumb', 'index', 'middle']
    assert back.contact_normals[1].x == -1.0


def test_progress_roundtrip():
    msg = make_progress()
    back = deserialize_message(serialize_message(msg), GraspProgress)
    assert back == msg
    assert back.header.stamp.nanosec == 345 and back.algorithm == 'pso'


def test_action_messages_roundtrip():
    goal = PlanGraspAction.Goal(object_name='barrel', algorithm='pso', seed=7)
    assert deserialize_message(serialize_message(goal), PlanGraspAction.Goal) == goal
    fb = PlanGraspAction.Impl.FeedbackMessage()
    fb.goal_id.uuid = list(range(16))
    fb.feedback.progress = make_progress()
    back = deserialize_message(serialize_message(fb), PlanGraspAction.Impl.FeedbackMessage)
    assert back == fb and back.feedback.progress.best_contacts == 4
    result = PlanGraspAction.Result()
    for name in RESPONSE_FIELDS:
        setattr(result, name, getattr(make_response(), name))
    assert deserialize_message(serialize_message(result), PlanGraspAction.Result) == result


def test_numpy_fixed_array_fields_roundtrip():
    """The wheels' message extensions work with the pinned numpy (fixed-size arrays are numpy)."""
    import numpy as np
    from sensor_msgs.msg import Imu

    msg = Imu()
    msg.orientation_covariance = np.arange(9, dtype=np.float64)
    back = deserialize_message(serialize_message(msg), Imu)
    assert isinstance(back.orientation_covariance, np.ndarray)
    np.testing.assert_array_equal(back.orientation_covariance, np.arange(9.0))


# --- through the middleware --------------------------------------------------------------

@pytest.fixture
def ros_context():
    context = rclpy.context.Context()
    rclpy.init(context=context)
    try:
        yield context
    finally:
        rclpy.shutdown(context=context)


def _spin_until(executor, future, timeout):
    executor.spin_until_future_complete(future, timeout_sec=timeout)
    return future.done()


def test_service_call_through_middleware(ros_context):
    from rclpy.executors import SingleThreadedExecutor

    server_node = rclpy.create_node('test_plan_grasp_server', context=ros_context)
    client_node = rclpy.create_node('test_plan_grasp_client', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(server_node)
    executor.add_node(client_node)
    received = []

    def handle(request, response):
        received.append(request)
        filled = make_response()
        for name in RESPONSE_FIELDS:
            setattr(response, name, getattr(filled, name))
        response.message = f'{len(request.mesh.vertices)} vertices'
        return response

    try:
        server_node.create_service(PlanGrasp, 'plan_grasp', handle)
        client = client_node.create_client(PlanGrasp, 'plan_grasp')
        assert client.wait_for_service(timeout_sec=15.0), 'service not discovered'
        future = client.call_async(make_request())
        assert _spin_until(executor, future, 15.0), 'no response'
        response = future.result()
        assert response.success and response.message == '4 vertices'
        assert list(response.configuration.name) == JOINT_NAMES
        assert received and received[0] == make_request()
    finally:
        executor.shutdown()
        server_node.destroy_node()
        client_node.destroy_node()


def test_action_goal_feedback_result_through_middleware(ros_context):
    from rclpy.action import ActionClient, ActionServer
    from rclpy.callback_groups import ReentrantCallbackGroup
    from rclpy.executors import MultiThreadedExecutor

    server_node = rclpy.create_node('test_plan_grasp_action_server', context=ros_context)
    client_node = rclpy.create_node('test_plan_grasp_action_client', context=ros_context)
    executor = MultiThreadedExecutor(num_threads=2, context=ros_context)
    executor.add_node(server_node)
    executor.add_node(client_node)
    spinner = threading.Thread(target=executor.spin, daemon=True)

    def execute(goal_handle):
        for i in range(1, 4):
            fb = PlanGraspAction.Feedback()
            fb.progress = make_progress()
            fb.progress.iteration = i
            fb.progress.iterations = goal_handle.request.iterations
            goal_handle.publish_feedback(fb)
        goal_handle.succeed()
        result = PlanGraspAction.Result()
        result.success = True
        result.message = goal_handle.request.object_name
        result.iterations_run = 3
        return result

    feedback = []
    try:
        ActionServer(server_node, PlanGraspAction, 'plan_grasp', execute,
                     callback_group=ReentrantCallbackGroup())
        client = ActionClient(client_node, PlanGraspAction, 'plan_grasp')
        spinner.start()
        assert client.wait_for_server(timeout_sec=15.0), 'action server not discovered'
        goal = PlanGraspAction.Goal(object_name='sphere', iterations=3)
        three_feedbacks = threading.Event()

        def on_feedback(message):
            feedback.append(message)
            if len(feedback) >= 3:
                three_feedbacks.set()

        def wait_done(future, timeout):
            done = threading.Event()
            future.add_done_callback(lambda _f: done.set())
            return done.wait(timeout)

        send = client.send_goal_async(goal, feedback_callback=on_feedback)
        assert wait_done(send, 15.0), 'goal not answered'
        goal_handle = send.result()
        assert goal_handle is not None and goal_handle.accepted
        result_future = goal_handle.get_result_async()
        assert wait_done(result_future, 15.0), 'no action result'
        result = result_future.result().result
        assert result.success and result.message == 'sphere' and result.iterations_run == 3
        # Feedback is best effort in time, but all three arrive around the result.
        assert three_feedbacks.wait(5.0), f'{len(feedback)} of 3 feedback messages'
        assert [m.feedback.progress.iteration for m in feedback] == [1, 2, 3]
        assert all(m.feedback.progress.iterations == 3 for m in feedback)
    finally:
        executor.shutdown()
        spinner.join(timeout=5.0)
        server_node.destroy_node()
        client_node.destroy_node()


def test_grasp_message_carries_the_design_fields():
    """msg/Grasp.msg: the contract of DESIGN.md "Several ranked candidates", field by field."""
    from grasp_apso_interfaces.msg import Grasp

    assert Grasp.get_fields_and_field_types() == {
        'id': 'string',
        'grasp_posture': 'sensor_msgs/JointState',
        'pre_grasp_posture': 'sensor_msgs/JointState',
        'hand_trajectory': 'trajectory_msgs/JointTrajectory',  # DESIGN.md "Replies for any hand"
        'grasp_pose': 'geometry_msgs/PoseStamped',
        'pre_grasp_pose': 'geometry_msgs/PoseStamped',
        'approach_direction': 'geometry_msgs/Vector3Stamped',
        'approach_distance': 'double',
        'grasp_quality': 'double',
        'fitness': 'double',
        'epsilon_quality': 'double',
        'force_closure': 'boolean',
        'contact_points': 'sequence<geometry_msgs/Point>',
        'contact_normals': 'sequence<geometry_msgs/Vector3>',
        'contact_fingers': 'sequence<string>',
        'sim_result': 'int8',
        'sim_max_shift': 'double',
        'sim_max_turn': 'double',
    }
    assert Grasp().sim_result == Grasp.SIM_NOT_RUN == -1
    assert (Grasp.SIM_DROPPED, Grasp.SIM_HELD) == (0, 1)
