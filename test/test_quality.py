"""Tests for grasp_apso.quality.measures: polygon shape (eq. 8-10), antipodality, force balance
(eq. 11-12) and the Ferrari-Canny epsilon quality. Known answers are computed by hand in the
tests; batch functions are checked against an independent per-particle reference."""

from __future__ import annotations

import math
import warnings
from itertools import combinations
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from grasp_apso.quality.measures import (
    antipodal_score,
    epsilon_quality,
    epsilon_quality_batch,
    force_balance_residual,
    polygon_shape_q,
)

R_SPHERE = 0.025  # m, the paper's 5 cm sphere
F = 5

# contact sets on the sphere, (colatitude, azimuth) in degrees
EQ3 = [(90, 0), (90, 120), (90, 240)]
EQ3_POLE = EQ3 + [(0, 0)]
TETRA = [(0, 0)] + [(math.degrees(math.acos(-1 / 3)), a) for a in (0, 120, 240)]
BUNCHED = [(75, 0), (75, 120), (75, 240), (0, 0)]  # all four in the upper cap


# ------------------------------------------------------------------------------------------
# helpers
# ------------------------------------------------------------------------------------------
def regular_polygon(n: int, radius: float = 0.03) -> np.ndarray:
    a = 2.0 * np.pi * np.arange(n) / n + 0.3
    return np.stack([radius * np.cos(a), radius * np.sin(a), np.zeros(n)], axis=1)


