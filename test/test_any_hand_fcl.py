"""python-fcl checks of any hand (grasp_apso.geometry.any_hand_fcl), judged independently.

The judges never call the code under test nor python-fcl: each link's exact geometry as a
fine trimesh surface (``LinkGeometry.to_trimesh``, curved surfaces inside the true ones by
at most 0.12 % of their radius) placed by ``hand.link_transforms``, measured with trimesh's
closest points, or closed forms (a sphere object or obstacle: the distance of its centre to
a link minus its radius; a wide box or a plane: the lowest vertex of every link).
Hands: the Shadow hand (MJCF, capsules, boxes, a forearm mesh) and the Allegro-like URDF
(boxes, cylinders, spheres and STL meshes; and a version with every link a mesh).
"""

from __future__ import annotations

import math
import threading

import fcl
import numpy as np
import pytest
import trimesh

from grasp_apso.errors import InputError
from grasp_apso.geometry.any_hand_fcl import (DEPTH_SLACK, TOUCH_TOLERANCE, HandCollision, approach_report, object_report,
                                             scene_distance)
from grasp_apso.model.hands.load import load_hand
from grasp_apso.model.scene import BOX, SPHERE, Scene
from hand_files import installed_hand, write_allegro_like

RADIUS = 0.03  # the sphere object / obstacle, m
#: The judge's surfaces are tessellated: inside the true ones by <= 0.12 % of a radius
#: (15 um for the 12 mm Allegro tips); the reported depths come from samples 1.5 mm apart.
TOL = 2.5e-4


@pytest.fixture(scope="module")
def hands(tmp_path_factory):
    folder = tmp_path_factory.mktemp("hands")
    return {
        "shadow": load_hand(installed_hand("shadow"), spheres=False),
        "allegro": load_hand(write_allegro_like(folder / "a", "mixed"), spheres=False),
        "allegro_meshes": load_hand(write_allegro_like(folder / "b", "all"), spheres=False),
    }


def _rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _link_meshes(hand, q, root) -> dict[str, trimesh.Trimesh]:
    """The judge's surfaces: every link's collision geometry, one mesh per link, placed."""
    return {link: trimesh.util.concatenate(parts) if len(parts) > 1 else parts[0]
            for link, parts in _link_parts(hand, q, root).items()}


def _sphere_judge(meshes: dict, centre: np.ndarray, radius: float) -> dict[str, float]:
    """Distance of a sphere (centre, radius) to each link: |centre - link| - radius; links
    that hold the centre are left out (no closed form)."""
    out = {}
    for link, mesh in meshes.items():
        sd = trimesh.proximity.signed_distance(mesh, centre[None])[0]  # trimesh: > 0 inside
        if sd < 0:
            out[link] = -sd - radius
    return out


def _random_q(hand, rng):
    return rng.uniform(hand.lower, hand.upper)


@pytest.mark.parametrize("name", ["shadow", "allegro", "allegro_meshes"])
def test_link_distances_to_a_sphere_object_match_the_closed_form(hands, name):
    """Per link signed distance (gap and penetration) against a sphere object, at seeded
    random postures and poses, the sphere put near a random link at a gap of +8, +1.5, -1.5
    and -4 mm."""
    hand = hands[name]
    hc = HandCollision(hand)
    ball = trimesh.creation.icosphere(subdivisions=5, radius=RADIUS)
    rng = np.random.default_rng(7)
    checked = penetrating = 0
    for trial in range(4):
        q = _random_q(hand, rng)
        root = np.eye(4)
        root[:3, :3] = _rotation(rng)
        root[:3, 3] = rng.uniform(-0.05, 0.05, 3)
        meshes = _link_meshes(hand, q, root)
        link = list(meshes)[rng.integers(len(meshes))]
        mesh = meshes[link]
        v = int(rng.integers(len(mesh.vertices)))
        for gap in (0.008, 0.0015, -0.0015, -0.004):
            centre = mesh.vertices[v] + mesh.vertex_normals[v] * (RADIUS + gap)
            judge = _sphere_judge(meshes, centre, RADIUS)
            in_object = root.copy()
            in_object[:3, 3] -= centre  # the object frame: the sphere's centre
            report = object_report(hc, q, in_object, ball)
            for lk, expected in judge.items():
                got = report.distance_of(lk)
                if expected < -0.005:  # deep: the samples' depth, short by their spacing at most
                    assert expected - TOL <= got <= expected + 0.002, (name, trial, gap, lk)
                else:  # exact within 1 cm; GJK on the convex object beyond
                    assert got == pytest.approx(expected, abs=TOL if expected < 0.01 else 1e-3), (name, trial, gap, lk)
                checked += 1
                penetrating += expected < -0.001
            holders = [lk for lk in report.links if lk not in judge]  # links that hold the centre
            assert all(report.distance_of(lk) < -0.001 for lk in holders)
            if not holders and min(judge.values()) > -0.005:
                assert report.deepest_penetration == pytest.approx(max(0.0, -min(judge.values())), abs=TOL)
            assert set(np.array(report.links)[report.touching]) == {lk for lk, d in judge.items() if d <= 0.001} | \
                {lk for lk in report.links if lk not in judge}
    assert checked > 100 and penetrating >= 4


