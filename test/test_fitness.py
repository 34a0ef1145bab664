"""Fitness of known grasps and the normal-wrench equilibrium residual."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize

from grasp_apso.quality import fitness as F
from grasp_apso.geometry.decoder import DecodedGrasps
from grasp_apso.model.hand import load_hand
from grasp_apso.model.builtin import builtin
from grasp_apso.search.planner import prepare
from grasp_apso.quality.measures import normal_wrench_residual

RADIUS = 0.025


@pytest.fixture(scope="module")
def sphere_model():
    return prepare(builtin("sphere"), load_hand())


def _decoded(points, contact, tip_gap=None, legal=True) -> DecodedGrasps:
    """Decoded grasps on the sphere with radial normals (P, 5, 3)."""
    points = np.asarray(points, dtype=float)
    p = len(points)
    normals = points / np.linalg.norm(points, axis=-1, keepdims=True)
    gap = np.zeros((p, 5)) if tip_gap is None else np.asarray(tip_gap, dtype=float)
    return DecodedGrasps(
        closed=np.zeros((p, 19)), wrist=np.tile(np.eye(4), (p, 1, 1)), joints=np.zeros((p, 5, 4, 3)),
        tip_gap=gap, contact=np.asarray(contact, dtype=bool), contact_points=points,
        contact_normals=normals, penetration=np.zeros((p, 5)), blocked=np.zeros((p, 5), bool),
        finger_collision=np.tile(~np.asarray(legal, bool).reshape(-1, 1), (1, 5)) & np.eye(5, dtype=bool)[0],
        palm_penetration=np.zeros(p), link_contact=np.zeros((p, 5), bool), palm_depth=np.zeros((p, 5)),
    )


def _ring(angles_deg, z=0.0):
    a = np.radians(angles_deg)
    pts = np.stack([np.cos(a), np.sin(a), np.full_like(a, z)], axis=-1)
    return RADIUS * pts / np.linalg.norm(pts, axis=-1, keepdims=True)


def test_regular_tripod_on_sphere_has_the_hand_computed_fitness(sphere_model):
    pts = np.zeros((1, 5, 3)) + [0, 0, RADIUS]
    pts[0, :3] = _ring([0, 120, 240])
    terms = F.evaluate(sphere_model, _decoded(pts, [[1, 1, 1, 0, 0]]), np.ones(1), mu=0.5)
    # Regular triangle: Q = 0; radial forces through the centre: balance residual 0 and
    # the squeeze along the normals balances: equilibrium 1; count (3 - 1) / 4.
    expected = F.W_SHAPE * 1 + F.W_BALANCE * 1 + F.W_EQUILIBRIUM * 1 + F.W_COUNT * 0.5 + F.W_FACTOR * 1
    assert terms.active[0]
    assert terms.shape[0] == pytest.approx(1.0, abs=1e-9)
    assert terms.balance[0] == pytest.approx(1.0, abs=1e-9)
    assert terms.equilibrium[0] == pytest.approx(1.0, abs=1e-6)
    assert terms.fitness[0] == pytest.approx(expected, abs=1e-6)
    assert expected == pytest.approx(0.9)


def test_more_and_better_spread_contacts_score_higher(sphere_model):
    pts = np.zeros((3, 5, 3)) + [0, 0, RADIUS]
    pts[0, :3] = _ring([0, 120, 240])            # regular tripod
    pts[1, :3] = _ring([0, 30, 60])              # bunched on one side
    pts[2, :4] = _ring([0, 90, 180, 270])        # regular square
    contact = [[1, 1, 1, 0, 0], [1, 1, 1, 0, 0], [1, 1, 1, 1, 0]]
    fit = F.evaluate(sphere_model, _decoded(pts, contact), np.ones(3), mu=0.5).fitness
    assert fit[2] > fit[0] > fit[1]
    assert fit[1] < 0.6  # bunched: no balance, no equilibrium


def test_inactive_particles_rank_below_active_and_point_toward_contact(sphere_model):
    pts = np.zeros((4, 5, 3)) + [0, 0, RADIUS]
    pts[:, :3] = _ring([0, 120, 240])
    contact = [[1, 1, 1, 0, 0], [1, 0, 0, 0, 0], [1, 0, 0, 0, 0], [1, 1, 1, 0, 0]]
    gaps = np.array([[0, 0, 0, 0.05, 0.05], [0, 0.01, 0.01, 0.05, 0.05], [0, 0.04, 0.04, 0.05, 0.05],
                     [0, 0, 0, 0.05, 0.05]])
    decoded = _decoded(pts, contact, gaps, legal=[True, True, True, False])
    terms = F.evaluate(sphere_model, decoded, np.ones(4), mu=0.5)
    assert terms.active.tolist() == [True, False, False, False]
    f = terms.fitness
    assert f[0] > 0 > -1 >= f[1] > f[2] > -2 >= f[3]
    assert np.isnan(terms.shape[1:]).all()


def _min_norm_reference(wrenches: np.ndarray) -> float:
    """Distance from the origin to conv(wrenches) with a general-purpose solver."""
    k = len(wrenches)
    res = minimize(
        lambda a: float(np.sum((a @ wrenches) ** 2)), np.full(k, 1.0 / k), method="SLSQP",
        bounds=[(0, 1)] * k, constraints=[{"type": "eq", "fun": lambda a: a.sum() - 1}],
        options={"ftol": 1e-14, "maxiter": 500},
    )
    return float(np.sqrt(max(res.fun, 0.0)))


def test_normal_wrench_residual_matches_a_general_solver():
    rng = np.random.default_rng(7)
    p, f = 40, 5
    pts = rng.normal(size=(p, f, 3))
    pts *= RADIUS / np.linalg.norm(pts, axis=-1, keepdims=True)
    normals = rng.normal(size=(p, f, 3)) * 0.3 + pts / RADIUS
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    mask = rng.random((p, f)) < 0.75
    mask[:, :2] = True
    got = normal_wrench_residual(pts, normals, mask, np.zeros(3), RADIUS)
    for i in range(p):
        n, q = -normals[i][mask[i]], pts[i][mask[i]]
        w = np.concatenate([n, np.cross(q, n) / RADIUS], axis=1)
        ref = min(1.0, _min_norm_reference(w))
        assert min(got[i], 1.0) == pytest.approx(ref, abs=2e-4), i


def test_normal_wrench_residual_known_cases():
    pts = np.zeros((3, 5, 3))
    mask = np.zeros((3, 5), bool)
    pts[0, :2] = [[RADIUS, 0, 0], [-RADIUS, 0, 0]]          # antipodal: balanced
    pts[1, :2] = _ring([0, 20])                              # same side: not balanced
    pts[2, :3] = _ring([0, 120, 240])                        # tripod: balanced
    mask[0, :2] = mask[1, :2] = mask[2, :3] = True
    normals = np.where(mask[..., None], pts / RADIUS, [0, 0, 1.0])
    r = normal_wrench_residual(pts, normals, mask, np.zeros(3), RADIUS)
    assert r[0] == pytest.approx(0.0, abs=1e-9)
    assert r[1] > 0.9
    assert r[2] == pytest.approx(0.0, abs=1e-9)
    with pytest.raises(ValueError, match="torque_scale"):
        normal_wrench_residual(pts, normals, mask, np.zeros(3), 0.0)


def test_every_contact_must_carry_load_in_the_equilibrium():
    # A grasp APSO returned on the cube (seed 4) that is not force closure: little and
    # thumb opposed along x, three fingers pushing +y with nothing pushing back. The
    # opposed pair alone balances, so without a minimum share the residual is ~0.
    pts = np.array([[-35.0, -31.4, -27.7], [-19.5, -35.0, 1.0], [6.9, -35.0, 8.1],
                    [35.0, -35.0, -17.7], [35.0, -31.5, -27.6]])[None] / 1000
    normals = np.array([[-1.0, 0, 0], [0, -1.0, 0], [0, -1.0, 0], [0.08, -1.0, 0], [1.0, 0, 0]])[None]
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    mask = np.ones((1, 5), bool)
    radius = float(builtin("cube").characteristic_radius)
    assert normal_wrench_residual(pts, normals, mask, np.zeros(3), radius)[0] < 0.005
    assert normal_wrench_residual(pts, normals, mask, np.zeros(3), radius, min_share=F.MIN_SHARE)[0] > 0.1
    # A balanced tripod keeps a zero residual with the minimum share.
    tri = np.zeros((1, 5, 3))
    tri[0, :3] = _ring([0, 120, 240])
    tri_mask = np.zeros((1, 5), bool)
    tri_mask[0, :3] = True
    tri_normals = np.where(tri_mask[..., None], tri / RADIUS, [0, 0, 1.0])
    assert normal_wrench_residual(tri, tri_normals, tri_mask, np.zeros(3), RADIUS, min_share=F.MIN_SHARE)[0] < 1e-9
    with pytest.raises(ValueError, match="min_share"):
        normal_wrench_residual(tri, tri_normals, tri_mask, np.zeros(3), RADIUS, min_share=1.0)
