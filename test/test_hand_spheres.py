"""Collision geometry of any hand's links (issue 20): exact signed distances, the sphere
covers and the fingertip pads (grasp_apso.model.hands.geometry / spheres / pads).

Checked independently of the code under test: coverage on surface samples drawn by
``trimesh.sample.sample_surface``; the stray with ``trimesh.proximity.signed_distance`` of
points on every sphere's surface; mesh distances against a brute-force loop over all
triangles and trimesh's ray-parity ``contains``; pads against the analytic surface.

Counts with a 2 mm stray (seed 0, random placement, measured when written): spheres only:
box 20 x 27 x 54 mm 169, sphere r 10 mm 1, cylinder r 8 x 40 mm 33, capsule r 8 + 40 mm
6, L-shaped mesh 141, a palm-sized box 100 x 90 x 20 mm more than 256. A box needs many:
its edges and corners are covered only by spheres centred within a few millimetres of
them. With capsules offered too: box 32, L-shaped mesh 32, palm-sized box 77, capsule 1.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from grasp_apso.errors import HandDescriptionError, InputError
from grasp_apso.geometry.sdf import point_triangle_distance
from grasp_apso.model.hands.geometry import LinkGeometry
from grasp_apso.model.hands.pads import PAD_RADIUS_RANGE, find_pad, outer_surface_samples
from grasp_apso.model.hands.spheres import MAX_STRAY, cover_link, union_signed_distance

TF = trimesh.transformations


def _pose(seed: int) -> np.ndarray:
    """A seeded rigid placement (rotation + translation of a few centimetres)."""
    rng = np.random.default_rng(seed)
    pose = TF.random_rotation_matrix(rng.random(3))
    pose[:3, 3] = rng.uniform(-0.05, 0.05, 3)
    return pose


PLACEMENTS = {"identity": np.eye(4), "placed": _pose(7)}


def _l_prism() -> trimesh.Trimesh:
    """A non-convex watertight L-shaped prism (legs 40 and 35 mm, 12 mm thick, 15 mm deep),
    built face by face (no boolean engine)."""
    outline = np.array([[0, 0], [40, 0], [40, 12], [12, 12], [12, 35], [0, 35]], dtype=float) * 1e-3
    n = len(outline)
    vertices = np.vstack([np.c_[outline, np.zeros(n)], np.c_[outline, np.full(n, 0.015)]])
    cap = [[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5]]  # fan from the outer corner
    faces = [[c[0], c[2], c[1]] for c in cap] + [[n + a, n + b, n + c] for a, b, c in cap]
    for i in range(n):
        j = (i + 1) % n
        faces += [[i, j, n + j], [i, n + j, n + i]]
    mesh = trimesh.Trimesh(vertices, np.array(faces), process=True)
    assert mesh.is_watertight and mesh.volume > 0
    return mesh


def _convex_mesh() -> trimesh.Trimesh:
    """A convex hull of 300 random points on an ellipsoid (semi-axes 8, 11, 20 mm)."""
    rng = np.random.default_rng(3)
    directions = rng.normal(size=(300, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return trimesh.convex.convex_hull(directions * [0.008, 0.011, 0.02])


def _shapes(pose: np.ndarray) -> dict[str, list[LinkGeometry]]:
    shift = TF.translation_matrix
    return {
        "box": [LinkGeometry("box", (0.010, 0.0135, 0.027), pose)],
        "sphere": [LinkGeometry("sphere", (0.010,), pose)],
        "cylinder": [LinkGeometry("cylinder", (0.008, 0.020), pose)],
        "capsule": [LinkGeometry("capsule", (0.008, 0.020), pose)],
        "convex_mesh": [LinkGeometry("mesh", (), pose, _convex_mesh())],
        "l_mesh": [LinkGeometry("mesh", (), pose, _l_prism())],
        "capsule_and_box": [LinkGeometry("capsule", (0.006, 0.015), pose),
                            LinkGeometry("box", (0.012, 0.005, 0.004), pose @ shift([0.0, 0.0, 0.018]))],
    }


#: Most spheres each shape may take (a regression bound; measured counts in the docstring).
MAX_COUNT = {"box": 200, "sphere": 2, "cylinder": 60, "capsule": 12, "convex_mesh": 40, "l_mesh": 170,
             "capsule_and_box": 120}


def _fibonacci(count: int) -> np.ndarray:
    i = np.arange(count) + 0.5
    z = 1.0 - 2.0 * i / count
    phi = np.pi * (1.0 + 5.0**0.5) * i
    return np.stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z], axis=1)


def _min_sphere_gap(points: np.ndarray, centers: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Per point: min over spheres of |p - c| - r (<= 0: inside one)."""
    out = np.empty(len(points))
    for s in range(0, len(points), 2000):
        block = points[s:s + 2000]
        out[s:s + 2000] = (np.linalg.norm(block[:, None] - centers[None], axis=2) - radii[None]).min(axis=1)
    return out