@pytest.mark.parametrize("name", ["shadow", "allegro"])
def test_a_hand_into_a_box_object_penetrates_and_one_a_centimetre_above_reports_a_centimetre(hands, name):
    hand = hands[name]
    hc = HandCollision(hand)
    rng = np.random.default_rng(3)
    q = _random_q(hand, rng)
    root = np.eye(4)
    root[:3, :3] = _rotation(rng)
    meshes = _link_meshes(hand, q, root)
    lowest = {lk: float(m.vertices[:, 2].min()) for lk, m in meshes.items()}
    box = trimesh.creation.box(extents=(2.0, 2.0, 0.4))  # top face at z = 0.2, far wider than the hand
    for gap in (0.01, -0.005):
        shift = 0.2 + gap - min(lowest.values())
        placed = root.copy()
        placed[2, 3] += shift
        report = object_report(hc, q, placed, box)
        for lk, z in lowest.items():
            assert report.distance_of(lk) == pytest.approx(z + shift - 0.2, abs=TOL), (gap, lk)
        assert report.deepest_penetration == pytest.approx(max(0.0, -gap), abs=TOL)
        assert report.legal is (gap > 0) or report.link_pairs_colliding
    # wholly inside a large box: every link penetrates (fcl alone sees no contact there)
    inside = root.copy()
    inside[:3, 3] = 0.0
    report = object_report(hc, q, inside, trimesh.creation.box(extents=(1.5, 1.5, 1.5)))
    assert np.all(report.link_distance < -0.3) and not report.legal


@pytest.mark.parametrize("name", ["shadow", "allegro"])
def test_a_link_is_legal_only_the_samples_slack_inside_the_tolerance(hands, name):
    """A link's depth is read at samples of its surface, which a denser check can find
    deeper (DEPTH_SLACK): a hand 0.95 mm into the object is within the 1 mm tolerance but
    not legal, 0.85 mm in it is (the open hand, its fingers apart)."""
    hand = hands[name]
    hc = HandCollision(hand)
    rng = np.random.default_rng(3)
    q = hand.open_configuration()
    root = np.eye(4)
    root[:3, :3] = _rotation(rng)
    lowest = min(float(m.vertices[:, 2].min()) for m in _link_meshes(hand, q, root).values())
    box = trimesh.creation.box(extents=(2.0, 2.0, 0.4))
    for depth, legal in ((0.00085, True), (0.00095, False)):
        placed = root.copy()
        placed[2, 3] += 0.2 - depth - lowest
        report = object_report(hc, q, placed, box)
        assert report.deepest_penetration == pytest.approx(depth, abs=2e-5)
        assert report.max_depth == pytest.approx(TOUCH_TOLERANCE - DEPTH_SLACK)
        assert not report.link_pairs_colliding
        assert report.legal is legal, (depth, report.deepest_penetration)


