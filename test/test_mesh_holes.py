"""Meshes with holes (issue 19, part 5): small holes are closed, so inside and outside are
known and every contact carries the outward normal; a mesh whose holes are too large to
close is refused, saying why; one whose hole cannot be closed (a rim that is not a simple
loop) stays open, its faces wound outward.

The reference is independent of the code under test: trimesh's face normals of the
closed mesh the holes were cut from.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from grasp_apso.errors import ObjectError
from grasp_apso.model.builtin import builtin
from grasp_apso.model.mesh_checks import MAX_HOLE_AREA, close_holes
from grasp_apso.model.objects import from_arrays
from grasp_apso.quality.measures import epsilon_quality
from grasp_apso.search.planner import PlanOptions, plan, prepare

EDGE = 0.07
BOX = trimesh.creation.box((EDGE, EDGE, EDGE))


def _without(mesh: trimesh.Trimesh, faces: np.ndarray):
    return from_arrays(mesh.vertices, np.delete(mesh.faces, faces, axis=0), name="holed")


def _reference_normals(closed: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    """Outward normals of the closed mesh's faces nearest to ``points``."""
    _, _, triangle = trimesh.proximity.closest_point(closed, points)
    return np.asarray(closed.face_normals)[triangle]


def _angles_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    cos = np.einsum("ij,ij->i", a, b) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _face_samples(closed: trimesh.Trimesh, seed: int, margin: float) -> np.ndarray:
    """Seeded surface samples at least ``margin`` from every edge of a box."""
    points, _ = trimesh.sample.sample_surface(closed, 4000, seed=seed)
    half = np.abs(points).max(axis=0)
    inner = np.sum(np.abs(points) > half - margin, axis=1) <= 1  # on one face only, away from its rim
    return points[inner][:300]


@pytest.mark.parametrize("holes", ["bottom face", "two faces"])
def test_normals_on_a_box_with_holes_are_those_of_the_closed_box(holes):
    if holes == "bottom face":
        cut = np.flatnonzero(BOX.face_normals[:, 2] < -0.9)          # a square hole
    else:
        cut = np.array([int(np.flatnonzero(BOX.face_normals[:, 2] < -0.9)[0]),
                        int(np.flatnonzero(BOX.face_normals[:, 0] > 0.9)[0])])  # two triangular holes
    assert len(cut) == 2
    obj = _without(BOX, cut)
    assert obj.watertight and obj.mesh.is_watertight
    assert obj.volume == pytest.approx(EDGE**3, rel=1e-9)
    np.testing.assert_allclose(obj.center_of_mass, BOX.center_mass, atol=1e-9)
    sdf = prepare(obj).sdf
    assert sdf.distance(np.zeros(3)) < -0.03                           # the centre is inside
    points = _face_samples(BOX, seed=1905, margin=0.004)
    _, normals = sdf.closest_surface_point(points)
    angles = _angles_deg(normals, _reference_normals(BOX, points))
    assert angles.max() < 3.0, angles.max()


def test_planned_grasps_on_the_holed_box_are_force_closure_with_outward_normals():
    """Before the holes were closed, 5 of these 25 contacts reported a normal pointing
    into the box (the face with the hole and its neighbours), and were called force closure."""
    cut = np.flatnonzero(BOX.face_normals[:, 1] > 0.9)                 # the +y face
    obj = _without(BOX, cut)
    result = plan(obj, options=PlanOptions(particles=30, iterations=20, max_grasps=5),
                  rng=np.random.default_rng(1906))
    assert len(result.candidates) >= 3
    for candidate in result.candidates:
        assert candidate.valid and candidate.force_closure and candidate.n_contacts >= 2
        points = np.array([c.position for c in candidate.contacts])
        normals = np.array([c.normal for c in candidate.contacts])
        reference = _reference_normals(BOX, points)
        assert _angles_deg(normals, reference).max() < 5.0, candidate.id
        eps, closure = epsilon_quality(points, reference, BOX.center_mass, mu=0.5, edges=8,
                                       torque_scale=float(obj.characteristic_radius))
        assert closure and eps > 0.0


def test_a_hole_in_a_curved_surface_is_capped_and_the_normals_stay_outward():
    sphere = builtin("sphere").mesh
    centres = np.asarray(sphere.triangles_center)
    cut = np.flatnonzero(centres[:, 2] > 0.8 * centres[:, 2].max())   # a polar cap of faces
    assert len(cut) > 10
    obj = _without(sphere, cut)
    assert obj.watertight
    points = _face_samples(sphere, seed=1906, margin=0.0)
    points = points[points[:, 2] < 0.6 * centres[:, 2].max()]           # away from the patched cap
    _, normals = prepare(obj).sdf.closest_surface_point(points)
    assert _angles_deg(normals, _reference_normals(sphere, points)).max() < 6.0


def test_inward_wound_faces_with_a_hole_are_turned_outward():
    cut = np.flatnonzero(BOX.face_normals[:, 2] < -0.9)
    inward = np.delete(BOX.faces, cut, axis=0)[:, ::-1]               # every face wound inward
    obj = from_arrays(BOX.vertices, inward)
    assert obj.watertight
    tops = np.asarray(obj.mesh.face_normals)[np.asarray(obj.mesh.triangles_center)[:, 2] > EDGE / 2 - 1e-9]
    np.testing.assert_allclose(tops, np.tile([0.0, 0.0, 1.0], (len(tops), 1)), atol=1e-9)


@pytest.mark.parametrize("wind", [1, -1])
def test_a_hole_too_large_to_close_is_refused_saying_why(wind):
    sphere = builtin("sphere").mesh
    upper = np.flatnonzero(np.asarray(sphere.triangles_center)[:, 2] > 0.0)   # a half shell: the cap adds ~50 %
    half = np.delete(sphere.faces, upper, axis=0)[:, ::wind]
    with pytest.raises(ObjectError, match=r"mesh: not closed, and its holes are too large to close .*would add \d+%.* at most "
                                          r"45%.*send a closed mesh"):
        from_arrays(sphere.vertices, half)
    assert MAX_HOLE_AREA == 0.45


def _fish_with_a_fin():
    """The fish with one face removed and a fin on an edge (three faces on it): its hole's
    rim is not a simple loop, so it stays open."""
    fish = builtin("fish").mesh
    faces = np.asarray(fish.faces)[1:]
    a, b = faces[0][0], faces[0][1]
    vertices = np.vstack([fish.vertices, np.asarray(fish.vertices)[[a, b]].mean(axis=0) + [0.0, 0.0, 0.01]])
    return fish, vertices, np.vstack([faces, [[a, b, len(vertices) - 1]]])


@pytest.mark.parametrize("wind", [1, -1])
def test_an_open_mesh_that_cannot_be_closed_is_wound_outward(wind):
    fish, vertices, faces = _fish_with_a_fin()
    obj = from_arrays(vertices, faces[:, ::wind])
    assert not obj.watertight and not close_holes(obj.mesh.copy())
    centres = np.asarray(obj.mesh.triangles_center)
    on_fish = np.abs(trimesh.proximity.signed_distance(fish, centres)) < 1e-6      # the fin aside
    reference = _reference_normals(fish, centres[on_fish])
    agree = np.einsum("ij,ij->i", np.asarray(obj.mesh.face_normals)[on_fish], reference) > 0.9
    assert agree.mean() > 0.99
