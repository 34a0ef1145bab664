"""A URDF hand through the node in its own process, its reply checked independently (issue 21).

``python -m grasp_apso.ros.node`` with ``hand_description`` the Allegro-like URDF (its distal
joints mimic the middle ones), a client here asking for the shipped mug resting on a table
(``mesh_uri``, a ``support_planes`` entry). Every grasp of the reply is read from the message
alone and checked without the planner's code: the URDF read with yourdfpy (its forward
kinematics, mimic joints applied by yourdfpy), its collision elements placed at the reply's
``grasp_pose`` (the root link) and ``grasp_posture``, python-fcl for the least distance to the
table, the URDF's own limits, each contact on its finger's fingertip. The scripted version
for any URDF: ``bench/unseen_hands_replies.py``.
"""
import os
import subprocess
import time

import fcl
import numpy as np
import pytest
import trimesh

rclpy = pytest.importorskip('rclpy')
yourdfpy = pytest.importorskip('yourdfpy')

from grasp_apso_interfaces.srv import PlanGrasp  # noqa: E402
from shape_msgs.msg import Plane  # noqa: E402

from hand_files import write_allegro_like  # noqa: E402
from node_helpers import PYTHON, REPO_ROOT, SpinningNode, identity_pose, ros_env, wait_future  # noqa: E402

from grasp_apso.model import poses  # noqa: E402

MESH_DIR = os.path.join(REPO_ROOT, 'grasp_apso', 'data', 'meshes')
PARAMS_FILE = os.path.join(REPO_ROOT, 'config', 'grasp_apso.yaml')
CLEARANCE = 0.005
#: Bounds (s): the node's start (the hand's covers are built on its first load) and the reply.
START_TIMEOUT = 240.0
CALL_TIMEOUT = 240.0


def _collision_elements(urdf, folder):
    """(link, origin (4, 4), trimesh) of every collision element of the URDF, as the file gives it."""
    out = []
    for name, link in urdf.link_map.items():
        for col in link.collisions:
            g = col.geometry
            if g.box is not None:
                mesh = trimesh.creation.box(extents=g.box.size)
            elif g.cylinder is not None:
                mesh = trimesh.creation.cylinder(radius=g.cylinder.radius, height=g.cylinder.length, sections=48)
            elif g.sphere is not None:
                mesh = trimesh.creation.icosphere(subdivisions=3, radius=g.sphere.radius)
            else:
                name_ = g.mesh.filename  # package://<package>/<path>: the package is the URDF's folder
                rest = name_.split('/', 3)[3] if name_.startswith('package://') else name_
                mesh = trimesh.load(os.path.join(folder, rest), force='mesh')
            out.append((name, np.eye(4) if col.origin is None else np.asarray(col.origin, float), mesh))
    return out


def _fcl(mesh, pose):
    bvh = fcl.BVHModel()
    bvh.beginModel(len(mesh.vertices), len(mesh.faces))
    bvh.addSubModel(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int32))
    bvh.endModel()
    return fcl.CollisionObject(bvh, fcl.Transform(pose[:3, :3], pose[:3, 3]))