@pytest.mark.parametrize("name", ["shadow", "allegro_meshes"])
def test_table_clearance_matches_the_lowest_vertex(hands, name):
    hand = hands[name]
    hc = HandCollision(hand)
    rng = np.random.default_rng(11)
    for trial in range(5):
        q = _random_q(hand, rng)
        root = np.eye(4)
        root[:3, :3] = _rotation(rng)
        root[:3, 3] = rng.uniform(-0.1, 0.1, 3)
        normal = np.array([0.2, -0.1, 1.0]) / np.linalg.norm([0.2, -0.1, 1.0])
        d = -0.03 if trial % 2 else 0.02  # the hand partly below and wholly above the plane
        judge = min(float((m.vertices @ normal + d).min()) for m in _link_meshes(hand, q, root).values())
        scene = Scene.from_primitives(planes=[(*normal, d)])
        assert scene_distance(hc, q, root, scene) == pytest.approx(judge, abs=TOL)


def test_obstacles_sphere_and_box_match_the_closed_forms(hands):
    hand = hands["shadow"]
    hc = HandCollision(hand)
    rng = np.random.default_rng(5)
    q = _random_q(hand, rng)
    root = np.eye(4)
    root[:3, :3] = _rotation(rng)
    meshes = _link_meshes(hand, q, root)
    tip = meshes["robot0:ffdistal"]
    v = int(np.argmax(tip.vertices[:, 0]))
    for gap in (0.006, -0.002):
        centre = tip.vertices[v] + tip.vertex_normals[v] * (RADIUS + gap)
        pose = np.eye(4)
        pose[:3, 3] = centre
        scene = Scene.from_primitives(obstacles=[(SPHERE, (RADIUS,))], obstacle_poses=[pose])
        judge = _sphere_judge(meshes, centre, RADIUS)
        if len(judge) == len(meshes):
            assert scene_distance(hc, q, root, scene) == pytest.approx(min(judge.values()), abs=TOL)
        else:  # a link holds the centre: deeper than the radius
            assert scene_distance(hc, q, root, scene) <= -RADIUS + TOL
    lowest = min(float(m.vertices[:, 2].min()) for m in meshes.values())
    for gap in (0.015, -0.003):
        pose = np.eye(4)
        pose[2, 3] = lowest - gap - 0.1  # a 2 m wide, 0.2 m tall box under the hand
        scene = Scene.from_primitives(obstacles=[(BOX, (2.0, 2.0, 0.2))], obstacle_poses=[pose])
        assert scene_distance(hc, q, root, scene) == pytest.approx(gap, abs=TOL)
    assert scene_distance(hc, q, root, Scene()) == np.inf


def _swept_sphere_judge(meshes: dict, centre: np.ndarray, radius: float, approach: np.ndarray,
                        retreats: np.ndarray) -> float:
    """Least distance of a fixed sphere to the hand moved back by each retreat along
    ``approach`` (the hand at grasp - s * approach): the sphere at centre + s * approach."""
    points = centre + retreats[:, None] * approach
    best = np.inf
    for mesh in meshes.values():
        sd = trimesh.proximity.signed_distance(mesh, points)
        best = min(best, float((-sd).min()) - radius)
    return best


