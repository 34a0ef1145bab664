"""Contact robustness (grasp_apso.quality.robustness): the normal uncertainty is small on
a face and large at an edge or a corner; the robust epsilon never exceeds the epsilon."""

from __future__ import annotations

import math

import numpy as np
import pytest

from grasp_apso.model.builtin import builtin
from grasp_apso.quality.measures import epsilon_quality
from grasp_apso.quality.robustness import normal_uncertainty, robust_epsilon, robustness_score

H = 0.035  # half edge of the built-in cube (edge 0.07 m), centred at the origin
MU = 0.5


@pytest.fixture(scope="module")
def cube():
    return builtin("cube")


def _box_grasp(offset: float = 0.0):
    """Four contacts on four side faces of the cube (outward normals), the first one
    ``offset`` m from the face centre toward the top edge."""
    points = np.array([[H, 0.01, 0.005 + offset], [-H, -0.01, 0.0], [0.0, H, 0.01], [0.005, -H, -0.01]])
    normals = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0]])
    return points, normals


def test_flat_face_edge_and_corner(cube):
    points = np.array([[H, 0.0, 0.0],            # face centre
                       [H, 0.0, -0.02],          # on the face, 15 mm from the nearest edge
                       [H, H, 0.0],              # on an edge
                       [H, H, H],                # a corner
                       [H, H - 0.002, 0.0]])     # 2 mm from an edge, within the 4 mm radius
    u = normal_uncertainty(cube, points)
    assert u.shape == (5,)
    assert u[0] == pytest.approx(0.0, abs=1e-6) and u[1] == pytest.approx(0.0, abs=1e-6)
    # two faces at 90 degrees, equal weights: 45 degrees from their mean normal
    assert u[2] == pytest.approx(math.radians(45.0), abs=1e-6)
    # three faces: about 54.7 degrees (the triangulation weighs them a little unequally)
    assert math.radians(50.0) < u[3] < math.radians(56.0)
    # the other face is 2 mm away: it weighs (r^2 - d^2) / r^2 = 3/4, close to the edge value
    assert math.radians(40.0) < u[4] < math.radians(45.0)
    # both edge and corner exceed the friction cone half-angle atan(0.5) = 26.6 degrees
    assert np.all(u[2:] > math.atan(MU))


def test_uncertainty_grows_toward_the_edge_and_with_the_radius(cube):
    d = np.array([0.010, 0.004, 0.003, 0.002, 0.0])  # distance to the edge y = H, m
    points = np.column_stack([np.full(5, H), H - d, np.zeros(5)])
    u = normal_uncertainty(cube, points)
    assert u[0] == pytest.approx(0.0, abs=1e-9) and u[1] == pytest.approx(0.0, abs=1e-9)
    assert np.all(np.diff(u[1:]) > 0.0)
    wide = normal_uncertainty(cube, points[:1], radius=0.012)
    assert wide[0] > math.radians(20.0)  # a 12 mm neighbourhood reaches the edge 10 mm away


def test_smooth_sphere_is_nearly_certain():
    sphere = builtin("sphere")  # diameter 5 cm, icosphere: facets about 10 degrees apart
    rng = np.random.default_rng(0)
    d = rng.normal(size=(20, 3))
    u = normal_uncertainty(sphere, 0.025 * d / np.linalg.norm(d, axis=1, keepdims=True))
    assert np.all(u < math.radians(15.0)) and np.all(u > 0.0)


def test_robust_epsilon_equals_epsilon_without_uncertainty(cube):
    points, normals = _box_grasp()
    eps, fc = epsilon_quality(points, normals, cube.center_of_mass, MU, 8, cube.characteristic_radius)
    assert fc and eps > 0.01
    assert robust_epsilon(cube, points, normals, MU, np.zeros(4)) == pytest.approx(eps, rel=1e-9)
    # all four contacts lie mid-face: the computed uncertainty is 0, the same epsilon
    assert robust_epsilon(cube, points, normals, MU) == pytest.approx(eps, rel=1e-9)


def test_robust_epsilon_never_exceeds_epsilon(cube):
    points, normals = _box_grasp()
    eps, _ = epsilon_quality(points, normals, cube.center_of_mass, MU, 8, cube.characteristic_radius)
    rng = np.random.default_rng(3)
    values = [robust_epsilon(cube, points, normals, MU, u) for u in rng.uniform(0.0, 0.5, size=(20, 4))]
    assert max(values) <= eps + 1e-12
    # shrinking every cone further never raises the robust epsilon
    levels = [robust_epsilon(cube, points, normals, MU, np.full(4, a)) for a in (0.0, 0.1, 0.2, 0.3)]
    assert all(b <= a + 1e-12 for a, b in zip(levels, levels[1:]))
    assert levels[2] < 0.7 * levels[0]