def place(pts2d_or_3d: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Random rotation + translation of planar points (given in the xy plane)."""
    rot = Rotation.random(random_state=rng).as_matrix()
    return pts2d_or_3d @ rot.T + rng.uniform(-0.5, 0.5, 3)


def one(points: np.ndarray, nslots: int = F, fill: float = np.nan, rng=None):
    """Pack nc contacts into a (1, nslots, 3) batch; other slots hold `fill`; random slots."""
    nc = len(points)
    out = np.full((1, nslots, 3), fill)
    mask = np.zeros((1, nslots), dtype=bool)
    slots = np.arange(nc) if rng is None else rng.permutation(nslots)[:nc]
    out[0, slots] = points
    mask[0, slots] = True
    return out, mask


def pack(pts: np.ndarray, nrm: np.ndarray, rng: np.random.Generator):
    """Contacts and normals in random slots of a (1, F, 3) batch, NaN elsewhere."""
    slots = rng.permutation(F)[: len(pts)]
    points = np.full((1, F, 3), np.nan)
    normals = np.full((1, F, 3), np.nan)
    mask = np.zeros((1, F), dtype=bool)
    points[0, slots], normals[0, slots], mask[0, slots] = pts, nrm, True
    return points, normals, mask


def sphere_grasp(angles_deg, radius: float = R_SPHERE):
    """Contacts on a sphere centred at the origin; angles are (colatitude, azimuth) degrees."""
    t = np.radians([a[0] for a in angles_deg])
    p = np.radians([a[1] for a in angles_deg])
    n = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=1)
    return radius * n, n


def reference_q(pts: np.ndarray) -> float:
    """Straightforward single-grasp eq. 8-10 (SVD plane, arccos angles, convexity test)."""
    nc = len(pts)
    if nc < 3:
        return math.nan
    c = pts - pts.mean(axis=0)
    _, _, vt = np.linalg.svd(c)
    xy = c @ vt[:2].T
    xy = xy[np.argsort(np.arctan2(xy[:, 1], xy[:, 0]))]
    theta = []
    for i in range(nc):
        prev, cur, nxt = xy[i - 1], xy[i], xy[(i + 1) % nc]
        a, b = prev - cur, nxt - cur
        cos_alpha = a @ b / np.linalg.norm(a) / np.linalg.norm(b)
        alpha = math.degrees(math.acos(np.clip(cos_alpha, -1.0, 1.0)))
        e_in, e_out = cur - prev, nxt - cur
        left_turn = e_in[0] * e_out[1] - e_in[1] * e_out[0] >= 0.0
        theta.append(alpha if left_turn else 360.0 - alpha)
    tbar = 180.0 * (nc - 2) / nc
    tmax = (nc - 2) * (180.0 - tbar) + 2 * tbar
    return min(1.0, sum(abs(t - tbar) for t in theta) / tmax)


def random_batch(rng: np.random.Generator, p: int = 60):
    points = rng.uniform(-0.05, 0.05, (p, F, 3))
    normals = rng.normal(size=(p, F, 3))
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    mask = rng.random((p, F)) < 0.6
    mask[:6] = False  # make sure every nc = 0..5 occurs
    for k in range(6):
        mask[k, :k] = True
    points[~mask] = np.nan  # masked slots must never be read
    normals[~mask] = np.nan
    return points, normals, mask


# ------------------------------------------------------------------------------------------
# polygon shape
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("n", [3, 4, 5])
def test_regular_polygon_is_zero_in_any_plane(n):
    rng = np.random.default_rng(n)
    for _ in range(10):
        pts = place(regular_polygon(n), rng)
        q = polygon_shape_q(*one(pts, rng=rng))
        assert q.shape == (1,)
        assert abs(q[0]) < 1e-9


@pytest.mark.parametrize("n", [3, 4, 5])
def test_regular_polygon_with_out_of_plane_noise(n):
    rng = np.random.default_rng(10 + n)
    for _ in range(10):
        flat = regular_polygon(n)
        flat[:, 2] += rng.normal(0.0, 3e-5, n)  # 0.1 % of the 3 cm radius, off the plane
        flat[:, :2] += rng.normal(0.0, 1e-6, (n, 2))
        q = polygon_shape_q(*one(place(flat, rng), rng=rng))
        assert 0.0 <= q[0] < 1e-3


def test_isoceles_right_triangle_hand_value():
    pts = np.array([[0.0, 0.0, 0.0], [0.04, 0.0, 0.0], [0.0, 0.04, 0.0]])
    # angles 90, 45, 45; theta_bar = 60; theta_max = (3-2)(180-60) + 2*60 = 240
    expected = (abs(90 - 60) + abs(45 - 60) + abs(45 - 60)) / 240.0
    assert expected == pytest.approx(0.25)
    rng = np.random.default_rng(1)
    q = polygon_shape_q(*one(place(pts, rng)))
    assert q[0] == pytest.approx(expected, abs=1e-12)


def test_rectangle_scores_as_regular_angles_only():
    # eq. 8 looks at angles only: a 2:1 rectangle has four 90-degree angles, Q = 0.
    pts = np.array([[0.0, 0.0, 0.0], [0.06, 0.0, 0.0], [0.06, 0.03, 0.0], [0.0, 0.03, 0.0]])
    assert polygon_shape_q(*one(pts))[0] == pytest.approx(0.0, abs=1e-12)


def test_non_convex_ordering_uses_reflex_angle():
    # Dart C-D-A-B (ordered by angle around the centroid (0, 0.3)); reflex vertex at D.
    pts = np.array([[2.0, 0.0, 0], [0.0, 1.0, 0], [-2.0, 0.0, 0], [0.0, 0.2, 0]]) * 0.01
    d = 180.0 + 2.0 * math.degrees(math.atan(0.1))  # reflex internal angle at D
    a = math.degrees(math.atan(0.5) - math.atan(0.1))  # at A and at C
    b = 2.0 * math.degrees(math.atan(2.0))  # at B
    assert d + 2 * a + b == pytest.approx(360.0)
    expected = (abs(d - 90) + 2 * abs(a - 90) + abs(b - 90)) / 360.0
    q = polygon_shape_q(*one(pts))[0]
    assert q == pytest.approx(expected, abs=1e-12)
    assert q == pytest.approx(0.76827, abs=1e-4)


def test_flat_triangle_is_close_to_one():
    pts = np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [0.025, 5e-5, 0.0]])
    q = polygon_shape_q(*one(pts))[0]
    assert q > 0.9
    # angles about 179.77, 0.11, 0.11 -> Q = (119.77 + 2 * 59.89) / 240
    small = math.degrees(math.atan(5e-5 / 0.025))
    expected = (abs(180 - 2 * small - 60) + 2 * abs(small - 60)) / 240
    assert q == pytest.approx(expected, abs=1e-9)


def test_exactly_collinear_points_are_worst():
    pts = np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [0.02, 0.0, 0.0], [0.04, 0.0, 0.0]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        q = polygon_shape_q(*one(pts))[0]
    assert q > 0.9


@pytest.mark.parametrize(
    "pts",
    [
        [[0, 0, 0], [0, 0, 0], [0.03, 0, 0]],  # two contacts at the same place
        [[0.01, 0.02, 0.03]] * 3,  # all at one point
        [[0, 0, 0], [0.03, 0, 0], [0, 0.03, 0], [0.03, 0, 0], [0.03, 0.03, 0]],
    ],
)
def test_coincident_points_are_worst_without_warnings(pts):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        q = polygon_shape_q(*one(np.asarray(pts, dtype=float)))
    assert q[0] == 1.0


def test_order_of_points_does_not_matter():
    rng = np.random.default_rng(2)
    for n in (3, 4, 5):
        for _ in range(20):
            pts = rng.uniform(-0.03, 0.03, (n, 3))
            q0 = polygon_shape_q(*one(pts))[0]
            for _ in range(3):
                q1 = polygon_shape_q(*one(pts[rng.permutation(n)], rng=rng))[0]
                assert q1 == pytest.approx(q0, abs=1e-9)


def test_masked_out_fingers_are_ignored():
    rng = np.random.default_rng(3)
    pts = place(regular_polygon(3), rng)
    for fill in (np.nan, np.inf, 0.0, 123.0):
        points, mask = one(pts, fill=fill, rng=rng)
        assert abs(polygon_shape_q(points, mask)[0]) < 1e-9


def test_fewer_than_three_contacts_is_nan():
    points = np.zeros((3, F, 3))
    mask = np.zeros((3, F), dtype=bool)
    mask[1, 0] = True
    mask[2, :2] = True
    points[2, 1] = [0.01, 0, 0]
    assert np.isnan(polygon_shape_q(points, mask)).all()


def test_polygon_batch_matches_reference_and_single_particle_loop():
    rng = np.random.default_rng(4)
    points, _, mask = random_batch(rng, 200)
    q = polygon_shape_q(points, mask)
    nc = mask.sum(1)
    assert q.shape == (200,)
    assert np.isnan(q[nc < 3]).all()
    assert ((q[nc >= 3] >= 0) & (q[nc >= 3] <= 1)).all()
    for i in range(len(q)):
        single = polygon_shape_q(points[i : i + 1], mask[i : i + 1])[0]
        ref = reference_q(points[i][mask[i]])
        if nc[i] < 3:
            assert np.isnan(single) and np.isnan(ref)
        else:
            assert single == pytest.approx(q[i], abs=1e-12)
            assert ref == pytest.approx(q[i], abs=1e-9)


# ------------------------------------------------------------------------------------------
# antipodality
# ------------------------------------------------------------------------------------------
def test_antipodal_perfect_pinch_is_one_in_any_pose():
    rng = np.random.default_rng(5)
    p, n = sphere_grasp([(90, 0), (90, 180)])
    for _ in range(5):
        rot = Rotation.random(random_state=rng).as_matrix()
        pts = p @ rot.T + rng.uniform(-1, 1, 3)
        nrm = n @ rot.T
        assert antipodal_score(*pack(pts, nrm, rng))[0] == pytest.approx(1.0, abs=1e-12)


def test_antipodal_same_side_hand_value_and_symmetry():
    p, n = sphere_grasp([(90, 0), (90, 20)])
    expected = ((1 - math.cos(math.radians(20))) / 2 + 2 * math.sin(math.radians(10))) / 3
    s = antipodal_score(*[a[None] for a in (p, n)], np.ones((1, 2), dtype=bool))[0]
    assert s == pytest.approx(expected, abs=1e-12)
    assert s < 0.2
    s_swapped = antipodal_score(p[None, ::-1], n[None, ::-1], np.ones((1, 2), dtype=bool))[0]
    assert s_swapped == pytest.approx(s, abs=1e-12)


def test_antipodal_bad_cases():
    mask = np.ones((1, 2), dtype=bool)
    p = np.array([[[0.0, 0, 0], [0.05, 0, 0]]])
    # both normals the same, perpendicular to the line: 0
    assert antipodal_score(p, np.array([[[0, 0, 1.0], [0, 0, 1.0]]]), mask)[0] == pytest.approx(0.0)
    # normals pointing at each other (expansion) gets only the "opposed" third
    expanding = np.array([[[1.0, 0, 0], [-1.0, 0, 0]]])
    assert antipodal_score(p, expanding, mask)[0] == pytest.approx(1 / 3)
    # coincident contacts: 0, no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        s = antipodal_score(np.zeros((1, 2, 3)), np.array([[[1.0, 0, 0], [-1.0, 0, 0]]]), mask)
    assert s[0] == 0.0


def test_antipodal_nan_unless_two_contacts_and_batch_matches_loop():
    rng = np.random.default_rng(6)
    points, normals, mask = random_batch(rng, 100)
    s = antipodal_score(points, normals, mask)
    nc = mask.sum(1)
    assert np.isnan(s[nc != 2]).all()
    assert ((s[nc == 2] >= 0) & (s[nc == 2] <= 1)).all()
    for i in np.flatnonzero(nc == 2):
        (p1, p2), (n1, n2) = points[i][mask[i]], normals[i][mask[i]]
        u = (p2 - p1) / np.linalg.norm(p2 - p1)
        ref = ((1 - n1 @ n2) / 2 + max(0.0, -n1 @ u) + max(0.0, n2 @ u)) / 3
        assert s[i] == pytest.approx(ref, abs=1e-12)


# ------------------------------------------------------------------------------------------
# force balance
# ------------------------------------------------------------------------------------------
def test_force_balance_known_cases():
    com = np.zeros(3)
    eq3, _ = sphere_grasp([(90, 0), (90, 120), (90, 240)])
    assert force_balance_residual(*one(eq3), com)[0] == pytest.approx(0.0, abs=1e-12)
    opposite, _ = sphere_grasp([(90, 0), (90, 180)])
    assert force_balance_residual(*one(opposite), com)[0] == pytest.approx(0.0, abs=1e-12)
    same_side, _ = sphere_grasp([(90, 0), (90, 20)])
    r = force_balance_residual(*one(same_side), com)[0]
    assert r == pytest.approx(math.cos(math.radians(10)), abs=1e-12)  # |v1 + v2| / 2
    assert r > 0.95
    single, _ = sphere_grasp([(30, 40)])
    assert force_balance_residual(*one(single), com)[0] == pytest.approx(1.0)
    tetra, _ = sphere_grasp(TETRA)
    assert force_balance_residual(*one(tetra), com)[0] == pytest.approx(0.0, abs=1e-12)


def test_force_balance_translation_invariant_and_nc_zero():
    rng = np.random.default_rng(7)
    eq3, _ = sphere_grasp([(90, 0), (90, 120), (90, 240)])
    shift = np.array([0.3, -0.2, 1.0])
    points, mask = one(eq3 + shift, rng=rng)
    assert force_balance_residual(points, mask, shift)[0] == pytest.approx(0.0, abs=1e-12)
    empty = np.full((2, F, 3), np.nan)
    assert (force_balance_residual(empty, np.zeros((2, F), dtype=bool), np.zeros(3)) == 1.0).all()


def test_force_balance_batch_matches_loop():
    rng = np.random.default_rng(8)
    points, _, mask = random_batch(rng, 100)
    com = np.array([0.001, -0.002, 0.003])
    r = force_balance_residual(points, mask, com)
    assert r.shape == (100,)
    assert ((r >= 0) & (r <= 1)).all()
    for i in range(100):
        p = points[i][mask[i]]
        if len(p) == 0:
            assert r[i] == 1.0
            continue
        v = (com - p) / np.linalg.norm(com - p, axis=1, keepdims=True)
        assert r[i] == pytest.approx(np.linalg.norm(v.sum(0)) / len(p), abs=1e-12)


# ------------------------------------------------------------------------------------------
# Ferrari-Canny epsilon
# ------------------------------------------------------------------------------------------
def eps_of(angles, **kw):
    p, n = sphere_grasp(angles)
    return epsilon_quality(p, n, np.zeros(3), **kw)


def test_epsilon_force_closure_configurations():
    for cfg in (EQ3_POLE, TETRA):
        eps, fc = eps_of(cfg)
        assert fc is True and isinstance(eps, float) and eps > 0.1
    eps_tet, _ = eps_of(TETRA)
    eps_bunched, fc_bunched = eps_of(BUNCHED)
    assert fc_bunched  # friction still holds it ...
    assert eps_tet > 2 * eps_bunched > 0  # ... but far less robustly than the tetrahedron
    assert eps_tet > eps_of(EQ3_POLE)[0]


def test_epsilon_three_frictional_contacts_on_equator():
    # Three contacts at 120 degrees on a great circle: the normal forces all pass through the
    # centre, yet with friction (mu = 0.5) tangential forces resist every torque, so the grasp
    # IS force closure (measured epsilon about 0.247 with 8 cone edges). As mu -> 0 the
    # tangential forces vanish and epsilon drops to 0 roughly linearly in mu.
    eps, fc = eps_of(EQ3, mu=0.5)
    assert fc and eps == pytest.approx(0.2468, abs=1e-3)
    mus = [0.05, 0.1, 0.2, 0.5, 1.0]
    values = [eps_of(EQ3, mu=m)[0] for m in mus]
    assert all(a < b for a, b in zip(values, values[1:]))
    assert values[0] < 0.03
    assert all(eps_of(EQ3, mu=m)[1] for m in mus)


def test_epsilon_not_force_closure_cases_never_raise():
    assert eps_of([(90, 0), (90, 20)]) == (0.0, False)  # same side
    assert eps_of([(90, 0), (90, 180)]) == (0.0, False)  # antipodal: free spin about axis
    assert eps_of([(90, 0)]) == (0.0, False)
    assert eps_of([(60, a) for a in (0, 90, 180, 270)]) == (0.0, False)  # cap: lifts off
    # three collinear contacts with parallel normals (a flat face): rank deficient
    p = np.array([[0.0, 0, 0], [0.01, 0, 0], [0.02, 0, 0]])
    n = np.tile([0.0, 0.0, 1.0], (3, 1))
    assert epsilon_quality(p, n, np.array([0.01, 0, -0.01])) == (0.0, False)
    assert epsilon_quality(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(3)) == (0.0, False)
    # all contacts at the centre of mass: no torque scale
    assert epsilon_quality(np.zeros((3, 3)), np.eye(3), np.zeros(3)) == (0.0, False)


def test_epsilon_invariances():
    rng = np.random.default_rng(9)
    p, n = sphere_grasp(TETRA)
    eps0, _ = epsilon_quality(p, n, np.zeros(3))
    # translation of the whole grasp: exact
    t = rng.uniform(-1, 1, 3)
    assert epsilon_quality(p + t, n, t)[0] == pytest.approx(eps0, rel=1e-9)
    # rotation: the pyramid's phase about each cone axis follows a fixed helper axis, so the
    # linearised cones do not rotate exactly with the grasp; the effect shrinks with edges
    rot = Rotation.random(random_state=rng).as_matrix()
    fine = epsilon_quality(p, n, np.zeros(3), edges=16)[0]
    fine_rot = epsilon_quality(p @ rot.T + t, n @ rot.T, t, edges=16)[0]
    assert fine_rot == pytest.approx(fine, rel=1.5e-2)  # measured <= 0.8 % (2.8 % at 8 edges)
    coarse_rot = epsilon_quality(p @ rot.T + t, n @ rot.T, t)[0]
    assert coarse_rot == pytest.approx(eps0, rel=0.05)
    # contact order
    perm = rng.permutation(len(p))
    assert epsilon_quality(p[perm], n[perm], np.zeros(3))[0] == pytest.approx(eps0, rel=1e-9)
    # uniform scale with the torque scale scaled too; default torque scale = radius here
    assert epsilon_quality(10 * p, n, np.zeros(3), torque_scale=10 * R_SPHERE)[0] == pytest.approx(
        eps0, rel=1e-9
    )
    explicit = epsilon_quality(p, n, np.zeros(3), torque_scale=R_SPHERE)[0]
    assert explicit == pytest.approx(eps0, rel=1e-12)
    # normals need not be unit on input
    assert epsilon_quality(p, 3 * n, np.zeros(3))[0] == pytest.approx(eps0, rel=1e-12)


def _independent_wrenches(p, n, mu, edges, scale):
    """Primitive wrenches built one by one (same edge phase convention as the module: the
    first tangent is axis x e_x, or axis x e_y when the axis is within 26 deg of x)."""
    out = []
    for pi, ni in zip(p, n):
        axis = -ni / np.linalg.norm(ni)
        t1 = np.cross(axis, [1.0, 0, 0] if abs(axis[0]) < 0.9 else [0, 1.0, 0])
        t1 /= np.linalg.norm(t1)
        t2 = np.cross(axis, t1)
        for k in range(edges):
            phi = 2 * np.pi * k / edges
            f = axis + mu * (np.cos(phi) * t1 + np.sin(phi) * t2)
            f /= np.linalg.norm(f)
            out.append(np.concatenate([f, np.cross(pi, f) / scale]))
    return np.array(out)


def _brute_force_epsilon(w: np.ndarray) -> float:
    """Exact L1 epsilon without qhull: enumerate every 6-subset of primitive wrenches, take the
    hyperplane a.x = 1 through it (the origin is inside, so no facet passes through it) and
    keep it when every wrench satisfies a.x <= 1; epsilon = min over those of 1 / |a|."""
    subsets = np.array(list(combinations(range(len(w)), 6)))
    mats = w[subsets]  # (S, 6, 6)
    ok = np.abs(np.linalg.det(mats)) > 1e-12
    a = np.linalg.solve(mats[ok], np.ones((int(ok.sum()), 6, 1)))[..., 0]
    facet = (a @ w.T <= 1.0 + 1e-9).all(axis=1)
    return float((1.0 / np.linalg.norm(a[facet], axis=1)).min())


@pytest.mark.parametrize("cfg", [EQ3, TETRA, BUNCHED, EQ3_POLE])
def test_epsilon_matches_brute_force_facet_enumeration(cfg):
    p, n = sphere_grasp(cfg)
    edges = 4  # keeps the 6-subset enumeration small (16 wrenches -> 8008 subsets)
    eps, fc = epsilon_quality(p, n, np.zeros(3), edges=edges, torque_scale=R_SPHERE)
    w = _independent_wrenches(p, n, 0.5, edges, R_SPHERE)
    assert fc
    assert eps == pytest.approx(_brute_force_epsilon(w), rel=1e-9)
    # and the ball of radius eps is inside the hull: support h(d) >= eps in every direction
    d = np.random.default_rng(11).normal(size=(20_000, 6))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    assert (d @ w.T).max(axis=1).min() >= eps * (1 - 1e-12)


def test_epsilon_batch_matches_single():
    rng = np.random.default_rng(12)
    configs = [TETRA, EQ3_POLE, [(90, 0), (90, 180)], EQ3, [(90, 0)], []]
    points = np.full((len(configs), F, 3), np.nan)
    normals = np.full_like(points, np.nan)
    mask = np.zeros((len(configs), F), dtype=bool)
    for i, cfg in enumerate(configs):
        if cfg:
            p, n = sphere_grasp(cfg)
            slots = rng.permutation(F)[: len(cfg)]
            points[i, slots], normals[i, slots], mask[i, slots] = p, n, True
    eps, fc = epsilon_quality_batch(points, normals, mask, np.zeros(3))
    assert eps.shape == fc.shape == (len(configs),) and fc.dtype == bool
    for i, cfg in enumerate(configs):
        p, n = sphere_grasp(cfg) if cfg else (np.zeros((0, 3)), np.zeros((0, 3)))
        assert (eps[i], fc[i]) == pytest.approx(epsilon_quality(p, n, np.zeros(3)))
    assert fc.tolist() == [True, True, False, True, False, False]


# ------------------------------------------------------------------------------------------
# validation
# ------------------------------------------------------------------------------------------
def test_epsilon_parameter_validation():
    p, n = sphere_grasp(TETRA)
    com = np.zeros(3)
    for bad in (0.0, -0.5, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="^mu"):
            epsilon_quality(p, n, com, mu=bad)
    for bad in (2, 0, 3.5, True):
        with pytest.raises(ValueError, match="^edges"):
            epsilon_quality(p, n, com, edges=bad)
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="^torque_scale"):
            epsilon_quality(p, n, com, torque_scale=bad)
    with pytest.raises(ValueError, match=r"^points: expected \(nc, 3\)"):
        epsilon_quality(p[:, :2], n, com)
    with pytest.raises(ValueError, match="^normals"):
        epsilon_quality(p, n[:3], com)
    with pytest.raises(ValueError, match="^normals"):
        epsilon_quality(p, np.zeros_like(n), com)
    with pytest.raises(ValueError, match="^com"):
        epsilon_quality(p, n, np.zeros(2))
    with pytest.raises(ValueError, match="^points"):
        epsilon_quality(np.where(np.eye(4, 3, dtype=bool), np.nan, p), n, com)
    with pytest.raises(ValueError, match="^mu"):
        epsilon_quality_batch(p[None], n[None], np.ones((1, 4), dtype=bool), com, mu=0)


def test_batch_shape_validation():
    pts = np.zeros((2, F, 3))
    mask = np.ones((2, F), dtype=bool)
    with pytest.raises(ValueError, match=r"^points: expected \(P, F, 3\), got \(2, 3\)"):
        polygon_shape_q(np.zeros((2, 3)), mask)
    with pytest.raises(ValueError, match="^mask"):
        polygon_shape_q(pts, np.ones((2, 4), dtype=bool))
    with pytest.raises(ValueError, match="^mask: expected a boolean"):
        force_balance_residual(pts, np.ones((2, F)), np.zeros(3))
    with pytest.raises(ValueError, match="^com"):
        force_balance_residual(pts, mask, np.zeros((1, 3)))
    with pytest.raises(ValueError, match="^normals"):
        antipodal_score(pts, np.zeros((2, F, 2)), mask)
    with pytest.raises(ValueError, match="^points"):
        polygon_shape_q(np.full((2, F, 3), np.nan), mask)
    with pytest.raises(ValueError, match="^points"):
        force_balance_residual(np.full((2, F, 3), np.inf), mask, np.zeros(3))
    with pytest.raises(ValueError, match="^points"):
        polygon_shape_q([["a"]], mask)


def test_cheap_outside_test_never_rejects_a_force_closure_grasp():
    """The non-negative least squares screen before qhull: on random contact sets (half
    of them force closure) it rejects only sets whose hull misses the origin, and most
    of those (it is what makes screening runner-up grasps cheap)."""
    from scipy.spatial import ConvexHull

    from grasp_apso.quality import measures

    rng = np.random.default_rng(11)
    rejected_outside = outside = 0
    for _ in range(400):
        k = int(rng.integers(2, 6))
        pts = rng.normal(size=(k, 3))
        pts /= np.linalg.norm(pts, axis=1, keepdims=True)
        if rng.random() < 0.5:  # contacts on one side only: rarely force closure
            pts[:, 0] = np.abs(pts[:, 0]) + 0.2
        normals = pts + rng.normal(scale=0.2, size=pts.shape)
        wrenches = measures._cone_wrenches(pts * 0.03, normals / np.linalg.norm(normals, axis=1, keepdims=True),
                                           np.zeros(3), 0.5, 8, 0.03)
        try:
            eq = ConvexHull(wrenches).equations
            origin_inside = bool(np.all(eq[:, -1] < 0.0))
        except Exception:  # flat wrench set: the origin is not strictly inside
            origin_inside = False
        may = measures.origin_may_be_inside(wrenches)
        if origin_inside:
            assert may
        else:
            outside += 1
            rejected_outside += not may
    assert outside > 100
    assert rejected_outside / outside > 0.9


def test_epsilon_without_facet_merging_equals_qhulls_default():
    """hull_only_epsilon builds the hull without facet merging (FAST_HULL_OPTIONS, about 3x
    faster in 6-D) and falls back to qhull's default where that raises: the value is the
    default hull's on random grasps of 3-5 contacts (some with a contact given twice, which
    the unmerged build still handles), on two saved wrench sets of planned grasps that make
    the unmerged build raise, and 0 where every normal is parallel."""
    from scipy.spatial import ConvexHull, QhullError

    from grasp_apso.quality.measures import FAST_HULL_OPTIONS, closure_wrenches, hull_only_epsilon

    def default(w):
        try:
            off = ConvexHull(w).equations[:, -1]
        except (QhullError, ValueError):
            return 0.0
        return float(-off.max()) if np.all(off < 0.0) else 0.0

    rng = np.random.default_rng(21)
    compared = positive = 0
    for trial in range(60):
        k = int(rng.integers(3, 6))
        n = rng.normal(size=(k, 3))
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        p = R_SPHERE * n
        if trial % 10 == 0:  # degenerate: a contact given twice
            p, n = np.vstack([p, p[:1]]), np.vstack([n, n[:1]])
        w = closure_wrenches(p, n, np.zeros(3), 0.5, torque_scale=R_SPHERE)
        if w is None:
            continue
        value, expected = hull_only_epsilon(w), default(w)
        assert value == pytest.approx(expected, abs=1e-12), trial
        compared += 1
        positive += expected > 0.0
    assert compared >= 50 and positive >= 10
    # Two wrench sets of grasps the planner returned (objects on a table) on which the
    # unmerged build raises a precision error: the default decides, the first force closure.
    data = np.load(Path(__file__).parent / "data" / "qhull_unmerged_precision_errors.npz")
    for name in ("concave", "flat"):
        with pytest.raises(QhullError):
            ConvexHull(data[name], qhull_options=FAST_HULL_OPTIONS)
        assert hull_only_epsilon(data[name]) == pytest.approx(default(data[name]), abs=1e-12)
    assert hull_only_epsilon(data["concave"]) == pytest.approx(0.0456, abs=1e-4)
    # every normal parallel (a flat face): no 6-D ball, whichever build decides
    p = np.column_stack([rng.uniform(-0.02, 0.02, (4, 2)), np.zeros(4)])
    w = closure_wrenches(p, np.tile([0.0, 0.0, 1.0], (4, 1)), np.zeros(3), 0.5, torque_scale=R_SPHERE)
    assert hull_only_epsilon(w) == 0.0