def test_the_approach_finds_an_obstacle_in_its_path_and_measures_one_beside_it(hands):
    hand = hands["allegro"]
    hc = HandCollision(hand)
    q = hand.open_configuration()
    root = np.eye(4)
    approach = hand.palm_normal / np.linalg.norm(hand.palm_normal)
    meshes = _link_meshes(hand, q, root)
    front = max(float((m.vertices @ approach).max()) for m in meshes.values())
    distance, step = 0.08, 0.005
    retreats = distance * np.arange(17) / 16
    # an obstacle 4 cm before the grasp, in front of the palm, in the path
    side = np.cross(approach, [1.0, 0.0, 0.0] if abs(approach[0]) < 0.9 else [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    for offset, expect_clear in ((0.0, False), (0.3, True)):
        centre = approach * (front - 0.04 + RADIUS) + side * offset
        pose = np.eye(4)
        pose[:3, 3] = centre
        scene = Scene.from_primitives(obstacles=[(SPHERE, (RADIUS,))], obstacle_poses=[pose])
        report = approach_report(hc, q, root, approach, distance, scene, step=step, clearance=0.005)
        judge = _swept_sphere_judge(meshes, centre, RADIUS, approach, retreats)
        assert report.steps == 17
        assert report.min_scene_distance == pytest.approx(judge, abs=TOL)
        assert report.clear is expect_clear and report.hits_object is False


def test_the_approach_finds_the_object_in_the_path_but_not_at_the_grasp(hands):
    hand = hands["shadow"]
    hc = HandCollision(hand)
    q = hand.open_configuration()
    root = np.eye(4)
    approach = hand.palm_normal / np.linalg.norm(hand.palm_normal)
    meshes = _link_meshes(hand, q, root)
    tip = max(meshes.values(), key=lambda m: float((m.vertices @ approach).max()))
    front = tip.vertices[int(np.argmax(tip.vertices @ approach))]  # the most advanced point of the hand
    ball = trimesh.creation.icosphere(subdivisions=4, radius=RADIUS)
    retreats = 0.08 * np.arange(17) / 16
    # 1 cm in front of it at the grasp: never touched
    obj_pose = np.eye(4)
    obj_pose[:3, 3] = front + approach * (0.01 + RADIUS)
    report = approach_report(hc, q, root, approach, 0.08, Scene(), ball, obj_pose)
    assert not report.hits_object and report.clear
    assert report.min_object_distance == pytest.approx(
        _swept_sphere_judge(meshes, obj_pose[:3, 3], RADIUS, approach, retreats), abs=5e-4)
    # the same object 3 cm closer: the hand runs into it 1 to 2 cm before the grasp
    obj_pose[:3, 3] -= 0.03 * approach
    report = approach_report(hc, q, root, approach, 0.08, Scene(), ball, obj_pose)
    assert report.hits_object and not report.clear and 0.01 < report.hit_at <= 0.02 + 1e-9
    assert report.hit_link in hc.links


@pytest.mark.parametrize("name", ["allegro_meshes", "shadow"])
def test_the_deciding_approach_check_agrees_with_the_full_one(hands, name):
    """``decide_only`` (the selection's pre-grasp choice) leaves distances at hull lower
    bounds and stops at the first hit: ``clear`` must agree with the full check; when
    clear its object distance must not exceed the full one; a hit must lie within the
    full one's stretch. A non-convex object (a torus) at seeded poses about the hand's front, some
    clear, some in the way."""
    hand = hands[name]
    hc = HandCollision(hand)
    rng = np.random.default_rng(5)
    approach = hand.palm_normal / np.linalg.norm(hand.palm_normal)
    ring = trimesh.creation.torus(major_radius=0.035, minor_radius=0.012)
    q0 = hand.open_configuration()
    front = max(float((m.vertices @ approach).max()) for m in _link_meshes(hand, q0, np.eye(4)).values())
    outcomes = set()
    for _ in range(8):
        q = _random_q(hand, rng) * 0.3 + q0 * 0.7
        pose = np.eye(4)
        pose[:3, :3] = _rotation(rng)
        pose[:3, 3] = approach * (front + rng.uniform(-0.03, 0.03)) + rng.uniform(-0.03, 0.03, 3)
        full = approach_report(hc, q, np.eye(4), approach, 0.06, Scene(), ring, pose)
        quick = approach_report(hc, q, np.eye(4), approach, 0.06, Scene(), ring, pose, decide_only=True)
        assert quick.clear is full.clear and quick.hits_object is full.hits_object
        if full.hits_object:  # stopped at its first hit: the steps beyond are not visited
            assert quick.hit_at <= full.hit_at + 1e-9 and quick.hit_link in hc.links
        else:  # every step visited: a lower bound of the least distance
            assert quick.min_object_distance <= full.min_object_distance + 1e-9
        outcomes.add(full.clear)
    assert outcomes == {True, False}  # both kinds were met


def _capsule_judge(hand, q) -> dict[tuple[str, str], float]:
    """Closed form for the Shadow hand's finger links (each one capsule): per link pair of
    different fingers, the least distance between their axes (points 0.2 mm apart) minus
    the radii."""
    poses = hand.link_transforms(q)
    axes = {}
    for finger in hand.fingers:
        for link in hand.finger_links(finger):
            geoms = hand.collision.get(link, ())
            if len(geoms) == 1 and geoms[0].kind == "capsule":
                radius, half = geoms[0].size
                t = np.linspace(-half, half, max(2, int(2 * half / 2e-4) + 1))
                local = np.column_stack([np.zeros((len(t), 2)), t, np.ones(len(t))])
                axes[link] = (finger.name, (poses[link] @ geoms[0].origin @ local.T).T[:, :3], radius)
    out = {}
    links = list(axes)
    for i, a in enumerate(links):
        for b in links[i + 1:]:
            if axes[a][0] != axes[b][0]:
                gap = np.linalg.norm(axes[a][1][:, None] - axes[b][1][None], axis=2).min()
                out[(a, b)] = float(gap - axes[a][2] - axes[b][2])
    return out


def test_finger_collisions_match_the_capsule_closed_form(hands):
    hand = hands["shadow"]
    hc = HandCollision(hand)
    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.01)
    far = np.eye(4)
    far[:3, 3] = [1.0, 0.0, 0.0]  # the object far away
    assert object_report(hc, hand.open_configuration(), far, ball).link_pairs_colliding == ()
    rng = np.random.default_rng(9)
    postures = [hand.closed_configuration(1.0)] + [_random_q(hand, rng) for _ in range(6)]
    colliding = 0
    for q in postures:
        report = object_report(hc, q, far, ball, allowed_overlap=0.002)
        found = {frozenset(p) for p in report.link_pairs_colliding}
        for (a, b), gap in _capsule_judge(hand, q).items():
            if gap < -0.0025:
                assert frozenset((a, b)) in found, (a, b, gap)
                fa = next(f.name for f in hand.fingers if a in hand.finger_links(f))
                fb = next(f.name for f in hand.fingers if b in hand.finger_links(f))
                assert tuple(sorted((fa, fb))) in {tuple(sorted(p)) for p in report.finger_pairs_colliding}
                colliding += 1
            elif gap > -0.0015:
                assert frozenset((a, b)) not in found, (a, b, gap)
    assert colliding >= 2  # the test postures do press fingers together


def _link_parts(hand, q, root) -> dict[str, list[trimesh.Trimesh]]:
    """The judge's surfaces, one closed mesh per collision geometry, placed."""
    poses = hand.link_transforms(q)
    out = {}
    for link, geoms in hand.collision.items():
        out[link] = []
        for g in geoms:
            m = g.to_trimesh()
            m.apply_transform(root @ poses[link])
            out[link].append(m)
    return out


def _depth(mesh_a: trimesh.Trimesh, mesh_b: trimesh.Trimesh, rng: np.random.Generator) -> float | None:
    """The judge's overlap of two placed closed meshes (m): the deepest of each one's surface
    samples inside the other (trimesh's signed distance, > 0 inside; a lower bound of the
    depth that separates them); None when their bounding boxes do not meet (apart)."""
    lo, hi = np.maximum(mesh_a.bounds[0], mesh_b.bounds[0]), np.minimum(mesh_a.bounds[1], mesh_b.bounds[1])
    if np.any(lo > hi):
        return None
    deepest = 0.0
    for inner, outer in ((mesh_a, mesh_b), (mesh_b, mesh_a)):
        points = inner.sample(5000, seed=int(rng.integers(1 << 30)))
        points = points[np.all((points >= lo) & (points <= hi), axis=1)]
        if len(points):
            deepest = max(deepest, float(trimesh.proximity.signed_distance(outer, points).max()))
    return deepest


def _link_depth(parts_a: list, parts_b: list, rng: np.random.Generator) -> float | None:
    """The judge's overlap of two placed links (m) over their part pairs; None: apart."""
    depths = [d for d in (_depth(a, b, rng) for a in parts_a for b in parts_b) if d is not None]
    return max(depths) if depths else None


def _separating_bound(parts_a: list, parts_b: list, directions: np.ndarray) -> float | None:
    """The judge's upper bound of two placed links' overlap (m): per part pair the least,
    over ``directions`` (D, 3) unit, overlap of their vertices' projections (moving one part
    that far along that direction separates their convex hulls, which contain the parts);
    the largest over the part pairs. None when no pair's bounding boxes meet (apart)."""
    worst = None
    for a in parts_a:
        for b in parts_b:
            lo, hi = np.maximum(a.bounds[0], b.bounds[0]), np.minimum(a.bounds[1], b.bounds[1])
            if np.any(lo > hi):
                continue
            pa, pb = np.asarray(a.vertices) @ directions.T, np.asarray(b.vertices) @ directions.T
            overlap = float(np.min(pa.max(axis=0) - pb.min(axis=0)))
            worst = overlap if worst is None else max(worst, overlap)
    return worst


#: Rows of ``default_rng(0).uniform(lower, upper, (3000, n))`` for the Shadow hand: the
#: first six (row 3 presses the thumb's middle link about 1.2 mm into the palm), row 292
#: (found by a search over 400 rows: the same link about 2.9 mm in) and rows 1196, 1905
#: and 2267 (found by a search over 3000: the thumb's middle or distal link 1.2-1.8 mm in,
#: the judge's bounds both between 1 and 2 mm).
PALM_ROWS = (0, 1, 2, 3, 4, 5, 292, 1196, 1905, 2267)


def test_a_finger_link_pressed_into_the_palm_collides(hands):
    """A finger link deeper than PALM_OVERLAP in a palm link (not its parent, apart with the
    hand open) is a self-collision, and one less deep is not: the palm takes the soft skins'
    ALLOWED_OVERLAP, as another finger does. Judged on the Shadow hand's links with trimesh
    (a lower bound of the separating depth: a pair it reads deeper than PALM_OVERLAP must be
    reported) and with the links' vertices projected on 2000 directions (an upper bound: a
    pair it bounds below PALM_OVERLAP, or whose boxes do not meet, must not be). Rows 1196,
    1905 and 2267 press the thumb 1.2-1.8 mm into the palm: a self-collision when the palm's
    allowance was 1 mm, which refused most of dex-urdf's Schunk SVH's opposed thumbs (a
    coarse palm box). The pair is a link pair, not a finger pair."""
    from grasp_apso.geometry.any_hand_fcl import ALLOWED_OVERLAP, PALM_OVERLAP

    assert PALM_OVERLAP == ALLOWED_OVERLAP
    hand = hands["shadow"]
    hc = HandCollision(hand)
    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.01)
    far = np.eye(4)
    far[:3, 3] = [1.0, 0.0, 0.0]  # the object far away
    fingers = {link for f in hand.fingers for link in hand.finger_links(f) if link in hand.collision}
    rng = np.random.default_rng(3)  # the judge's samples
    directions = np.random.default_rng(5).normal(size=(2000, 3))
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    opened = _link_parts(hand, hand.open_configuration(), far)
    pairs = [(hand.root_link, link) for link in fingers
             if hand.chain(link)[-2] != hand.root_link and not _link_depth(opened[hand.root_link], opened[link], rng)]
    assert pairs
    rows = np.random.default_rng(0).uniform(hand.lower, hand.upper, (3000, hand.n_joints))
    deeper = shallower = 0
    for q in rows[list(PALM_ROWS)]:
        report = object_report(hc, q, far, ball)
        found = {frozenset(p) for p in report.link_pairs_colliding}
        parts = _link_parts(hand, q, far)
        for p, link in pairs:
            depth = _link_depth(parts[p], parts[link], rng)
            bound = _separating_bound(parts[p], parts[link], directions)
            if depth is None or bound < PALM_OVERLAP:
                assert frozenset((p, link)) not in found, (p, link, bound)
                shallower += depth is not None and depth > TOUCH_TOLERANCE  # deeper than the old 1 mm
            elif depth > PALM_OVERLAP:
                assert frozenset((p, link)) in found, (p, link, depth)
                assert not report.legal
                deeper += 1
        names = [f.name for f in hand.fingers]
        assert all(a in names and b in names for a, b in report.finger_pairs_colliding)
    assert deeper >= 1  # row 292 presses a finger into the palm
    assert shallower >= 2  # rows 1196, 1905, 2267: in, but less than the allowance