def _independent_stray(geoms: list[LinkGeometry], centers: np.ndarray, radii: np.ndarray) -> float:
    """Largest distance outside the union of the geometries' meshes of points on the spheres."""
    rng = np.random.default_rng(11)
    unit = _fibonacci(120) @ TF.random_rotation_matrix(rng.random(3))[:3, :3].T
    points = (centers[:, None] + radii[:, None, None] * unit[None]).reshape(-1, 3)
    inside_depth = np.max([trimesh.proximity.signed_distance(g.to_trimesh(), points) for g in geoms], axis=0)
    return float(-inside_depth.min())  # trimesh: > 0 inside


@pytest.mark.parametrize("placement", sorted(PLACEMENTS))
@pytest.mark.parametrize("shape", sorted(MAX_COUNT))
def test_spheres_cover_the_surface_and_stray_at_most_2mm(shape, placement):
    geoms = _shapes(PLACEMENTS[placement])[shape]
    cover = cover_link(geoms, rng=np.random.default_rng(0))
    assert 1 <= cover.count <= MAX_COUNT[shape]
    surface = trimesh.util.concatenate([g.to_trimesh() for g in geoms])
    samples, _ = trimesh.sample.sample_surface(surface, 20000, seed=5)
    gap = _min_sphere_gap(np.asarray(samples), cover.centers, cover.radii)
    assert gap.max() <= 0.0, f"{(gap > 0).sum()} of 20000 surface samples outside every sphere"
    stray = _independent_stray(geoms, cover.centers, cover.radii)
    assert stray <= MAX_STRAY
    # The cover's own report agrees with the independent measurement.
    assert cover.uncovered == 0.0
    assert cover.max_stray <= MAX_STRAY
    assert abs(cover.max_stray - stray) < 3e-4
    # The spheres are not needlessly small: the stray allowance is used.
    assert stray > 0.5 * MAX_STRAY


def _independent_capsule_stray(geoms: list[LinkGeometry], cover) -> float:
    """Like _independent_stray, for capsules: spheres at 9 stations along each segment."""
    rng = np.random.default_rng(12)
    unit = _fibonacci(80) @ TF.random_rotation_matrix(rng.random(3))[:3, :3].T
    t = np.linspace(0.0, 1.0, 9)
    axis = cover.centers[:, None] + t[None, :, None] * (cover.ends - cover.centers)[:, None]
    points = (axis[:, :, None] + cover.radii[:, None, None, None] * unit[None, None]).reshape(-1, 3)
    inside_depth = np.max([trimesh.proximity.signed_distance(g.to_trimesh(), points) for g in geoms], axis=0)
    return float(-inside_depth.min())


def _capsule_gap(points: np.ndarray, cover) -> np.ndarray:
    """Per point: min over capsules of (distance to the segment) - radius."""
    a, b = cover.centers, cover.ends
    ab = b - a
    ap = points[:, None, :] - a[None]
    t = np.clip((ap * ab[None]).sum(axis=2) / np.maximum((ab * ab).sum(axis=1), 1e-30)[None], 0.0, 1.0)
    return (np.linalg.norm(ap - t[:, :, None] * ab[None], axis=2) - cover.radii[None]).min(axis=1)


#: Most elements with capsules (measured when written: box 32, L mesh 35, capsule 1).
MAX_CAPSULE_COUNT = {"box": 45, "l_mesh": 50, "capsule": 2, "capsule_and_box": 60}


