"""Planning in a scene (issue 11): support planes and obstacles the hand never comes
near, the pre-grasp and the approach, the object's placement, a scene without room.

The clearance is checked here with python-fcl on the whole hand built independently of
the planner (link capsules between the frames of ``HandModel.finger_frames``, pad spheres,
the palm box), never with the decoder's own distances.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import fcl
import numpy as np
import pytest

from grasp_apso.errors import PlanningError, SceneError
from grasp_apso.model.builtin import builtin
from grasp_apso.model.hand import load_hand
from grasp_apso.model.scene import BOX, Scene
from grasp_apso.search.planner import PlanOptions, plan

PINNED = json.loads((Path(__file__).parent / "data" / "pinned_plans.json").read_text())
#: The options the pinned plans were recorded with (the rest default).
PINNED_OPTIONS = {"particles": 30, "iterations": 15}
SMALL = {"particles": 20, "iterations": 12}
CLEARANCE = 0.005


def _hand_objects(hand, values: np.ndarray, wrist: np.ndarray) -> list[fcl.CollisionObject]:
    """The whole hand as fcl objects in the wrist's frame: palm box, 15 capsules, 5 pads."""
    frames = hand.finger_frames(np.asarray(values, dtype=float)[None, :15])[0]  # (5, 4, 4, 4) palm frame
    pts = frames[..., :3, 3] @ wrist[:3, :3].T + wrist[:3, 3]                 # (5, 4, 3)
    radii = [hand.link_radii[0], hand.link_radii[1], hand.link_radii[2]]
    out = []
    palm = np.eye(4)
    palm[:3, 3] = hand.palm_center
    palm = wrist @ palm
    out.append(fcl.CollisionObject(fcl.Box(*(2 * np.asarray(hand.palm_half_extents))),
                                   fcl.Transform(palm[:3, :3], palm[:3, 3])))
    for f in range(5):
        for link in range(3):
            a, b = pts[f, link], pts[f, link + 1]
            axis = b - a
            length = float(np.linalg.norm(axis))
            z = axis / length
            helper = np.array([1.0, 0, 0]) if abs(z[0]) < 0.9 else np.array([0, 1.0, 0])
            x = np.cross(helper, z)
            x /= np.linalg.norm(x)
            rot = np.stack([x, np.cross(z, x), z], axis=1)
            out.append(fcl.CollisionObject(fcl.Capsule(radii[link], length), fcl.Transform(rot, 0.5 * (a + b))))
        out.append(fcl.CollisionObject(fcl.Sphere(hand.pad_radius), fcl.Transform(np.eye(3), pts[f, 3])))
    return out


def _scene_objects(scene: Scene, near: np.ndarray) -> list[fcl.CollisionObject]:
    """Planes as 2 m x 2 m x 1 m boxes under the plane (centred below ``near``), boxes."""
    out = []
    for a, b, c, d in scene.planes:
        n = np.array([a, b, c])
        foot = near - (n @ near + d) * n
        z = n
        helper = np.array([1.0, 0, 0]) if abs(z[0]) < 0.9 else np.array([0, 1.0, 0])
        x = np.cross(helper, z)
        x /= np.linalg.norm(x)
        rot = np.stack([x, np.cross(z, x), z], axis=1)
        out.append(fcl.CollisionObject(fcl.Box(2.0, 2.0, 1.0), fcl.Transform(rot, foot - 0.5 * n)))
    for o in scene.obstacles:
        assert o.kind == BOX
        out.append(fcl.CollisionObject(fcl.Box(*o.dimensions), fcl.Transform(o.pose[:3, :3], o.pose[:3, 3])))
    return out


def _least_distance(hand, values, wrist, scene: Scene) -> float:
    best = np.inf
    for h in _hand_objects(hand, values, wrist):
        for s in _scene_objects(scene, wrist[:3, 3]):
            req = fcl.DistanceRequest(enable_signed_distance=True)
            best = min(best, fcl.distance(h, s, req, fcl.DistanceResult()))
    return best


def _assert_clear(result, scene: Scene, clearance: float = CLEARANCE) -> None:
    """Every candidate's grasp, pre-grasp and 3 poses between keep the clearance (fcl)."""
    hand = load_hand()
    assert result.candidates
    for c in result.candidates:
        assert c.valid
        at_grasp = _least_distance(hand, c.joint_positions, c.wrist_pose, scene)
        assert at_grasp >= clearance - 1e-6, (c.id, at_grasp)
        for t in (0.0, 0.33, 0.67, 1.0):
            pose = c.wrist_pose.copy()
            pose[:3, 3] -= t * c.approach_distance * c.approach
            d = _least_distance(hand, c.pre_grasp_positions, pose, scene)
            assert d >= clearance - 1e-6, (c.id, t, d)
        assert c.scene_distance >= clearance - 1e-9


def _pose(translation) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, 3] = translation
    return pose


