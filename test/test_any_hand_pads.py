"""A general hand's contacts are AT its pads (issue 21, "pads on the object's surface within
2 mm"): each contacting finger's pad -- the sphere of radius ``pad_radius`` whose surface
passes through the pad point ``Finger.pad_center`` with the fingertip's own surface normal
there -- lies within 2 mm of the object on its pad side (the half facing the pad normal: a
fingertip touching with its back or its very tip once passed), and the reported contact is
on that pad.

The pad link itself touches too: its collision geometry, placed by yourdfpy, within 2 mm of
the object by python-fcl's exact mesh distance (no pad point or pad radius involved; a pad
sphere wider than its fingertip once touched where the link was not).

Checked independently of the planner's kinematics: the URDF read again with yourdfpy, its
forward kinematics (mimic joints applied by yourdfpy) placing the pad points, trimesh's exact
proximity on the object mesh; joint limits from the URDF's own ``<limit>`` elements."""
from __future__ import annotations

import fcl
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


def _world_base(robot: yourdfpy.URDF, hand, cand) -> np.ndarray:
    """The URDF's base link in the planning frame (4, 4) with the robot posed at the
    candidate's joints (yourdfpy's forward kinematics), its root link at ``wrist_pose``."""
    robot.update_cfg(dict(zip(hand.actuated_joints, np.asarray(cand.joint_positions, float))))
    base_root = robot.get_transform(frame_to=hand.root_link, frame_from=robot.base_link)
    return np.asarray(cand.wrist_pose, float) @ np.linalg.inv(base_root)


def _pads(robot: yourdfpy.URDF, hand, cand, mesh: trimesh.Trimesh) -> dict[str, tuple[float, float, float]]:
    """Each contacting finger -> (pad gap m, cosine between its pad normal and the way to
    the object, distance m of the reported contact from the pad sphere's surface)."""
    world_base = _world_base(robot, hand, cand)
    out = {}
    for contact in cand.contacts:
        finger = hand.finger(contact.finger)
        tip = trimesh.util.concatenate([g.to_trimesh() for g in hand.collision[finger.pad_link]])
        _, _, face = trimesh.proximity.closest_point(tip, np.asarray(finger.pad_center, float)[None])
        normal_link = tip.face_normals[face[0]]
        link = world_base @ robot.get_transform(frame_to=finger.pad_link, frame_from=robot.base_link)
        point = link[:3, :3] @ np.asarray(finger.pad_center, float) + link[:3, 3]
        normal = link[:3, :3] @ normal_link
        center = point - finger.pad_radius * normal
        nearest, distance, _ = trimesh.proximity.closest_point(mesh, center[None])
        way = (nearest[0] - center) / max(float(distance[0]), 1e-12)
        inside = mesh.contains(center[None])[0]
        gap = (-distance[0] if inside else distance[0]) - finger.pad_radius
        reported = abs(np.linalg.norm(np.asarray(contact.position, float) - center) - finger.pad_radius)
        out[contact.finger] = (float(gap), float(way @ normal) * (-1.0 if inside else 1.0), float(reported))
    return out


def _bvh(mesh: trimesh.Trimesh) -> fcl.CollisionObject:
    model = fcl.BVHModel()
    model.beginModel(len(mesh.vertices), len(mesh.faces))
    model.addSubModel(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int32))
    model.endModel()
    return fcl.CollisionObject(model, fcl.Transform())


def _pad_link_gaps(robot: yourdfpy.URDF, hand, cand, obj_fcl) -> dict[str, float]:
    """Each contacting finger -> python-fcl distance (m, 0 when touching) from its pad
    link's collision geometry (placed by yourdfpy) to the object."""
    world_base = _world_base(robot, hand, cand)
    out = {}
    for contact in cand.contacts:
        finger = hand.finger(contact.finger)
        tip = trimesh.util.concatenate([g.to_trimesh() for g in hand.collision[finger.pad_link]])
        tip.apply_transform(world_base @ robot.get_transform(frame_to=finger.pad_link, frame_from=robot.base_link))
        link = _bvh(tip)
        touching = fcl.collide(link, obj_fcl, fcl.CollisionRequest(), fcl.CollisionResult())
        out[contact.finger] = 0.0 if touching else float(
            fcl.distance(link, obj_fcl, fcl.DistanceRequest(), fcl.DistanceResult()))
    return out


def test_pads_touch_the_object_and_joints_stay_in_the_urdf_limits(urdf):
    hand = load_hand(urdf)
    robot = yourdfpy.URDF.load(str(urdf), load_meshes=False, load_collision_meshes=False,
                               build_collision_scene_graph=False)
    obj = builtin("cube")
    obj_fcl = _bvh(obj.mesh)
    table = Scene.table_under(np.asarray(obj.mesh.vertices))
    checked = 0
    for seed in (0, 1):
        try:
            result = plan(obj, options=OPTIONS, rng=np.random.default_rng(seed), hand=hand, scene=table)
        except PlanningError:
            continue
        for cand in result.candidates:
            assert cand.n_contacts >= 2
            pads = _pads(robot, hand, cand, obj.mesh)
            for finger, (gap, facing, reported) in pads.items():
                assert abs(gap) <= PAD_TOLERANCE, (seed, cand.rank, finger, pads)
                assert facing >= -0.05, (seed, cand.rank, finger, pads)  # the pad side, not the back
                assert reported <= PAD_TOLERANCE, (seed, cand.rank, finger, pads)
            links = _pad_link_gaps(robot, hand, cand, obj_fcl)
            assert max(links.values()) <= PAD_TOLERANCE, (seed, cand.rank, links)
            values = dict(zip(hand.actuated_joints, cand.joint_positions))
            for name, joint in robot.joint_map.items():
                if joint.mimic is not None:
                    values[name] = joint.mimic.multiplier * values[joint.mimic.joint] + joint.mimic.offset
                if name in values and joint.limit is not None:
                    assert joint.limit.lower - 1e-6 <= values[name] <= joint.limit.upper + 1e-6, (name, values[name])
            checked += 1
    assert checked >= 2, "too few candidates to check"


def test_a_fingertip_touching_with_its_back_or_side_is_told_apart(urdf):
    """The decoder's pad side (``_pad_facing``): a pad sphere touching the cube's +x face,
    its pad normal turned 0, 80, 100 and 180 degrees from the face's inward normal, reads
    the cosine of that angle; only the first two are pad contacts (``PAD_CONE``: the half
    facing the pad normal)."""
    from grasp_apso.geometry import any_hand_decoder as decoder

    obj = builtin("cube")
    model = decoder.make_any_hand_model(load_hand(urdf), obj)
    half = float(obj.mesh.bounds[1, 0])
    r = 0.01
    angles = np.radians([0.0, 80.0, 100.0, 180.0])
    centers = np.tile([half + r, 0.0, 0.0], (1, len(angles), 1))     # (1, 4, 3): touching the +x face
    normals = np.stack([-np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
    facing = decoder._pad_facing(model, centers + r * normals[None], centers)[0]
    assert facing == pytest.approx(np.cos(angles), abs=0.03)
    assert list(facing >= decoder._COS_CONE) == [True, True, False, False]