@pytest.mark.parametrize("shape", sorted(MAX_CAPSULE_COUNT))
def test_capsules_cover_with_far_fewer_elements(shape):
    geoms = _shapes(PLACEMENTS["placed"])[shape]
    spheres = cover_link(geoms, rng=np.random.default_rng(0))
    cover = cover_link(geoms, rng=np.random.default_rng(0), capsules=True)
    assert cover.count <= MAX_CAPSULE_COUNT[shape]
    assert cover.is_capsule.any()
    if shape in ("box", "l_mesh"):
        assert cover.count < 0.4 * spheres.count
    surface = trimesh.util.concatenate([g.to_trimesh() for g in geoms])
    samples, _ = trimesh.sample.sample_surface(surface, 20000, seed=6)
    gap = np.concatenate([_capsule_gap(np.asarray(samples[i:i + 2000]), cover) for i in range(0, 20000, 2000)])
    assert gap.max() <= 0.0, f"{(gap > 0).sum()} of 20000 surface samples outside every capsule"
    assert _independent_capsule_stray(geoms, cover) <= MAX_STRAY
    assert cover.uncovered == 0.0 and cover.max_stray <= MAX_STRAY


def test_a_palm_sized_box_needs_capsules():
    """100 x 90 x 20 mm: spheres alone run out at 256 with part of the surface uncovered."""
    palm = [LinkGeometry("box", (0.05, 0.045, 0.01), PLACEMENTS["placed"])]
    spheres = cover_link(palm, max_spheres=256)
    assert spheres.count == 256 and spheres.uncovered > 0.01
    cover = cover_link(palm, capsules=True)
    assert cover.uncovered == 0.0 and cover.count <= 120


def test_cover_is_deterministic_and_seeded():
    geoms = _shapes(PLACEMENTS["placed"])["l_mesh"]
    a = cover_link(geoms, rng=np.random.default_rng(4))
    b = cover_link(geoms, rng=np.random.default_rng(4))
    assert np.array_equal(a.centers, b.centers) and np.array_equal(a.radii, b.radii)
    assert not a.centers.flags.writeable and not a.radii.flags.writeable


def test_a_smaller_tolerance_strays_less_with_more_spheres():
    geoms = _shapes(np.eye(4))["capsule"]
    loose = cover_link(geoms, tolerance=0.002)
    tight = cover_link(geoms, tolerance=0.001)
    assert tight.count > loose.count
    assert _independent_stray(geoms, tight.centers, tight.radii) <= 0.001


def test_max_spheres_stops_the_cover_and_reports_what_is_left():
    geoms = _shapes(np.eye(4))["box"]
    cover = cover_link(geoms, max_spheres=10)
    assert cover.count == 10
    assert 0.05 < cover.uncovered < 1.0


@pytest.mark.parametrize("kwargs, field", [
    ({"geoms": []}, "geoms"),
    ({"geoms": ["box"]}, "geoms"),
    ({"tolerance": 0.0}, "tolerance"),
    ({"tolerance": float("nan")}, "tolerance"),
    ({"rng": 3}, "rng"),
    ({"max_spheres": 0}, "max_spheres"),
])
def test_cover_link_refuses_bad_arguments(kwargs, field):
    args = {"geoms": _shapes(np.eye(4))["sphere"]} | kwargs
    geoms = args.pop("geoms")
    with pytest.raises(InputError) as err:
        cover_link(geoms, **args)
    assert err.value.field == field


