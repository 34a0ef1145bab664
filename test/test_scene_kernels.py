"""The decoder's compiled scene checks (grasp_apso.geometry.scene_kernels) against
independent references: closed-form distances written here in numpy, sampled densely,
and python-fcl on the whole hand (grasp_apso.geometry.hand_fcl builds its parts from
``HandModel.finger_frames`` with fcl primitives, not from the decoder's link spheres).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from grasp_apso.geometry import convex_distance, decoder, hand_fcl, scene_kernels
from grasp_apso.model.builtin import builtin
from grasp_apso.model.scene import BOX, CYLINDER, SPHERE, Scene
from grasp_apso.search.grg import PreshapeRanges, classify_shape, sample_particles
from grasp_apso.search.planner import prepare

CLEARANCE = 0.005
APPROACH = 0.08


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def _random_obstacle(rng: np.random.Generator) -> tuple:
    """A random pose and size: rotation (3, 3), centre (3,), world -> local (4, 4), box
    half sizes (3,), cylinder radius and half height (m)."""
    rot = _random_rotation(rng)
    centre = rng.uniform(-0.05, 0.05, 3)
    inv = np.eye(4)
    inv[:3, :3] = rot.T
    inv[:3, 3] = -rot.T @ centre
    half = rng.uniform(0.005, 0.08, 3)
    return rot, centre, inv, half, float(rng.uniform(0.005, 0.05)), float(rng.uniform(0.005, 0.08))


def _box_sdf(local: np.ndarray, half: np.ndarray) -> np.ndarray:
    q = np.abs(local) - half
    return np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(axis=-1), 0.0)


def _cylinder_sdf(local: np.ndarray, radius: float, half_height: float) -> np.ndarray:
    q = np.stack([np.linalg.norm(local[..., :2], axis=-1) - radius, np.abs(local[..., 2]) - half_height], -1)
    return np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(axis=-1), 0.0)


@pytest.mark.parametrize("is_box", [True, False])
def test_convex_path_least_is_a_tight_lower_bound_of_the_sampled_least(is_box):
    """The least distance along a straight path to a box or a cylinder: never above the
    least of 20,001 samples, and within the tolerance plus the sampling error of it."""
    rng = np.random.default_rng(5)
    worst_over, worst_under = -np.inf, -np.inf
    for _ in range(300):
        rot, centre, inv, half, radius, half_height = _random_obstacle(rng)
        q = rng.uniform(-0.15, 0.15, 3)
        d = rng.normal(size=3)
        d *= rng.uniform(0.01, 0.12) / np.linalg.norm(d)
        w = rot.T @ d
        got = convex_distance.convex_path_least(
            is_box, inv, half[0], half[1], half[2], radius, half_height, q[0], q[1], q[2],
            d[0], d[1], d[2], w[0], w[1], w[2], np.inf)
        path = q + np.linspace(0.0, 1.0, 20001)[:, None] * d
        local = (path - centre) @ rot
        sampled = (_box_sdf(local, half) if is_box else _cylinder_sdf(local, radius, half_height)).min()
        worst_over = max(worst_over, got - sampled)
        worst_under = max(worst_under, sampled - got)
    assert worst_over <= 1e-9  # a lower bound (the samples lie on the path)
    assert worst_under <= convex_distance.CONVEX_TOLERANCE + 1e-5  # and a tight one


def test_convex_path_least_stops_once_the_least_is_known_to_exceed_stop():
    inv = np.eye(4)
    half = np.array([0.01, 0.01, 0.01])
    # a path passing 5 cm from the box: asked only whether it comes within 1 cm
    got = convex_distance.convex_path_least(True, inv, *half, 0.0, 0.0, -0.1, 0.06, 0.0, 0.2, 0.0, 0.0,
                                           0.2, 0.0, 0.0, 0.01)
    assert got >= 0.01
    exact = convex_distance.convex_path_least(True, inv, *half, 0.0, 0.0, -0.1, 0.06, 0.0, 0.2, 0.0, 0.0,
                                             0.2, 0.0, 0.0, np.inf)
    assert exact == pytest.approx(0.05, abs=convex_distance.CONVEX_TOLERANCE)


def test_object_distance_for_tracing_never_over_estimates_far_away():
    """Outside the grid's box the grid's own extension over-estimates the distance; the
    approach tracing's distance stays below the exact one (trimesh) everywhere."""
    obj = builtin("fish")
    model = prepare(obj)
    sdf = model.sdf
    rng = np.random.default_rng(2)
    lo, hi = model.object_box
    points = rng.uniform(lo - 0.12, hi + 0.12, (800, 3))
    exact = np.linalg.norm(points - obj.mesh.nearest.on_surface(points)[0], axis=1)
    inside = obj.mesh.contains(points)
    below = np.array([scene_kernels._object_distance_below(
        sdf._values64, *sdf._origin64, 1.0 / sdf.spacing, float(sdf.spacing), lo, hi, *p) for p in points])
    outside = ~inside
    # the grid is exact to about a spacing (its far nodes come from a distance transform)
    assert np.all(below[outside] <= exact[outside] + 1.5 * sdf.spacing)
    assert np.all(below[inside] <= 1.5 * sdf.spacing)
    # and not needlessly low: within a few millimetres inside the grid's box
    in_box = np.all((points >= sdf._origin64) & (points <= sdf._origin64 + sdf.spacing * (np.array(sdf.shape) - 1)),
                    axis=1)
    assert np.median(np.abs(below - exact)[outside & in_box]) < 0.002