@pytest.mark.parametrize("key", ["sphere/apso/0", "cube/pso/1"])
def test_scene_free_plan_unchanged(key):
    """No scene: the same best grasp as recorded before the scene and the candidates."""
    name, algorithm, seed = key.split("/")
    res = plan(builtin(name), options=PlanOptions(algorithm=algorithm, **PINNED_OPTIONS),
               rng=np.random.default_rng(int(seed)))
    pinned = PINNED[key]
    assert abs(res.fitness - pinned["fitness"]) <= 1e-9
    np.testing.assert_allclose(res.joint_positions, pinned["joints"], atol=1e-6)
    assert res.evaluations == pinned["evaluations"]
    # an empty scene is no scene
    again = plan(builtin(name), options=PlanOptions(algorithm=algorithm, **PINNED_OPTIONS),
                 rng=np.random.default_rng(int(seed)), scene=Scene())
    assert again.fitness == res.fitness


def test_table_every_candidate_above_the_table():
    """An object resting on a table in a rotated, shifted planning frame: every
    candidate's hand at the grasp, the pre-grasp and along the approach keeps the
    clearance from the table (python-fcl, whole hand)."""
    obj = builtin("cube")
    pose = _pose([0.3, -0.1, 0.75])
    pose[:3, :3] = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    vertices = obj.mesh.vertices @ pose[:3, :3].T + pose[:3, 3]
    table = Scene.table_under(vertices)
    res = plan(obj, pose, PlanOptions(max_grasps=3, **SMALL), rng=np.random.default_rng(1), scene=table)
    _assert_clear(res, table)
    # the approach comes from the free side: never from below the table top
    assert all(c.approach[2] <= 1e-9 for c in res.candidates)


def test_box_obstacle_beside_the_object_is_respected():
    obj = builtin("barrel")
    v = obj.mesh.vertices
    # a wall 1.5 cm beside the object, along its whole height
    wall = _pose([0.0, v[:, 1].max() + 0.015 + 0.01, 0.5 * (v[:, 2].min() + v[:, 2].max())])
    scene = Scene.from_primitives(obstacles=[(BOX, (0.3, 0.02, 0.3))], obstacle_poses=[wall])
    res = plan(obj, None, PlanOptions(max_grasps=3, **SMALL), rng=np.random.default_rng(2), scene=scene)
    _assert_clear(res, scene)


def test_pre_grasp_lies_approach_distance_back_along_the_approach():
    obj = builtin("fish")
    table = Scene.table_under(obj.mesh.vertices)
    res = plan(obj, None, PlanOptions(max_grasps=2, approach_distance=0.06, **SMALL),
               rng=np.random.default_rng(3), scene=table)
    for c in res.candidates:
        np.testing.assert_allclose(np.linalg.norm(c.approach), 1.0, atol=1e-12)
        np.testing.assert_allclose(c.approach, c.wrist_pose[:3, 2], atol=1e-12)
        np.testing.assert_allclose(c.pre_grasp_pose[:3, 3], c.wrist_pose[:3, 3] - 0.06 * c.approach, atol=1e-12)
        np.testing.assert_allclose(c.pre_grasp_pose[:3, :3], c.wrist_pose[:3, :3], atol=1e-12)
        assert c.approach_distance == 0.06
        # the pre-grasp posture is the open pre-shape: fingers no more flexed than at the grasp
        assert np.all(c.pre_grasp_positions[0:15:3] <= c.joint_positions[0:15:3] + 1e-12)


def test_boxed_in_object_fails_clearly_in_bounded_time():
    """Walls 5 mm around the cube on every side and a lid: no room for the hand."""
    obj = builtin("cube")
    v = obj.mesh.vertices
    lo, hi = v.min(axis=0) - 0.005, v.max(axis=0) + 0.005
    centre = 0.5 * (lo + hi)
    size = hi - lo
    t = 0.02
    boxes, poses = [], []
    for axis in range(3):
        for side in (-1, 1):
            dims = size + 2 * t
            dims[axis] = t
            c = centre.copy()
            c[axis] = (hi if side > 0 else lo)[axis] + side * t / 2
            boxes.append((BOX, tuple(dims)))
            poses.append(_pose(c))
    scene = Scene.from_primitives(obstacles=boxes, obstacle_poses=poses)
    for algorithm in ("apso", "pso"):
        t0 = time.perf_counter()
        with pytest.raises(PlanningError, match="no collision-free grasp") as err:
            plan(obj, None, PlanOptions(algorithm=algorithm, **SMALL), rng=np.random.default_rng(0), scene=scene)
        assert err.value.field == "scene"
        assert time.perf_counter() - t0 < 60.0


def test_object_sunk_into_the_table_is_refused():
    obj = builtin("cube")
    v = obj.mesh.vertices
    table = Scene.from_primitives(planes=[(0.0, 0.0, 1.0, -(v[:, 2].min() + 0.01))])  # 1 cm above its bottom
    with pytest.raises(SceneError, match="object_pose") as err:
        plan(obj, None, PlanOptions(**SMALL), rng=np.random.default_rng(0), scene=table)
    assert err.value.field == "object_pose"
    # resting on it (touching) is fine
    plan(obj, None, PlanOptions(max_grasps=1, **SMALL), rng=np.random.default_rng(0),
         scene=Scene.table_under(v))