def test_threads_share_one_hand_and_agree(hands):
    hand = hands["shadow"]
    hc = HandCollision(hand)
    assert HandCollision(hand).shapes is hc.shapes  # built once per hand
    ball = trimesh.creation.icosphere(subdivisions=3, radius=RADIUS)
    rng = np.random.default_rng(2)
    cases = []
    for _ in range(6):
        root = np.eye(4)
        root[:3, :3] = _rotation(rng)
        root[:3, 3] = rng.uniform(-0.06, 0.06, 3)
        cases.append((_random_q(hand, rng), root))
    expected = [object_report(hc, q, r, ball).link_distance for q, r in cases]
    results: dict[int, list] = {}

    def work(i):
        results[i] = [object_report(hc, q, r, ball).link_distance for q, r in cases * 3]

    threads = [threading.Thread(target=work, args=(i,)) for i in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert sorted(results) == [0, 1, 2]
    for got in results.values():
        for a, b in zip(got, expected * 3):
            np.testing.assert_allclose(a, b, atol=1e-12)


def test_bad_input_names_the_field(hands):
    hand = hands["allegro"]
    hc = HandCollision(hand)
    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.02)
    q = hand.open_configuration()
    with pytest.raises(InputError) as err:
        object_report(hc, q[:-1], np.eye(4), ball)
    assert err.value.field == "q"
    bad = np.eye(4)
    bad[0, 0] = 2.0
    with pytest.raises(InputError) as err:
        object_report(hc, q, bad, ball)
    assert err.value.field == "root_in_object"
    with pytest.raises(InputError) as err:
        object_report(hc, q, np.eye(4), fcl.BVHModel())
    assert err.value.field == "obj"
    with pytest.raises(InputError) as err:
        approach_report(hc, q, np.eye(4), np.zeros(3), 0.08, Scene())
    assert err.value.field == "approach"
    with pytest.raises(InputError) as err:
        scene_distance(hc, np.full_like(q, np.nan), np.eye(4), Scene())
    assert err.value.field == "q"