def _scene(with_ball: bool = True) -> Scene:
    """A tilted table, a wall, a post and (``with_ball``) a ball around the built-in fish
    (object frame)."""
    v = np.asarray(builtin("fish").mesh.vertices)
    tilt = np.array([0.08, 0.0, 1.0]) / np.linalg.norm([0.08, 0.0, 1.0])
    wall, post, ball = np.eye(4), np.eye(4), np.eye(4)
    wall[:3, 3] = [0.0, v[:, 1].max() + 0.05, 0.0]
    post[:3, :3] = _random_rotation(np.random.default_rng(1))
    post[:3, 3] = [v[:, 0].max() + 0.04, 0.0, 0.02]
    ball[:3, 3] = [v[:, 0].min() - 0.05, -0.03, 0.03]
    return Scene.from_primitives(
        planes=[(*tilt, -(v @ tilt).min())],
        obstacles=[(BOX, (0.3, 0.02, 0.12)), (CYLINDER, (0.12, 0.015)), (SPHERE, (0.02,))][:3 if with_ball else 2],
        obstacle_poses=[wall, post, ball][:3 if with_ball else 2],
    )


@pytest.fixture(scope="module", params=[True, False], ids=["with_ball", "boxes_only"])
def decoded_in_a_scene(request):
    """Without a ball the path check screens capsules by slabs first; with one it does not."""
    obj = builtin("fish")
    scene = _scene(request.param)
    model = decoder.with_scene(prepare(obj), scene, CLEARANCE, APPROACH)
    # class-guided particles from the table's free side, without GRG's screening of the
    # palm against the scene: many meet the scene, many do not
    shape = classify_shape(obj).with_support(scene.planes[:, :3])
    x = sample_particles(prepare(obj), shape, 400, np.random.default_rng(7), PreshapeRanges())
    x = np.clip(x, model.lower, model.upper)
    return model, scene, x, decoder.decode(model, x)


def test_scene_legal_particles_keep_the_clearance_by_python_fcl(decoded_in_a_scene):
    """Every particle the decoder finds clear of the scene (fingers and palm, at the grasp
    and along the approach) keeps the clearance by python-fcl on the whole hand."""
    model, scene, x, d = decoded_in_a_scene
    clear = (d.scene_margin >= 0).all(axis=1) & (d.palm_scene_margin >= 0)
    assert 40 <= clear.sum() <= len(x) - 40  # the scene decides for a good share both ways
    hand = model.hand
    for i in np.flatnonzero(clear):
        grasp = hand_fcl.hand_scene_distance(hand, d.closed[i], d.wrist[i], scene)
        way_in = hand_fcl.approach_report(hand, x[i], d.wrist[i], APPROACH, scene, None, None, CLEARANCE, step=0.001)
        assert grasp >= CLEARANCE - 1e-9, i
        assert way_in.min_scene_distance >= CLEARANCE - 1e-9, i


