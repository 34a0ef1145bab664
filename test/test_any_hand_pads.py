"""A general hand's contacts are AT its pads (issue 21, "pads on the object's surface within
2 mm"): the pad point itself (``Finger.pad_center``, on the fingertip's surface) lies on the
object, not just some point of the pad sphere (a tilted fingertip touching with its side or
its very tip once passed).

Checked independently of the planner's kinematics: the URDF read again with yourdfpy, its
forward kinematics (mimic joints applied by yourdfpy) placing the pad points, trimesh's exact
proximity on the object mesh; joint limits from the URDF's own ``<limit>`` elements."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh
import yourdfpy

from grasp_apso.errors import PlanningError
from grasp_apso.model.builtin import builtin
from grasp_apso.model.hands.load import load_hand
from grasp_apso.model.scene import Scene
from grasp_apso.search.planner import PlanOptions, plan
from hand_files import write_allegro_like

PAD_TOLERANCE = 0.002  # m, the issue's
OPTIONS = PlanOptions(particles=30, iterations=15, max_grasps=3)


@pytest.fixture(scope="module", params=[False, True], ids=["independent", "coupled"])
def urdf(request, tmp_path_factory):
    return write_allegro_like(tmp_path_factory.mktemp("pads"), "mixed", coupled=request.param)


def _pad_distances(robot: yourdfpy.URDF, hand, cand, mesh: trimesh.Trimesh) -> dict[str, float]:
    """Each contacting finger's pad point -> its distance (m) to the object's surface."""
    robot.update_cfg(dict(zip(hand.actuated_joints, np.asarray(cand.joint_positions, float))))
    base_root = robot.get_transform(frame_to=hand.root_link, frame_from=robot.base_link)
    world_base = np.asarray(cand.wrist_pose, float) @ np.linalg.inv(base_root)
    out = {}
    for contact in cand.contacts:
        finger = hand.finger(contact.finger)
        link = world_base @ robot.get_transform(frame_to=finger.pad_link, frame_from=robot.base_link)
        point = link @ np.append(np.asarray(finger.pad_center, float), 1.0)
        _, distance, _ = trimesh.proximity.closest_point(mesh, point[None, :3])
        out[contact.finger] = float(distance[0])
    return out


def test_pad_points_touch_the_object_and_joints_stay_in_the_urdf_limits(urdf):
    hand = load_hand(urdf)
    robot = yourdfpy.URDF.load(str(urdf), load_meshes=False, load_collision_meshes=False,
                               build_collision_scene_graph=False)
    obj = builtin("cube")
    table = Scene.table_under(np.asarray(obj.mesh.vertices))
    checked = 0
    for seed in (0, 1):
        try:
            result = plan(obj, options=OPTIONS, rng=np.random.default_rng(seed), hand=hand, scene=table)
        except PlanningError:
            continue
        for cand in result.candidates:
            assert cand.n_contacts >= 2
            distances = _pad_distances(robot, hand, cand, obj.mesh)
            assert max(distances.values()) <= PAD_TOLERANCE, (seed, cand.rank, distances)
            values = dict(zip(hand.actuated_joints, cand.joint_positions))
            for name, joint in robot.joint_map.items():
                if joint.mimic is not None:
                    values[name] = joint.mimic.multiplier * values[joint.mimic.joint] + joint.mimic.offset
                if name in values and joint.limit is not None:
                    assert joint.limit.lower - 1e-6 <= values[name] <= joint.limit.upper + 1e-6, (name, values[name])
            checked += 1
    assert checked >= 2, "too few candidates to check"