def test_a_non_convex_object_ring_over_its_top_and_inside_its_hole(hands):
    """A ring (annulus): the hand above its top face reports the gap; the hand inside the
    hole (inside the hull, outside the solid) reports its distance to the inner wall."""
    hand = hands["allegro"]
    hc = HandCollision(hand)
    rng = np.random.default_rng(4)
    q = hand.open_configuration()
    root = np.eye(4)
    root[:3, :3] = _rotation(rng)
    meshes = _link_meshes(hand, q, root)
    ring = trimesh.creation.annulus(r_min=0.25, r_max=0.7, height=0.4, sections=512)  # top face z = 0.2
    # over the top face, 4 mm up, the hand centred over the ring's middle radius
    lowest = {lk: float(m.vertices[:, 2].min()) for lk, m in meshes.items()}
    placed = root.copy()
    placed[:3, 3] += [0.475, 0.0, 0.2 + 0.004 - min(lowest.values())]
    report = object_report(hc, q, placed, ring)
    for lk, z in lowest.items():
        expected = z + placed[2, 3] - 0.2
        assert report.distance_of(lk) == pytest.approx(expected, abs=TOL if expected < 0.01 else 1e-3), lk
    # in the hole: distance to the inner wall = 0.25 - the link's largest radius
    report = object_report(hc, q, root, ring)
    for lk, m in meshes.items():
        assert np.abs(m.vertices[:, 2]).max() < 0.19  # within the ring's height
        expected = 0.25 - float(np.hypot(m.vertices[:, 0], m.vertices[:, 1]).max())
        assert expected > 0.05
        # inside the hull: measured exactly on the mesh (fcl alone would call it apart)
        assert report.distance_of(lk) == pytest.approx(expected, abs=TOL), lk
    # half out of the hole: beyond exact_within a link reports the hull's lower bound;
    # exact_within=inf measures every link exactly (never less than the bound)
    placed = root.copy()
    placed[2, 3] = 0.15
    bounded = object_report(hc, q, placed, ring)
    exact = object_report(hc, q, placed, ring, exact_within=np.inf)
    assert np.all(bounded.link_distance <= exact.link_distance + 1e-9)
    near = exact.link_distance < 0.01
    np.testing.assert_allclose(bounded.link_distance[near], exact.link_distance[near], atol=1e-9)
    assert np.any(bounded.link_distance < exact.link_distance - 0.05)  # links above the top: bounds