def test_scene_margins_are_not_needlessly_conservative(decoded_in_a_scene):
    """Most particles python-fcl finds 3 mm beyond the clearance the decoder finds clear."""
    model, scene, x, d = decoded_in_a_scene
    clear = (d.scene_margin >= 0).all(axis=1) & (d.palm_scene_margin >= 0)
    hand = model.hand
    roomy = []
    for i in range(len(x)):
        grasp = hand_fcl.hand_scene_distance(hand, d.closed[i], d.wrist[i], scene)
        way_in = hand_fcl.approach_report(hand, x[i], d.wrist[i], APPROACH, scene, None, None, CLEARANCE)
        if min(grasp, way_in.min_scene_distance) >= CLEARANCE + 0.003:
            roomy.append(i)
    assert len(roomy) >= 20
    assert clear[roomy].mean() >= 0.9


def test_the_scene_changes_only_the_fingers_it_makes_illegal(decoded_in_a_scene):
    """Fingers clear of the scene close exactly as in free space; the others (some not
    closed at all: their open hand meets the scene on the way in) are illegal."""
    model, scene, x, d = decoded_in_a_scene
    free = decoder.decode(prepare(builtin("fish")), x)
    clear = d.scene_margin >= 0
    assert clear.mean() > 0.3 and (~clear).sum() > 50
    for name in ("contact", "tip_gap", "penetration", "blocked", "link_contact"):
        assert np.array_equal(getattr(d, name)[clear], getattr(free, name)[clear]), name
    flex = np.r_[0:15].reshape(5, 3)[:, :2]
    assert np.array_equal(d.closed[:, flex][clear], free.closed[:, flex][clear])
    changed = (d.closed[:, flex] != free.closed[:, flex]).any(axis=-1)
    assert changed.any() and np.all(~clear[changed])
    assert not d.legal(model.settings.max_penetration)[(~clear).any(axis=1)].any()


def test_approach_past_the_object_is_traced_only_for_otherwise_valid_particles(decoded_in_a_scene):
    model, scene, x, d = decoded_in_a_scene
    ready = d.n_contacts >= 2
    traced = d.approach_traced.any(axis=1)
    assert traced.any()
    assert np.all(ready[traced])
    assert np.all(d.approach_traced[traced])  # every finger of a traced particle


@pytest.mark.parametrize("is_box", [True, False])
def test_slab_bound_never_exceeds_the_least_along_the_path(is_box):
    rng = np.random.default_rng(8)
    for _ in range(300):
        rot, centre, inv, half, radius, half_height = _random_obstacle(rng)
        q = rng.uniform(-0.15, 0.15, 3)
        d = rng.normal(size=3) * 0.05
        w = rot.T @ d
        bound = convex_distance.path_slab_bound(is_box, inv, *half, radius, half_height, *q, *w)
        local = (q + np.linspace(0.0, 1.0, 5001)[:, None] * d - centre) @ rot
        sampled = (_box_sdf(local, half) if is_box else _cylinder_sdf(local, radius, half_height)).min()
        assert bound <= sampled + 1e-9


def test_slab_gap_bounds_a_swept_segment_from_below():
    """The slab bound of a parallelogram (a link swept along the approach) never exceeds
    the least distance of its densely sampled points to the box."""
    rng = np.random.default_rng(9)
    ends = np.empty((4, 3))
    for _ in range(200):
        rot, centre, inv, half, _, _ = _random_obstacle(rng)
        a, e, w = rng.uniform(-0.15, 0.15, 3), rng.normal(size=3) * 0.03, rng.normal(size=3) * 0.05
        ends[:] = [a, a + w, a + e, a + e + w]
        bound = scene_kernels._slab_gap(inv, *half, ends, 4, True)
        s, t = np.meshgrid(np.linspace(0, 1, 81), np.linspace(0, 1, 81))
        pts = a + s.reshape(-1, 1) * e + t.reshape(-1, 1) * w
        assert bound <= _box_sdf((pts - centre) @ rot, half).min() + 1e-9