# ------------------------------------------------------------------------------------------
# exact signed distance
# ------------------------------------------------------------------------------------------
def _brute_signed_distance(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    """Distance to every triangle, the least; the sign from trimesh's ray parity (> 0 out).
    (trimesh.proximity.signed_distance is approximate: up to 0.08 mm off on a capsule.)"""
    tri = mesh.triangles
    brute = np.array([point_triangle_distance(np.repeat(p[None], len(tri), 0), tri[:, 0], tri[:, 1],
                                              tri[:, 2]).min() for p in points])
    return np.where(mesh.contains(points), -brute, brute)


@pytest.mark.parametrize("placement", sorted(PLACEMENTS))
@pytest.mark.parametrize("shape", ["box", "sphere", "cylinder", "capsule"])
def test_primitive_signed_distance_matches_the_tessellated_surface(shape, placement):
    geom = _shapes(PLACEMENTS[placement])[shape][0]
    mesh = geom.to_trimesh()
    assert mesh.is_watertight
    rng = np.random.default_rng(2)
    points = mesh.bounds.mean(axis=0) + rng.uniform(-0.03, 0.03, (400, 3))
    # The tessellation lies up to 0.12 % of a 10 mm radius (12 um) inside the true surface.
    assert np.abs(geom.signed_distance(points) - _brute_signed_distance(mesh, points)).max() < 1.5e-5


def test_primitive_meshes_have_their_analytic_volume_and_place():
    pose = PLACEMENTS["placed"]
    r, h = 0.008, 0.020
    volumes = {"box": 8 * 0.010 * 0.0135 * 0.027, "sphere": 4 / 3 * np.pi * 0.010**3,
               "cylinder": np.pi * r * r * 2 * h, "capsule": np.pi * r * r * 2 * h + 4 / 3 * np.pi * r**3}
    for shape, volume in volumes.items():
        mesh = _shapes(pose)[shape][0].to_trimesh()
        assert mesh.volume == pytest.approx(volume, rel=5e-3)
        assert np.allclose(mesh.center_mass, pose[:3, 3], atol=1e-6)


@pytest.mark.parametrize("shape", ["convex_mesh", "l_mesh"])
def test_mesh_signed_distance_is_exact(shape):
    geom = _shapes(PLACEMENTS["placed"])[shape][0]
    mesh = geom.to_trimesh()
    rng = np.random.default_rng(9)
    near = mesh.vertices[rng.integers(0, len(mesh.vertices), 500)] + rng.normal(0.0, 3e-4, (500, 3))
    points = np.vstack([mesh.bounds.mean(axis=0) + rng.uniform(-0.04, 0.04, (700, 3)), near])
    assert np.abs(geom.signed_distance(points) - _brute_signed_distance(mesh, points)).max() < 1e-12


def test_a_mesh_that_is_not_watertight_stands_for_its_convex_hull():
    open_box = trimesh.creation.box([0.02, 0.02, 0.02])
    open_box.update_faces(np.arange(len(open_box.faces)) != 0)
    assert not open_box.is_watertight
    geom = LinkGeometry("mesh", (), np.eye(4), open_box, source="hand.urdf: link1 collision 0")
    assert "convex hull" in geom.source and geom.mesh.is_watertight
    assert geom.signed_distance(np.zeros((1, 3)))[0] == pytest.approx(-0.01)


def _with_cavity(outer: trimesh.Trimesh, size: float, offset) -> trimesh.Trimesh:
    """``outer`` and, inside it, a closed box shell wound inward: a cavity, as CAD exports
    carry for a screw hole or engraved text (dex hands' STL files, e.g. the XHAND's)."""
    cavity = trimesh.creation.box([size] * 3)
    cavity.apply_translation(offset)
    return trimesh.util.concatenate([outer, trimesh.Trimesh(cavity.vertices, cavity.faces[:, ::-1])])


@pytest.mark.parametrize("kind, size, scale", [("mesh", (), 0.1), ("box", (0.6, 0.02, 0.02), 1.0),
                                               ("capsule", (0.01, 0.6), 1.0)])
def test_a_geometry_larger_than_a_hand_is_refused_as_a_unit_error(kind, size, scale):
    # HOPE-Jr's fingertip STL files scaled 0.1 by its URDF: 27 m long.
    mesh = trimesh.creation.box([272.5, 152.0, 136.7]).apply_scale(scale) if kind == "mesh" else None
    geom = LinkGeometry(kind, size, np.eye(4), mesh, source="link1 collision 0")   # an obstacle may be so large
    with pytest.raises(HandDescriptionError, match=r"link1 collision 0: .* m across, more than any part of a hand "
                                                   r"\(1 m\): are its units the file's"):
        geom.check_hand_part()
    if kind == "capsule":  # the largest a hand's part may be
        LinkGeometry(kind, (0.01, 0.49), np.eye(4), None, source="link1 collision 0").check_hand_part()


def test_a_mesh_with_a_cavity_reads_outside_beyond_its_surface():
    box = trimesh.creation.box([0.02, 0.02, 0.02])
    mesh = _with_cavity(box, 0.006, (0.002, 0.0, 0.0))
    geom = LinkGeometry("mesh", (), np.eye(4), mesh, source="hand.urdf: link1 collision 0")
    rng = np.random.default_rng(11)
    points = rng.uniform(-0.05, 0.05, (400, 3))
    # The solid is the outer box's (the cavity's shell turned outward lies within it):
    # before, the cavity's part read every point inside.
    np.testing.assert_allclose(geom.signed_distance(points), _brute_signed_distance(box, points), atol=1e-12)
    samples, _ = outer_surface_samples([geom], 0.002, rng, 2000)
    assert len(samples) > 100
    assert np.abs(_brute_signed_distance(box, samples)).max() < 1e-9   # all on the outer surface


@pytest.mark.parametrize("corner", [0, 1])
def test_a_cavity_shell_folded_through_itself_leaves_the_outside_outside(corner):
    # The Wuji hand's phalanx STL files: a cavity shell that crosses itself, where the
    # closest feature's pseudo-normal points the wrong way, read points millimetres
    # outside the link as inside, and the cover's spheres stood 5-6 mm out of the link.
    box = trimesh.creation.box([0.02, 0.02, 0.02])
    cavity = trimesh.creation.box([0.006] * 3)
    vertices = np.array(cavity.vertices)
    vertices[corner] *= -1.5  # one corner pulled through the opposite one: the shell folds
    folded = trimesh.Trimesh(vertices, cavity.faces[:, ::-1], process=False)
    geom = LinkGeometry("mesh", (), np.eye(4), trimesh.util.concatenate([box, folded]), source="link2 collision 0")
    assert "hull" not in geom.source  # closed and consistently wound: kept as it is
    points = np.random.default_rng(5).uniform(-0.05, 0.05, (600, 3))
    # Before: 173 and 255 of the 600 points, most of them outside the box, read wrong.
    np.testing.assert_allclose(geom.signed_distance(points), _brute_signed_distance(box, points), atol=1e-12)
    cover = cover_link([geom], rng=np.random.default_rng(0))
    # measured against the box alone (the solid), not the geometry under test
    assert _independent_stray([LinkGeometry("mesh", (), np.eye(4), box)], cover.centers, cover.radii) <= MAX_STRAY


def test_a_hand_whose_fingertip_meshes_have_cavities_finds_its_pads(tmp_path):
    from hand_files import write_allegro_like  # noqa: PLC0415 -- the test hands

    from grasp_apso.model.hands.load import load_hand  # noqa: PLC0415

    path = write_allegro_like(tmp_path, "all")
    tips = sorted((path.parent / "meshes").glob("*_tip_0.stl"))
    assert len(tips) == 4
    for tip in tips:
        _with_cavity(trimesh.load(tip), 0.004, (0.0, 0.0, 0.002)).export(tip)
    hand = load_hand(path, spheres=False)   # before: no outer surface on the tips, a crash
    assert len(hand.fingers) == 4
    for finger in hand.fingers:
        geoms = hand.collision[finger.pad_link]
        assert abs(union_signed_distance(geoms, np.asarray(finger.pad_center)[None])[0]) < 1e-3


def test_an_open_mesh_whose_hull_qhull_leaves_open_stands_for_its_closed_hull():
    # Tesollo DG-5F's STL files: points on the hull's edges a hair off them make qhull drop
    # a sliver facet, the hull came out open and the hand was refused as "flat"; rounded to
    # 1 um the points give the closed hull.
    box = trimesh.creation.box([0.02, 0.02, 0.02])
    rng = np.random.default_rng(0)
    ends = box.vertices[box.edges_unique]
    t = rng.random((len(ends), 8, 1))
    edge_points = (ends[:, 0, None] * (1.0 - t) + ends[:, 1, None] * t).reshape(-1, 3)
    edge_points += rng.normal(0.0, 1e-10, edge_points.shape)
    vertices = np.vstack([box.vertices, edge_points])
    assert not trimesh.convex.convex_hull(vertices).is_watertight
    corner = int(np.argmax(np.linalg.norm(box.vertices - edge_points[0], axis=1)))
    fan = [[8 + i, 9 + i, corner] for i in range(len(edge_points) - 1)]
    open_mesh = trimesh.Trimesh(vertices, np.vstack([box.faces[1:], fan]), process=False)
    geom = LinkGeometry("mesh", (), np.eye(4), open_mesh, source="link1 collision 0")
    assert "convex hull" in geom.source and geom.mesh.is_watertight
    assert geom.mesh.volume == pytest.approx(8e-6, rel=1e-6)


@pytest.mark.parametrize("args", [
    ("cone", (0.01,)),
    ("box", (0.01, 0.01)),
    ("box", (0.01, -0.01, 0.01)),
    ("sphere", ("big",)),
    ("mesh", ()),
])
def test_bad_geometry_is_refused_naming_collision(args):
    with pytest.raises(HandDescriptionError) as err:
        LinkGeometry(*args, source="hand.urdf: link3")
    assert err.value.field == "collision"


def test_a_scaled_origin_is_refused():
    with pytest.raises(HandDescriptionError, match="rigid"):
        LinkGeometry("box", (0.01, 0.01, 0.01), np.diag([2.0, 1.0, 1.0, 1.0]))


# ------------------------------------------------------------------------------------------
# pads
# ------------------------------------------------------------------------------------------
def _local(pose: np.ndarray, point: np.ndarray) -> np.ndarray:
    return np.linalg.inv(pose)[:3, :3] @ point + np.linalg.inv(pose)[:3, 3]


@pytest.mark.parametrize("placement", sorted(PLACEMENTS))
def test_pad_of_a_box_fingertip_is_on_its_palmar_face_near_the_tip(placement):
    pose = PLACEMENTS[placement] @ TF.translation_matrix([0.0, 0.0, 0.015])
    box = LinkGeometry("box", (0.008, 0.006, 0.015), pose)  # 16 wide, 12 thick, 30 long (z)
    rot = pose[:3, :3]
    center, radius = find_pad([box], rot @ [0.0, -1.0, 0.0], rot @ [0.0, 0.0, 1.0])
    local = _local(pose, center)
    assert local[1] == pytest.approx(-0.006, abs=1e-9)     # on the palmar face
    assert 0.015 - 0.35 * 0.030 <= local[2] <= 0.015      # in the distal part
    assert abs(local[0]) < 0.002                          # across: near the middle
    assert radius == pytest.approx(0.008, abs=3e-4)       # the face's half-width


@pytest.mark.parametrize("placement", sorted(PLACEMENTS))
def test_pad_of_a_capsule_fingertip_has_its_radius(placement):
    pose = PLACEMENTS[placement]
    capsule = LinkGeometry("capsule", (0.007, 0.012), pose)
    rot = pose[:3, :3]
    center, radius = find_pad([capsule], rot @ [1.0, 0.0, 0.0], rot @ [0.0, 0.0, 1.0])
    local = _local(pose, center)
    assert np.hypot(local[0], local[1]) == pytest.approx(0.007, abs=1e-4)
    assert local[0] > 0.0069 and 0.0 < local[2] <= 0.019
    assert radius == pytest.approx(0.007, abs=3e-4)


def test_pad_of_a_mesh_fingertip():
    tip = trimesh.creation.capsule(height=0.024, radius=0.007, count=[32, 32])
    pose = PLACEMENTS["placed"]
    geom = LinkGeometry("mesh", (), pose, tip)
    rot = pose[:3, :3]
    center, radius = find_pad([geom], rot @ [0.0, -1.0, 0.0], rot @ [0.0, 0.0, 1.0])
    local = _local(pose, center)
    assert abs(trimesh.proximity.signed_distance(tip, local[None])[0]) < 1e-6  # on the surface
    assert local[1] < -0.0068 and 0.0 < local[2] <= 0.019                     # palmar, distal part
    assert radius == pytest.approx(0.007, abs=5e-4)


def test_pad_of_an_ellipsoid_tip_is_in_range_and_palmar():
    tip = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    tip.apply_scale([0.008, 0.006, 0.016])
    geom = LinkGeometry("mesh", (), np.eye(4), tip)
    center, radius = find_pad([geom], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0])
    assert center[1] < -0.004 and center[2] > 0.0
    assert PAD_RADIUS_RANGE[0] <= radius <= PAD_RADIUS_RANGE[1]
    # Across the finger the ellipsoid curves with radius 8^2/6 = 10.7 mm at its equator,
    # less toward the tip.
    assert 0.006 < radius < 0.0115


def test_find_pad_refuses_bad_directions():
    geoms = [LinkGeometry("sphere", (0.01,))]
    with pytest.raises(InputError) as err:
        find_pad(geoms, [0.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    assert err.value.field == "palmar"
    with pytest.raises(InputError) as err:
        find_pad(geoms, [0.0, 0.0, 1.0], [0.0, 0.0, 2.0])
    assert err.value.field == "distal"
