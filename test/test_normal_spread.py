"""The normal-spread grid (grasp_apso/geometry/normal_spread.py) and the fitness's penalty on
contacts at edges and corners (grasp_apso/quality/fitness.py, "Contacts on an ill-defined
normal")."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import trimesh

from grasp_apso.geometry.decoder import DecodedGrasps
from grasp_apso.geometry.normal_spread import build_normal_spread_grid
from grasp_apso.geometry.sdf import cached_sdf_grid
from grasp_apso.model.builtin import builtin
from grasp_apso.model.hand import load_hand
from grasp_apso.quality import fitness as F
from grasp_apso.search.planner import prepare

HALF = 0.035  # the built-in cube's half edge, m
ALPHA = np.degrees(np.arctan(0.5))  # friction cone half-angle at mu = 0.5, deg


@pytest.fixture(scope="module")
def cube_model():
    return prepare(builtin("cube"), load_hand())


@pytest.fixture(scope="module")
def sphere_model():
    return prepare(builtin("sphere"), load_hand())


def test_cube_face_centre_is_zero_edges_and_corners_are_large(cube_model):
    spread = np.degrees(cube_model.spread.spread(np.array([
        [HALF, 0, 0], [0, -HALF, 0.01], [0, 0, HALF],            # face centres
        [HALF, HALF, 0], [-HALF, 0, -HALF],                       # edges (45 deg exactly)
        [HALF, HALF, HALF], [-HALF, HALF, -HALF],                 # corners (55 deg exactly)
    ])))
    assert np.all(spread[:3] == 0.0)
    assert np.all(spread[3:] > ALPHA)
    assert np.all(spread[5:] > 45.0)


def test_sphere_tessellation_does_not_register_as_edges(sphere_model):
    points, _ = trimesh.sample.sample_surface(builtin("sphere").mesh, 2000, seed=3)
    spread = np.degrees(sphere_model.spread.spread(points))
    # curvature over 4 mm of a 25 mm sphere and its 1,280 facets: a few degrees, far
    # below where the fitness starts to count a contact as uncertain (alpha / 2)
    assert spread.max() < F.UNCERTAIN_FROM * ALPHA
    assert np.median(spread) > 0.0


def test_grid_is_deterministic_and_has_the_distance_grids_lattice():
    cube = builtin("cube")
    sdf = cached_sdf_grid(cube.mesh, cube.mesh_hash, padding=0.025)
    a, b = build_normal_spread_grid(cube.mesh, sdf), build_normal_spread_grid(cube.mesh, sdf)
    np.testing.assert_array_equal(a.values, b.values)
    assert a.values.shape == sdf.values.shape and a.spacing == sdf.spacing
    np.testing.assert_array_equal(a.origin, sdf.origin)
    assert not a.values.flags.writeable
    # far from the surface (the grid's corner) nothing is stored; non-finite points read 0
    assert a.values[0, 0, 0] == 0.0
    assert a.spread(np.array([[np.nan, 0.0, 0.0], [1.0, 1.0, 1.0]])).tolist() == [0.0, 0.0]


def _decoded(points, normals) -> DecodedGrasps:
    points, normals = np.asarray(points, float), np.asarray(normals, float)
    p = len(points)
    normals = normals / np.linalg.norm(normals, axis=-1, keepdims=True)
    return DecodedGrasps(
        closed=np.zeros((p, 19)), wrist=np.tile(np.eye(4), (p, 1, 1)), joints=np.zeros((p, 5, 4, 3)),
        tip_gap=np.zeros((p, 5)), contact=np.tile([True, True, True, True, False], (p, 1)),
        contact_points=points, contact_normals=normals, penetration=np.zeros((p, 5)),
        blocked=np.zeros((p, 5), bool), finger_collision=np.zeros((p, 5), bool), palm_penetration=np.zeros(p),
        link_contact=np.zeros((p, 5), bool), palm_depth=np.zeros((p, 5)),
    )


def _face_and_edge_sets():
    """Two square four-finger grasps around the cube's z axis: on the four side faces'
    centres, and on the four vertical edges (normals along the diagonals). Without the
    penalty both are regular, balanced and in equilibrium: the same fitness."""
    face = [[HALF, 0, 0], [0, HALF, 0], [-HALF, 0, 0], [0, -HALF, 0], [0, 0, HALF]]
    edge = [[HALF, HALF, 0], [-HALF, HALF, 0], [-HALF, -HALF, 0], [HALF, -HALF, 0], [0, 0, HALF]]
    points = np.array([face, edge])
    return _decoded(points, points / np.linalg.norm(points, axis=-1, keepdims=True))


def test_penalty_orders_face_centres_above_edges(cube_model):
    decoded = _face_and_edge_sets()
    plain = F.evaluate(replace(cube_model, spread=None), decoded, np.ones(2), mu=0.5)
    assert plain.fitness[0] == pytest.approx(plain.fitness[1], abs=1e-9)
    terms = F.evaluate(cube_model, decoded, np.ones(2), mu=0.5)
    assert terms.uncertain.tolist() == [0.0, 4.0]
    assert terms.fitness[0] > terms.fitness[1] + 0.3
    # face centres: exactly the fitness without the penalty (nothing uncertain)
    assert terms.fitness[0] == plain.fitness[0]
    # every contact uncertain: polygon, balance and equilibrium vanish, count halves
    assert terms.fitness[1] == pytest.approx(F.W_COUNT * (4 - 2 - 1) / 4 + F.W_FACTOR, abs=1e-9)
    again = F.evaluate(cube_model, decoded, np.ones(2), mu=0.5)
    np.testing.assert_array_equal(terms.fitness, again.fitness)


def test_uncertainty_ramps_with_the_friction_cone(cube_model):
    decoded = _face_and_edge_sets()
    # a high friction coefficient (alpha = 63 deg) makes the 45 deg edge partly certain
    e = F.contact_uncertainty(cube_model, decoded, mu=2.0)
    assert np.all(e[0] == 0.0)
    assert np.all((e[1, :4] > 0.0) & (e[1, :4] < 1.0)) and e[1, 4] == 0.0
    assert np.all(F.contact_uncertainty(cube_model, decoded, mu=0.5)[1, :4] == 1.0)