def test_an_edge_contact_loses_its_force(cube):
    """The first contact moved onto the top edge: its uncertainty (45 deg) exceeds the
    friction cone (26.6 deg) and it is dropped: the three others keep under half the
    grasp's margin."""
    points, normals = _box_grasp(offset=H - 0.005)  # z = H: on the top edge
    score = robustness_score(cube, points, normals, MU)
    assert score["uncertainty"][0] == pytest.approx(math.radians(45.0), abs=1e-6)
    assert score["epsilon"] > 0.0
    assert 0.0 < score["margin"] < 0.8
    # a dropped contact contributes nothing, whatever its uncertainty beyond the cone
    beyond = [robust_epsilon(cube, points, normals, MU, np.array([u, 0.0, 0.0, 0.0])) for u in (0.47, 0.8, 1.5)]
    assert beyond[0] == beyond[1] == beyond[2] == score["robust_epsilon"]
    # dropping a mid-face contact instead (uncertainty 1 rad) lowers it as well
    assert robust_epsilon(cube, points, normals, MU, np.array([0.0, 0.0, 0.0, 1.0])) < score["epsilon"]
    # mid-face, the same grasp keeps its whole margin
    centred = robustness_score(cube, *_box_grasp(), MU)
    assert centred["margin"] == pytest.approx(1.0)


def test_deterministic_and_checked(cube):
    points, normals = _box_grasp(offset=0.02)
    first = robustness_score(cube, points, normals, MU)
    again = robustness_score(cube, points, normals, MU)
    assert np.array_equal(first["uncertainty"], again["uncertainty"])
    assert first["robust_epsilon"] == again["robust_epsilon"]
    with pytest.raises(ValueError):
        normal_uncertainty(cube, np.zeros((2, 2)))
    with pytest.raises(ValueError):
        normal_uncertainty(cube, points, radius=0.0)
    with pytest.raises(ValueError):
        robust_epsilon(cube, points, normals, MU, np.full(4, -0.1))


def test_the_quick_outside_test_leaves_every_value_as_the_hull_gives_it(cube):
    """Most fragile grasps are refused by the least-squares test before qhull: the values
    are those of the wrench hull itself (qhull on the shrunk cones), zero or not."""
    from scipy.spatial import ConvexHull

    from grasp_apso.quality.robustness import _shrunk_cone_wrenches

    rng = np.random.default_rng(11)
    com, scale = np.asarray(cube.center_of_mass, float), float(cube.characteristic_radius)
    zeros = positives = 0
    for _ in range(60):
        k = int(rng.integers(3, 5))
        normals = rng.normal(size=(k, 3))
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        points = H * normals
        unc = rng.uniform(0.0, 0.4, k)
        value = robust_epsilon(cube, points, normals, MU, unc)
        beta = math.atan(MU) - unc
        keep = beta >= 0.0
        expected = 0.0
        if keep.sum() >= 2:
            w = _shrunk_cone_wrenches(points[keep], normals[keep], com, MU, beta[keep], 8, scale)
            offsets = ConvexHull(w).equations[:, -1]
            expected = float(-offsets.max()) if np.all(offsets < 0.0) and -offsets.max() > 1e-9 else 0.0
        assert value == pytest.approx(expected, abs=1e-12)
        zeros += value == 0.0
        positives += value > 0.0
    assert zeros >= 10 and positives >= 10  # both kinds were drawn


@pytest.mark.parametrize('name', ['cube', 'barrel', 'mug'])
def test_the_closest_face_is_trimeshs_on_faces_edges_and_corners(name, monkeypatch):
    """The thin-wall filter's closest face (``_closest_faces``, from the prefilter's own
    distances) is the one ``trimesh.proximity.closest_point`` returns, for contacts on the
    surface, off it, inside it, and on edges and corners where two faces tie (there trimesh
    decides); the uncertainty is then the same as with trimesh's face."""
    import trimesh

    from grasp_apso.model.mesh_files import from_file
    from grasp_apso.quality import robustness

    obj = builtin(name) if name != 'mug' else from_file('grasp_apso/data/meshes/mug.stl')
    mesh = obj.mesh
    rng = np.random.default_rng(5)
    surface, _ = trimesh.sample.sample_surface(mesh, 600, seed=5)
    on_edges = mesh.vertices[mesh.edges_unique].mean(axis=1)[:200]
    points = np.concatenate([surface, surface + rng.normal(0.0, 0.002, surface.shape), on_edges,
                             mesh.vertices[:100]])
    tri, lo, hi = robustness._face_boxes(obj)
    r = robustness.DEFAULT_RADIUS
    near = np.all((points[:, None, :] >= lo[None] - r) & (points[:, None, :] <= hi[None] + r), axis=2)
    ci, fi = np.nonzero(near)
    closest = trimesh.triangles.closest_point(tri[fi], points[ci])
    d2 = np.einsum('ij,ij->i', closest - points[ci], closest - points[ci])
    expected = trimesh.proximity.closest_point(mesh, points)[2]
    asked = []  # the contacts trimesh is asked about (it still answers them)
    query = trimesh.proximity.closest_point
    monkeypatch.setattr(trimesh.proximity, 'closest_point', lambda m, p: asked.append(len(p)) or query(m, p))
    faces = robustness._closest_faces(mesh, points, ci, fi, d2, r)
    np.testing.assert_array_equal(faces, expected)
    # the edges and corners tie, and a few contacts lie deep inside (no face within r):
    # trimesh decides those; the shortcut the rest
    assert 0 < sum(asked) < 0.35 * len(points), (sum(asked), len(points))