def test_a_grasp_object_is_measured_as_its_mesh(hands):
    from grasp_apso.model.objects import from_arrays

    hand = hands["allegro"]
    box = trimesh.creation.box(extents=(0.06, 0.05, 0.08))
    obj = from_arrays(box.vertices, box.faces, name="box")
    root = np.eye(4)
    root[:3, 3] = [0.0, 0.0, 0.09]
    q = hand.closed_configuration(0.5)
    a = object_report(hand, q, root, obj)
    b = object_report(hand, q, root, obj.mesh.copy())
    np.testing.assert_allclose(a.link_distance, b.link_distance, atol=1e-9)
    assert np.any(a.link_distance < 0.01)  # the posture reaches the box


@pytest.mark.parametrize("mesh_name", ["mug", "ring"])
def test_the_object_bound_never_puts_a_point_farther_out_than_it_is(mesh_name):
    """``ObjectShape.hull_gap`` (the planes that spare most link samples the exact depth
    query) must, where positive, be a lower bound of how far a point lies outside the object: judged by
    trimesh's signed distance, on a non-convex mug and a torus, seeded points in and around."""
    from grasp_apso.geometry.any_hand_shapes import object_shape
    from grasp_apso.model.mesh_files import from_file

    if mesh_name == "mug":
        mesh = from_file("grasp_apso/data/meshes/mug.stl").mesh
    else:
        mesh = trimesh.creation.torus(major_radius=0.035, minor_radius=0.012)
    shape = object_shape(mesh)
    rng = np.random.default_rng(3)
    lo, hi = mesh.bounds
    points = rng.uniform(lo - 0.02, hi + 0.02, size=(3000, 3))
    outside = -trimesh.proximity.signed_distance(mesh, points)  # trimesh: > 0 inside
    gap = shape.hull_gap(points)
    shown = gap > 0.0  # the only reading used: a point shown this far outside (at least)
    assert np.all(gap[shown] <= outside[shown] + 1e-7)
    assert shown.mean() > 0.3  # and it does bound: most points around are shown outside
    for within in (0.0, 0.0015, 0.01):  # the compiled filter reads the same planes
        assert np.array_equal(shape.may_reach(points, within), gap < within)