@pytest.fixture(scope='module')
def reply(tmp_path_factory):
    folder = tmp_path_factory.mktemp('node_any_hand')
    urdf_path = write_allegro_like(folder, coupled=True)
    mug = trimesh.load(os.path.join(MESH_DIR, 'mug.stl'), force='mesh')
    low = float(mug.vertices[:, 2].min())
    log_path = folder / 'node.log'  # a file, not a pipe nobody reads while the node runs
    log = open(log_path, 'w')
    proc = subprocess.Popen(
        [PYTHON, '-m', 'grasp_apso.ros.node', '--ros-args', '--params-file', PARAMS_FILE,
         '-p', f'hand_description:={urdf_path}', '-p', f'allowed_mesh_dir:={MESH_DIR}'],
        cwd=REPO_ROOT, env=ros_env(), stdout=log, stderr=subprocess.STDOUT)
    context = rclpy.context.Context()
    rclpy.init(context=context)
    client_node = SpinningNode(context, 'grasp_apso_any_hand_process_client')
    client_node.start()
    try:
        client = client_node.node.create_client(PlanGrasp, '/grasp_apso/plan_grasp')
        deadline = time.monotonic() + START_TIMEOUT
        while not client.wait_for_service(timeout_sec=1.0):
            assert proc.poll() is None, log_path.read_text()
            assert time.monotonic() < deadline, 'no plan_grasp service'
        req = PlanGrasp.Request()
        req.mesh_uri = os.path.join(MESH_DIR, 'mug.stl')
        req.object_pose = identity_pose(frame='world')
        req.support_planes = [Plane(coef=[0.0, 0.0, 1.0, -low])]
        req.particles, req.iterations, req.seed, req.max_grasps, req.clearance = 30, 10, 3, 3, CLEARANCE
        res = wait_future(client.call_async(req), CALL_TIMEOUT, spinners=(client_node,))
        yield res, urdf_path, mug, low
    finally:
        client_node.close()
        rclpy.shutdown(context=context)
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=20.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=5.0)
        log.close()


def test_the_node_answers_a_urdf_hand_with_grasps_that_pass_independent_checks(reply):
    res, urdf_path, mug, low = reply
    assert res.success, res.message
    assert res.grasps
    urdf = yourdfpy.URDF.load(str(urdf_path), load_meshes=False, build_collision_scene_graph=False,
                              load_collision_meshes=False)
    own = [n for n in urdf.actuated_joint_names if urdf.joint_map[n].mimic is None]
    followers = [n for n, j in urdf.joint_map.items() if j.mimic is not None]
    assert followers  # the test hand couples its distal joints
    elements = _collision_elements(urdf, urdf_path.parent)
    table = fcl.CollisionObject(fcl.Box(4.0, 4.0, 0.2), fcl.Transform(np.eye(3), np.array([0.0, 0.0, low - 0.1])))
    for g in res.grasps:
        # the hand's own joints by name, no mimic follower among them
        names = list(g.grasp_posture.name)
        assert sorted(names) == sorted(own) and list(g.pre_grasp_posture.name) == names
        cfg = dict(zip(names, g.grasp_posture.position))
        values = dict(cfg)
        for name in followers:  # the URDF's mimic: follower = multiplier * leader + offset
            mimic = urdf.joint_map[name].mimic
            values[name] = mimic.multiplier * cfg[mimic.joint] + mimic.offset
        for name, value in values.items():  # the URDF's own limits, followers included
            limit = urdf.joint_map[name].limit
            assert limit.lower - 1e-6 <= value <= limit.upper + 1e-6, (g.id, name, value)
        urdf.update_cfg(cfg)
        p, o = g.grasp_pose.pose.position, g.grasp_pose.pose.orientation
        root = poses.pose_to_matrix([p.x, p.y, p.z], [o.x, o.y, o.z, o.w])
        base_root = urdf.get_transform(frame_to='palm', frame_from=urdf.base_link)
        world = root @ np.linalg.inv(base_root)
        placed = {}
        for link, origin, mesh in elements:
            pose = world @ urdf.get_transform(frame_to=link, frame_from=urdf.base_link) @ origin
            d = fcl.distance(_fcl(mesh, pose), table, fcl.DistanceRequest(), fcl.DistanceResult())
            assert d >= CLEARANCE - 5e-4, (g.id, link, d)
            placed.setdefault(link, []).append(mesh.copy().apply_transform(pose))
        assert len(g.contact_points) >= 2
        for finger, point in zip(g.contact_fingers, g.contact_points):
            tip = trimesh.util.concatenate(placed[f'{finger}_tip'] + placed[f'{finger}_distal'])
            gap = trimesh.proximity.closest_point(tip, np.array([[point.x, point.y, point.z]]))[1][0]
            assert gap <= 0.002, (g.id, finger, gap)
            # and the point lies on the mug's surface
            assert abs(trimesh.proximity.signed_distance(mug, np.array([[point.x, point.y, point.z]]))[0]) <= 0.002