def test_an_objects_edge_pressed_into_a_link_between_its_vertices_is_read_at_its_depth(hands):
    """An object's sharp edge pressing into a link's face is as deep as the edge, even where
    the object's vertices lie outside the link: a thin wedge whose 80 mm ridge lies 1.5 mm
    inside the Allegro-like index proximal's box face (the box 54 mm long, the ridge's ends
    outside it). Read from the object's vertices and the box's surface samples alone (inside
    the thin wedge by 0.3 mm at most) it was legal; dex-urdf's LEAP thumb took the mug's rim
    1.31 mm into its fingertip, read 0.65 mm. Judged by the geometry: the ridge is a straight
    line 1.5 mm under the face, away from the box's other faces."""
    hand = hands["allegro"]
    hc = HandCollision(hand)
    q = hand.open_configuration()
    link = "index_proximal"
    part = [k for k in range(len(hc.shapes.geoms)) if hc.links[hc.shapes.part_link[k]] == link]
    assert len(part) == 1 and hc.shapes.geoms[part[0]].kind == "box"
    hx, hy, hz = hc.shapes.geoms[part[0]].size
    pose = hc.part_poses(q, np.eye(4))[part[0]]  # the box frame in the object (= root) frame
    depth, half_opening, height = 0.0015, math.radians(10.0), 0.02
    apex, ridge = hx - depth, 1.5 * hz
    wide = height * math.tan(half_opening)
    # the wedge's cross-section: the apex inside the +x face, the base 20 mm outside it
    section = [(apex, 0.0), (apex + height, wide), (apex + height, -wide)]
    local = np.array([(x, y, z) for z in (-ridge, ridge) for x, y in section])
    faces = [(0, 2, 1), (3, 4, 5), (0, 1, 4), (0, 4, 3), (1, 2, 5), (1, 5, 4), (2, 0, 3), (2, 3, 5)]
    wedge = trimesh.Trimesh(local @ pose[:3, :3].T + pose[:3, 3], faces, process=False)
    wedge.fix_normals()
    assert wedge.is_watertight and wedge.volume > 0
    inside = np.all(np.abs(local) < np.array([hx, hy, hz]), axis=1)
    assert not inside.any()  # no vertex of the wedge is inside the box
    report = object_report(hc, q, np.eye(4), wedge)
    read = -float(report.link_distance[list(report.links).index(link)])
    assert read == pytest.approx(depth, abs=2e-4)
    assert not report.legal
