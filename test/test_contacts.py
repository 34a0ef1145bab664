"""Tests for grasp_apso.geometry.decoder (decoding particles: wrist placement, closing the fingers,
contacts) and grasp_apso.geometry.collision, on the built-in objects.

Geometry is checked against analytic shapes (the built-in sphere and cube are centred on
their centre of mass) and against python-fcl, not against the signed-distance grid the
decoder uses. Decisions read the grid, whose error on these shapes stays below about
0.7 mm (test_sdf.py); GRID_ALLOWANCE covers it where an analytic value is compared with
a decision threshold."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from grasp_apso.geometry import collision
from grasp_apso.geometry import decoder as contacts_module
from grasp_apso.geometry.collision import finger_collisions, segment_distances, verify_with_fcl
from grasp_apso.geometry.decoder import N_DIMS, STANDOFF_INDEX, decode, make_grasp_model, wrist_transforms
from grasp_apso.model.hand import FINGER_NAMES, JOINT_NAMES, load_hand
from grasp_apso.model.shapes import CUBE_EDGE, SPHERE_DIAMETER
from grasp_apso.model.builtin import builtin

R_SPHERE = SPHERE_DIAMETER / 2  # 0.025
HALF_CUBE = CUBE_EDGE / 2  # 0.035
GRID_ALLOWANCE = 0.00075  # m, grid error allowance (sharp cube edges: ~0.7 mm)
FCL_TOLERANCE = 0.0015  # m, fcl penetration tolerance: 1 mm + grid allowance
OBJECTS = ("sphere", "cube", "barrel", "fish")
MIDDLE, THUMB = 2, 4
FLEXION_COLUMNS = [3 * f + j for f in range(5) for j in (0, 1)]
PIVOT_COLUMNS = [3 * f + 2 for f in range(5)]


@pytest.fixture(scope="module")
def hand():
    return load_hand()


@pytest.fixture(scope="module")
def models(hand):
    return {name: make_grasp_model(hand, builtin(name)) for name in OBJECTS}


def grg_like(model, n: int, seed: int) -> np.ndarray:
    """Particles like GRG's: any wrist angles and pivots, flexions in the lower third of
    their range, standoff offset 0..2 cm."""
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(model.lower), np.asarray(model.upper)
    x = rng.uniform(lo, hi, size=(n, N_DIMS))
    for k in FLEXION_COLUMNS:
        x[:, k] = rng.uniform(lo[k], lo[k] + (hi[k] - lo[k]) / 3.0, size=n)
    x[:, STANDOFF_INDEX] = rng.uniform(0.0, 0.02, size=n)
    return x


def link_radii(hand) -> np.ndarray:
    return np.array([*hand.link_radii[:2], hand.pad_radius])


def dense_link_points(joints: np.ndarray, n: int = 201) -> np.ndarray:
    """(P, 5, 3 links, n, 3): points along the capsule axes between base, PIP, DIP, tip."""
    t = np.linspace(0.0, 1.0, n)[:, None]
    a, b = joints[..., :3, :], joints[..., 1:, :]
    return a[..., None, :] + t * (b - a)[..., None, :]


def sphere_sdf(p: np.ndarray, com: np.ndarray) -> np.ndarray:
    return np.linalg.norm(p - com, axis=-1) - R_SPHERE


def cube_sdf(p: np.ndarray, com: np.ndarray) -> np.ndarray:
    q = np.abs(p - com) - HALF_CUBE
    return np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(axis=-1), 0.0)


ANALYTIC = {"sphere": sphere_sdf, "cube": cube_sdf}


def capsule_clearance(joints: np.ndarray, radii: np.ndarray, sdf, com) -> np.ndarray:
    """(P, 5): smallest analytic clearance of any link capsule of each finger."""
    d = sdf(dense_link_points(joints), com) - radii[:, None]
    return d.min(axis=(-1, -2))


def preshape_joints(hand, x: np.ndarray, wrist: np.ndarray) -> np.ndarray:
    """(P, 5, 4, 3): base, PIP, DIP, tip of the pre-shape (before closing), object frame."""
    palm = hand.finger_frames(x[:, :18])[:, :, :, :3, 3]
    return np.einsum("pij,pfkj->pfki", wrist[:, :3, :3], palm) + wrist[:, None, None, :3, 3]


# ------------------------------------------------------------------------------------------
# contacts on the sphere
# ------------------------------------------------------------------------------------------
def test_fingertips_closed_onto_the_sphere_end_on_its_surface(models, hand) -> None:
    model = models["sphere"]
    com = np.asarray(model.obj.center_of_mass)
    tol = model.settings.tolerance
    assert tol == 0.002 and hand.pad_radius == 0.008
    decoded = decode(model, grg_like(model, 200, seed=20))
    contact = decoded.contact
    assert contact.sum() >= 400  # the sphere is easy: most fingers touch it
    tips = decoded.joints[:, :, 3]
    gap = np.linalg.norm(tips - com, axis=-1) - (R_SPHERE + hand.pad_radius)
    assert np.abs(gap[contact]).max() <= tol, f"worst pad gap {np.abs(gap[contact]).max() * 1e3:.2f} mm"
    # most contacts are pads resting on the surface, not merely near it
    assert np.median(np.abs(gap[contact])) < 0.0005
    # the reported contact point is on the analytic sphere, its normal radial
    points = decoded.contact_points[contact]
    radial = points - com
    dist = np.linalg.norm(radial, axis=-1)
    assert np.abs(dist - R_SPHERE).max() < 0.001
    normals = decoded.contact_normals[contact]
    np.testing.assert_allclose(np.linalg.norm(normals, axis=-1), 1.0, atol=1e-9)
    cos = np.einsum("ij,ij->i", normals, radial / dist[:, None])
    assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 5.0
    # contact points lie under the pads
    under = np.linalg.norm(points - tips[contact], axis=-1)
    assert np.abs(under - hand.pad_radius).max() < tol + 0.001
    # fingers not in contact are not within the tolerance of the surface, or illegal
    free = ~contact & ~decoded.finger_illegal(model.settings.max_penetration)
    assert (gap[free] > tol - GRID_ALLOWANCE).all()


def test_tip_gap_matches_the_analytic_sphere(models, hand) -> None:
    model = models["sphere"]
    decoded = decode(model, grg_like(model, 100, seed=21))
    gap = np.linalg.norm(decoded.joints[:, :, 3] - model.obj.center_of_mass, axis=-1) - R_SPHERE - hand.pad_radius
    near = np.abs(gap) < 0.01  # within the accurate band of the grid
    assert near.sum() > 300
    np.testing.assert_allclose(decoded.tip_gap[near], gap[near], atol=0.0005)


@pytest.mark.parametrize("name", ["sphere", "cube"])
def test_no_link_inside_the_object_after_closing(models, hand, name: str) -> None:
    model = models[name]
    settings = model.settings
    com = np.asarray(model.obj.center_of_mass)
    decoded = decode(model, grg_like(model, 300, seed=22))
    clear = capsule_clearance(decoded.joints, link_radii(hand), ANALYTIC[name], com)
    free = ~decoded.blocked
    assert free.sum() > 1000
    # every finger that is not blocked ends with no link deeper than the tolerance
    worst = clear[free].min()
    assert worst >= -(settings.tolerance + GRID_ALLOWANCE), f"{name}: link {-worst * 1e3:.2f} mm inside"
    # a finger the decoder accepts (not blocked, penetration within max_penetration) is
    # at most max_penetration inside, fingertip contacts included
    accepted = free & (decoded.penetration <= settings.max_penetration)
    assert clear[accepted].min() >= -(settings.max_penetration + GRID_ALLOWANCE)
    assert clear[decoded.contact].min() >= -(settings.max_penetration + GRID_ALLOWANCE)


@pytest.mark.parametrize("name", ["sphere", "cube"])
def test_penetration_is_not_under_reported(models, hand, name: str) -> None:
    """The decoder's penetration covers the whole capsules, not only sample spheres on them."""
    model = models[name]
    decoded = decode(model, grg_like(model, 300, seed=23))
    clear = capsule_clearance(decoded.joints, link_radii(hand), ANALYTIC[name], model.obj.center_of_mass)
    depth = np.maximum(0.0, -clear)
    # within the grid's accurate band (3 mm inside) the depth is measured, not just flagged
    shallow = depth <= 0.003
    under = depth[shallow] - decoded.penetration[shallow]
    assert under.max() <= GRID_ALLOWANCE, f"{name}: penetration under-reported by {under.max() * 1e3:.2f} mm"
    # deeper (coarse grid values there) it is at least reported as deeper than the tolerance
    deep = ~shallow
    assert deep.sum() >= 10
    assert (decoded.penetration[deep] > model.settings.tolerance).all()


@pytest.mark.parametrize("name", ["sphere", "cube"])
def test_blocked_fingers_are_inside_at_their_preshape(models, hand, name: str) -> None:
    model = models[name]
    com = np.asarray(model.obj.center_of_mass)
    x = grg_like(model, 300, seed=24)
    decoded = decode(model, x)
    pre = capsule_clearance(preshape_joints(hand, x, decoded.wrist), link_radii(hand), ANALYTIC[name], com)
    assert decoded.blocked.sum() >= 10
    assert (pre[decoded.blocked] < 0).all()  # really inside
    # a finger deeper than the tolerance at its pre-shape is blocked (or flagged penetrating)
    deep = pre < -(model.settings.tolerance + GRID_ALLOWANCE)
    assert (decoded.blocked | (decoded.penetration > model.settings.max_penetration))[deep].all()
    assert not (decoded.contact & decoded.blocked).any()


# ------------------------------------------------------------------------------------------
# explicit configurations
# ------------------------------------------------------------------------------------------
def explicit_particle(**values: float) -> np.ndarray:
    x = np.zeros((1, N_DIMS))
    for name, value in values.items():
        if name == "standoff":
            x[0, STANDOFF_INDEX] = value
        else:
            x[0, JOINT_NAMES.index(name)] = value
    return x


def test_explicit_palm_toward_the_sphere_closes_middle_and_thumb(models, hand) -> None:
    model = models["sphere"]
    com = np.asarray(model.obj.center_of_mass)
    # wrist_x = 180 deg: palm normal (palm z axis) along -z, the hand above the sphere;
    # thumb raised 40 deg out of the palm, its distal joint pre-flexed; hand 2 cm farther out.
    x = explicit_particle(wrist_x=math.pi, thumb_pivot=math.radians(40), thumb_distal=math.radians(30), standoff=0.02)
    decoded = decode(model, x)
    wrist = decoded.wrist[0]
    normal = wrist[:3, 2]
    np.testing.assert_allclose(normal, [0, 0, -1], atol=1e-12)
    grasp_center = wrist[:3, :3] @ hand.grasp_center + wrist[:3, 3]
    to_com = (com - grasp_center) / np.linalg.norm(com - grasp_center)
    assert normal @ to_com == pytest.approx(1.0, abs=1e-9)  # the palm faces the object
    # palm face at clearance + standoff from the sphere's top
    palm_face = wrist[:3, 3] + normal * (hand.palm_center[2] + hand.palm_half_extents[2])
    assert (palm_face - com) @ -normal == pytest.approx(R_SPHERE + model.settings.clearance + 0.02, abs=1e-4)
    assert decoded.contact[0, MIDDLE] and decoded.contact[0, THUMB], decoded.contact
    assert decoded.n_contacts[0] >= 2
    assert not decoded.finger_illegal(model.settings.max_penetration)[0, [MIDDLE, THUMB]].any()
    tips = decoded.joints[0, [MIDDLE, THUMB], 3]
    np.testing.assert_allclose(np.linalg.norm(tips - com, axis=-1), R_SPHERE + hand.pad_radius, atol=0.002)


def test_the_palm_faces_the_object_for_any_wrist_angles(models, hand) -> None:
    for name, model in models.items():
        x = grg_like(model, 50, seed=25)
        wrist = wrist_transforms(model, x)
        centre = np.einsum("pij,j->pi", wrist[:, :3, :3], hand.grasp_center) + wrist[:, :3, 3]
        to_com = model.obj.center_of_mass - centre
        to_com /= np.linalg.norm(to_com, axis=1, keepdims=True)
        np.testing.assert_allclose(np.einsum("pi,pi->p", wrist[:, :3, 2], to_com), 1.0, atol=1e-9, err_msg=name)
        # no palm point inside the object: the object lies beyond the palm face
        support = (model.obj.hull_vertices - centre[:, None, :]) @ wrist[:, :3, 2][..., None]
        palm_face = hand.palm_center[2] + hand.palm_half_extents[2]
        expected = palm_face + model.settings.clearance + x[:, STANDOFF_INDEX] - hand.grasp_center[2]
        # The model's support points sample the hull's support function along 2,000
        # directions: within about 0.1 mm of the exact hull (far below the clearance).
        np.testing.assert_allclose(support[..., 0].min(axis=1), expected, atol=1e-4, err_msg=name)


def test_blocked_fingers_on_the_cube(models) -> None:
    model = models["cube"]
    flex = {f"{f}_proximal": math.radians(60) for f in FINGER_NAMES[:4]}
    inside = explicit_particle(**flex, standoff=0.0)  # fingers curled into the cube face
    clear = explicit_particle(standoff=0.03)  # straight fingers, hand 3 cm out
    decoded = decode(model, np.vstack([inside, clear]))
    assert decoded.blocked[0, :4].all()
    assert not decoded.contact[0, :4].any()
    assert not decoded.legal(model.settings.max_penetration)[0]
    np.testing.assert_allclose(decoded.closed[0, :12], inside[0, :12], rtol=0, atol=1e-9)  # blocked: no motion
    assert not decoded.blocked[1].any()
    # the straight fingers close over the cube's face and touch it with their tips
    assert decoded.contact[1, :4].all()
    tips = decoded.joints[1, :4, 3]
    gap = cube_sdf(tips, model.obj.center_of_mass) - model.hand.pad_radius
    assert np.abs(gap).max() <= model.settings.tolerance + GRID_ALLOWANCE


# ------------------------------------------------------------------------------------------
# closed configuration, wrist position, bad input
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", OBJECTS)
def test_closed_configuration_respects_limits_and_only_flexes(models, name: str) -> None:
    model = models[name]
    x = grg_like(model, 100, seed=26)
    decoded = decode(model, x)
    closed = decoded.closed
    assert closed.shape == x.shape
    model.hand.validate_configuration(closed[:, :18])  # within the limits (1e-9 rad slack)
    assert 0.0 <= closed[:, STANDOFF_INDEX].min() and closed[:, STANDOFF_INDEX].max() <= model.settings.standoff_max
    keep = PIVOT_COLUMNS + [15, 16, 17, STANDOFF_INDEX]
    np.testing.assert_array_equal(closed[:, keep], x[:, keep])
    assert (closed[:, FLEXION_COLUMNS] >= x[:, FLEXION_COLUMNS]).all()
    # both flexions move together along the closing line pre + s * (upper - pre)
    pre = x[:, FLEXION_COLUMNS].reshape(-1, 5, 2)
    span = np.asarray(model.upper)[FLEXION_COLUMNS].reshape(5, 2) - pre
    s = (closed[:, FLEXION_COLUMNS].reshape(-1, 5, 2) - pre) / span
    np.testing.assert_allclose(s[..., 0], s[..., 1], atol=1e-6)
    assert ((s >= 0.0) & (s <= 1.0)).all()
    # the joints reported are the forward kinematics (DH products) of the closed configuration
    palm = model.hand.finger_frames(closed[:, :18])[:, :, :, :3, 3]
    world = np.einsum("pij,pfkj->pfki", decoded.wrist[:, :3, :3], palm) + decoded.wrist[:, None, None, :3, 3]
    np.testing.assert_allclose(decoded.joints, world, rtol=0, atol=1e-9)


def reference_closing(model, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The closing motion of contacts.py's docstring written out plainly in numpy (the
    decoder runs it in compiled loops): coarse sweep of the sweep spheres, Illinois
    regula falsi on the first bracket, contact test on the dense points, re-opening.

    -> s (P, 5) closing parameter returned, contact (P, 5), blocked (P, 5)
    """
    hand, settings, sdf = model.hand, model.settings, model.sdf
    n = len(x)
    wrist = wrist_transforms(model, x)
    theta = x[:, :15].reshape(n, 5, 3)
    origin, ex, ey = hand.flexion_planes(theta[..., 2])
    d0, p0 = theta[..., 0], theta[..., 1]
    d_span, p_span = hand.upper[0:15:3] - d0, hand.upper[1:15:3] - p0

    def clearance(p: int, f: int, s: float, points: np.ndarray, radii: np.ndarray) -> np.ndarray:
        uv = hand.planar_chain(np.full((1, 5), d0[p, f] + s * d_span[p, f]),
                               np.full((1, 5), p0[p, f] + s * p_span[p, f]), points)[0, f]
        palm = origin[p, f] + uv[:, :1] * ex[p, f] + uv[:, 1:] * ey[p, f]
        return sdf.distance(palm @ wrist[p, :3, :3].T + wrist[p, :3, 3]) - radii

    steps = np.linspace(0.0, 1.0, settings.coarse_steps)
    s_out = np.zeros((n, 5))
    contact = np.zeros((n, 5), dtype=bool)
    blocked = np.zeros((n, 5), dtype=bool)
    for p in range(n):
        for f in range(5):
            sweep = [clearance(p, f, s, contacts_module.SWEEP_POINTS, model.sweep_radii).min() for s in steps]
            blocked[p, f] = sweep[0] < -settings.max_penetration
            hits = np.flatnonzero(np.array(sweep) <= 0.0)
            if len(hits) == 0:
                s_stop = 1.0
            elif hits[0] == 0:
                s_stop = 0.0
            else:
                k = hits[0]
                lo, hi, c_lo, c_hi, side = steps[k - 1], steps[k], sweep[k - 1], sweep[k], 0
                for _ in range(settings.refine_steps):
                    denom = c_lo - c_hi
                    mid = lo + np.clip(c_lo / (denom if abs(denom) > 1e-12 else 1.0), 0.05, 0.95) * (hi - lo)
                    c_mid = clearance(p, f, mid, contacts_module.SWEEP_POINTS, model.sweep_radii).min()
                    if c_mid > 0.0:
                        c_hi = 0.5 * c_hi if side > 0 else c_hi
                        lo, c_lo, side = mid, c_mid, 1
                    else:
                        c_lo = 0.5 * c_lo if side < 0 else c_lo
                        hi, c_hi, side = mid, c_mid, -1
                s_stop = lo
            final = clearance(p, f, s_stop, contacts_module.FINAL_POINTS, model.point_radii)
            contact[p, f] = (final[-1] <= settings.tolerance and not blocked[p, f]
                             and final.min() >= -settings.max_penetration)
            s_out[p, f] = s_stop if contact[p, f] else 0.0
    return s_out, contact, blocked


@pytest.mark.parametrize("name", OBJECTS)
def test_compiled_closing_matches_a_plain_reference(models, name: str) -> None:
    model = models[name]
    x = grg_like(model, 40, seed=29)
    decoded = decode(model, x)
    s, contact, blocked = reference_closing(model, x)
    assert contact.sum() >= 20 and (~contact).sum() >= 20  # both outcomes are exercised
    np.testing.assert_array_equal(decoded.contact, contact)
    np.testing.assert_array_equal(decoded.blocked, blocked)
    pre = x[:, :15].reshape(-1, 5, 3)[..., :2]
    span = np.asarray(model.upper)[:15].reshape(5, 3)[:, :2] - pre
    expected = pre + s[..., None] * span
    np.testing.assert_allclose(decoded.closed[:, :15].reshape(-1, 5, 3)[..., :2], expected, rtol=0, atol=1e-9)


def test_a_thumb_folded_through_the_palm_collides(models) -> None:
    model = models["sphere"]
    settings = model.settings
    x = np.zeros((2, N_DIMS))
    x[:, :15] = np.clip(0.0, model.lower[:15], model.upper[:15])
    x[0, 12:15] = np.radians([30.0, 90.0, 45.0])  # thumb flexed across, through the palm
    x[1, 12:15] = np.radians([30.0, 0.0, 45.0])   # the same thumb, proximal joint straight
    # The wrist 1 m away: nothing is touched and every finger stays at its pre-shape.
    decoded = decode(model, x, wrist_position=np.array([1.0, 0.0, 0.0]))
    assert not decoded.contact.any()
    # Analytic depth of the thumb's links in the palm box (palm frame), from the middle of
    # its proximal link to the pad (the base of a finger sits on the palm).
    pts = dense_link_points(decoded.joints)[:, THUMB]  # (2, 3 links, n, 3)
    t = np.linspace(0.0, 1.0, pts.shape[2])
    rot, trans = decoded.wrist[:, :3, :3], decoded.wrist[:, :3, 3]
    local = np.einsum("pkni,pij->pknj", pts - trans[:, None, None, :], rot)
    depth = (model.palm_half_extents - np.abs(local - model.palm_center)).min(axis=-1)
    depth[:, 0, t < 0.5] = -np.inf
    depth = depth.max(axis=(1, 2))
    assert depth[0] > settings.palm_overlap + 0.002 and depth[1] < 0.0
    capsules = finger_collisions(decoded.joints, model.capsule_radii, settings.finger_overlap)
    assert not capsules.any()  # no finger against another: only the palm check can flag it
    assert decoded.finger_collision[0, THUMB] and not decoded.finger_collision[1].any()
    assert not decoded.legal(settings.max_penetration)[0]


@pytest.mark.parametrize("name", ["cube", "fish"])
def test_redecoding_only_changed_fingers_equals_a_full_decode(models, name: str) -> None:
    model = models[name]
    x = grg_like(model, 60, seed=30)
    first = decode(model, x)
    rng = np.random.default_rng(31)
    changed = rng.random((60, 5)) < 0.3
    fresh = grg_like(model, 60, seed=32)[:, :15].reshape(60, 5, 3)
    y = x.copy()
    fingers = y[:, :15].reshape(60, 5, 3)
    fingers[changed] = fresh[changed]
    y[:, :15] = fingers.reshape(60, 15)
    partial = decode(model, y, reuse=first, changed=changed)
    full = decode(model, y)
    assert (partial.contact != first.contact).any()  # the change matters
    for f in dataclasses.fields(full):
        np.testing.assert_array_equal(getattr(partial, f.name), getattr(full, f.name), err_msg=f.name)
    # a subset of the batch, as GRG's later rounds use it
    keep = changed.any(axis=1)
    again = decode(model, y[keep], reuse=partial.take(keep), changed=np.zeros((keep.sum(), 5), bool))
    np.testing.assert_array_equal(again.closed, full.closed[keep])
    np.testing.assert_array_equal(again.finger_collision, full.finger_collision[keep])


def test_redecoding_rejects_particles_that_changed_elsewhere(models) -> None:
    model = models["sphere"]
    x = grg_like(model, 4, seed=33)
    first = decode(model, x)
    changed = np.zeros((4, 5), dtype=bool)
    changed[0, 1] = True
    with pytest.raises(ValueError, match="reuse, changed"):
        decode(model, x, reuse=first)
    with pytest.raises(ValueError, match="changed: expected"):
        decode(model, x, reuse=first, changed=changed[:2])
    moved = x.copy()
    moved[2, 16] += 0.1  # a wrist angle
    with pytest.raises(ValueError, match="wrist angles or the standoff"):
        decode(model, moved, reuse=first, changed=changed)
    turned = x.copy()
    turned[3, 3 * 2 + 2] = 0.5 * (model.lower[8] + model.upper[8]) + 0.01  # middle pivot, not changed
    with pytest.raises(ValueError, match="pivot of a finger not in changed"):
        decode(model, turned, reuse=first, changed=changed)


def test_out_of_bounds_particles_are_clamped(models) -> None:
    model = models["sphere"]
    x = grg_like(model, 20, seed=27)
    wild = x.copy()
    wild[:, PIVOT_COLUMNS] += 10.0
    wild[:, STANDOFF_INDEX] = -1.0
    decoded = decode(model, wild)
    clamped = np.clip(wild, model.lower, model.upper)
    np.testing.assert_allclose(decoded.closed[:, PIVOT_COLUMNS], clamped[:, PIVOT_COLUMNS], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(decoded.closed[:, STANDOFF_INDEX], 0.0)
    model.hand.validate_configuration(decoded.closed[:, :18])


def test_fixed_wrist_position(models) -> None:
    model = models["barrel"]
    x = grg_like(model, 40, seed=28)
    p = np.array([0.01, -0.02, 0.09])
    decoded = decode(model, x, wrist_position=p)
    np.testing.assert_allclose(decoded.wrist[:, :3, 3], np.broadcast_to(p, (40, 3)), rtol=0, atol=1e-12)
    np.testing.assert_allclose(decoded.wrist[:, :3, :3], wrist_transforms(model, x)[:, :3, :3], rtol=0, atol=1e-12)
    assert (decoded.palm_penetration >= 0).all()
    # far from the object nothing touches: fingers without a fingertip contact take no
    # part in the precision grasp and stay at their pre-shape
    far = decode(model, x, wrist_position=np.array([1.0, 1.0, 1.0]))
    assert not far.contact.any() and not far.blocked.any() and (far.penetration == 0).all()
    np.testing.assert_allclose(
        far.closed[:, FLEXION_COLUMNS], np.clip(x, model.lower, model.upper)[:, FLEXION_COLUMNS], rtol=0, atol=1e-12
    )
    # the wrist inside the object: the palm penetrates
    inside = decode(model, x[:3], wrist_position=model.obj.center_of_mass)
    assert (inside.palm_penetration > 0.005).all()
    assert not inside.legal(model.settings.max_penetration).any()


@pytest.mark.parametrize("shape", [(N_DIMS,), (3, 18), (3, 20), (3, N_DIMS, 1), (0,)])
def test_decode_rejects_wrong_shape(models, shape) -> None:
    with pytest.raises(ValueError, match=r"\bx\b"):
        decode(models["sphere"], np.zeros(shape))


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_decode_rejects_non_finite_particles(models) -> None:
    x = grg_like(models["sphere"], 3, seed=29)
    x[1, 4] = np.nan
    with pytest.raises(ValueError, match=r"\bx\b"):
        decode(models["sphere"], x)


# ------------------------------------------------------------------------------------------
# python-fcl cross-check
# ------------------------------------------------------------------------------------------
def folded_with_fcl(joints: np.ndarray, radii: np.ndarray, overlap: float) -> np.ndarray:
    """(5,) bool: the distal capsule meets the proximal one of the same finger (fcl)."""
    return np.array([
        collision._collide(
            collision._capsule(joints[f, 0], joints[f, 1], float(radii[0]) - 0.5 * overlap),
            collision._capsule(joints[f, 2], joints[f, 3], float(radii[2]) - 0.5 * overlap),
        )
        for f in range(5)
    ])


FCL_RATES: dict[str, float] = {}


@pytest.mark.parametrize("name", OBJECTS)
def test_decoder_agrees_with_fcl(models, hand, name: str) -> None:
    model = models[name]
    settings = model.settings
    decoded = decode(model, grg_like(model, 30, seed=30))
    bvh = collision.mesh_bvh(model.obj.mesh)
    radii = link_radii(hand)
    accepted = ~decoded.blocked & (decoded.penetration <= settings.max_penetration)
    deep = decoded.penetration > settings.tolerance + GRID_ALLOWANCE
    numpy_hits = finger_collisions(decoded.joints, radii, allowed_overlap=settings.finger_overlap)
    pen_agree = deep_agree = pair_agree = 0
    for p in range(len(decoded.closed)):
        report = verify_with_fcl(
            decoded.joints[p], radii, bvh, FINGER_NAMES,
            penetration_tolerance=FCL_TOLERANCE, allowed_overlap=settings.finger_overlap,
        )
        fcl_pen = report.link_penetrates.any(axis=1)
        pen_agree += int((accepted[p] & ~fcl_pen).sum())
        deep_agree += int((deep[p] & fcl_pen).sum())
        in_pair = np.zeros(5, dtype=bool)
        for a, b in report.finger_pairs_colliding:
            in_pair[FINGER_NAMES.index(a)] = in_pair[FINGER_NAMES.index(b)] = True
        # finger_collisions may also flag a finger folded into itself (distal link on the
        # proximal one), which fcl's pair check does not look at: compare the other fingers
        folded = folded_with_fcl(decoded.joints[p], radii, settings.finger_overlap)
        pair_agree += int(np.array_equal(in_pair[~folded], numpy_hits[p][~folded]))
        # fcl distances of links that stay clear match the analytic clearance sign
        assert (report.link_distance >= 0).all()
    n_accepted, n_deep = int(accepted.sum()), int(deep.sum())
    rate = pen_agree / n_accepted
    FCL_RATES[name] = rate
    print(
        f"\n{name}: fcl agrees on {pen_agree}/{n_accepted} accepted fingers ({100 * rate:.1f} %), "
        f"on {deep_agree}/{n_deep} deeply penetrating fingers, finger pairs on {pair_agree}/30 particles"
    )
    assert n_accepted >= 60
    assert rate >= 0.95
    if n_deep:
        assert deep_agree / n_deep >= 0.95
    assert pair_agree / 30 >= 0.95


def test_finger_collisions_match_fcl_on_close_fingers(hand) -> None:
    """Finger pairs placed near the collision threshold (capsule gap -3..+3 mm)."""
    rng = np.random.default_rng(31)
    radii = link_radii(hand)
    model_joints = []
    for _ in range(60):
        joints = np.zeros((5, 4, 3))
        for f in range(5):  # five parallel straight fingers 40 mm apart in z
            joints[f] = np.array([[0, 0, 0.04 * f], [0.04, 0, 0.04 * f], [0.07, 0, 0.04 * f], [0.09, 0, 0.04 * f]])
        # bring the index tip toward the middle finger's distal link
        gap = rng.uniform(-0.003, 0.003)
        direction = rng.normal(size=3)
        direction[2] = 0.0
        joints[3, 3] = joints[2, 3] + [0, 0, radii[2] + radii[2] - 0.002 + gap]
        joints[3, 2] = joints[3, 3] + 0.02 * direction / np.linalg.norm(direction)
        model_joints.append(joints)
    joints = np.stack(model_joints)
    numpy_hits = finger_collisions(joints, radii, allowed_overlap=0.002)
    bvh = collision.mesh_bvh(builtin("sphere").mesh)
    agree = 0
    for p in range(len(joints)):
        far = joints[p] + [0, 0, 1.0]  # away from the mesh: only the finger pairs matter
        report = verify_with_fcl(far, radii, bvh, FINGER_NAMES, allowed_overlap=0.002)
        hit = np.zeros(5, dtype=bool)
        for a, b in report.finger_pairs_colliding:
            hit[FINGER_NAMES.index(a)] = hit[FINGER_NAMES.index(b)] = True
        agree += int(np.array_equal(hit, numpy_hits[p]))
    assert 10 < numpy_hits[:, 3].sum() < 50  # both outcomes occur
    assert agree >= 57  # >= 95 %


# ------------------------------------------------------------------------------------------
# segment distances
# ------------------------------------------------------------------------------------------
def reference_segment_distances(p0, p1, q0, q1, iterations: int = 80) -> np.ndarray:
    """Nested ternary search over the convex distance |P(s) - Q(t)|, batched over (n, 3)
    segment pairs (independent of Ericson's closed form)."""
    n = len(p0)

    def inner(points: np.ndarray) -> np.ndarray:  # min over t of |points - Q(t)|
        lo, hi = np.zeros(n), np.ones(n)
        for _ in range(iterations):
            m1, m2 = lo + (hi - lo) / 3, hi - (hi - lo) / 3
            d1 = np.linalg.norm(points - (q0 + m1[:, None] * (q1 - q0)), axis=1)
            d2 = np.linalg.norm(points - (q0 + m2[:, None] * (q1 - q0)), axis=1)
            left = d1 < d2
            hi, lo = np.where(left, m2, hi), np.where(left, lo, m1)
        return np.linalg.norm(points - (q0 + (0.5 * (lo + hi))[:, None] * (q1 - q0)), axis=1)

    lo, hi = np.zeros(n), np.ones(n)
    for _ in range(iterations):
        m1, m2 = lo + (hi - lo) / 3, hi - (hi - lo) / 3
        left = inner(p0 + m1[:, None] * (p1 - p0)) < inner(p0 + m2[:, None] * (p1 - p0))
        hi, lo = np.where(left, m2, hi), np.where(left, lo, m1)
    return inner(p0 + (0.5 * (lo + hi))[:, None] * (p1 - p0))


def brute_force_distance(p0, p1, q0, q1, n: int = 151) -> float:
    t = np.linspace(0.0, 1.0, n)[:, None]
    a = p0 + t * (p1 - p0)
    b = q0 + t * (q1 - q0)
    return float(np.sqrt(((a[:, None, :] - b[None, :, :]) ** 2).sum(-1)).min())


def special_segments() -> list[tuple[str, np.ndarray, float]]:
    cases = [
        ("parallel disjoint", [[0, 0, 0], [1, 0, 0], [2, 1, 0], [3, 1, 0]], math.sqrt(2)),
        ("parallel overlapping", [[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [1.5, 1, 0]], 1.0),
        ("anti-parallel overlapping", [[0, 0, 0], [1, 0, 0], [1.5, 0, 1], [0.5, 0, 1]], 1.0),
        ("collinear disjoint", [[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]], 1.0),
        ("collinear overlapping", [[0, 0, 0], [1, 0, 0], [0.5, 0, 0], [3, 0, 0]], 0.0),
        ("identical", [[0, 0, 0], [1, 0, 0], [0, 0, 0], [1, 0, 0]], 0.0),
        ("crossing", [[0, 0, 0], [1, 0, 0], [0.5, -1, 0], [0.5, 1, 0]], 0.0),
        ("skew", [[0, 0, 0], [1, 0, 0], [0.3, 1, -1], [0.3, 1, 1]], 1.0),
        ("skew beyond end", [[0, 0, 0], [1, 0, 0], [2, 1, -1], [2, 1, 1]], math.sqrt(2)),
        ("nearly parallel", [[0, 0, 0], [1, 0, 0], [0.2, 1, 0], [1.2, 1 + 1e-9, 0]], 1.0),
        ("T end-on", [[0, 0, 0], [1, 0, 0], [0.5, 0.5, 0], [0.5, 2, 0]], 0.5),
        # the degenerate segment first: the other order is the xfail test below
        ("point vs segment", [[0.5, 1, 0], [0.5, 1, 0], [0, 0, 0], [1, 0, 0]], 1.0),
        ("point vs point", [[0, 0, 0], [0, 0, 0], [1, 1, 0], [1, 1, 0]], math.sqrt(2)),
    ]
    return [(name, np.array(seg, dtype=float), d) for name, seg, d in cases]


@pytest.mark.parametrize("case", special_segments(), ids=lambda c: c[0])
@pytest.mark.parametrize("scale", [1.0, 0.03])  # unit and finger (cm) scale
def test_segment_distance_special_cases(case, scale: float) -> None:
    _, seg, expected = case
    seg = seg * scale
    assert segment_distances(*seg) == pytest.approx(expected * scale, abs=1e-9 * scale)
    assert segment_distances(seg[1], seg[0], seg[3], seg[2]) == pytest.approx(expected * scale, abs=1e-9 * scale)
    if case[0] != "point vs segment":
        assert segment_distances(seg[2], seg[3], seg[0], seg[1]) == pytest.approx(expected * scale, abs=1e-9 * scale)


def test_segment_distance_segment_vs_point() -> None:
    p0, p1, q = np.array([0.0, 0, 0]), np.array([1.0, 0, 0]), np.array([0.5, 1, 0])
    assert segment_distances(p0, p1, q, q) == pytest.approx(1.0, abs=1e-9)
    q1 = q + [0, 0, 1e-9]  # a 1 nm link next to a 1 cm one
    assert segment_distances(p0 * 0.01, p1 * 0.01, q * 0.01, q1 * 0.01) == pytest.approx(0.01, abs=1e-9)


def test_segment_distances_against_brute_force() -> None:
    rng = np.random.default_rng(32)
    n = 80
    p0, p1 = rng.uniform(-0.05, 0.05, size=(2, n, 3))
    q0, q1 = rng.uniform(-0.05, 0.05, size=(2, n, 3))
    # a quarter parallel (q = p shifted), some with one end shared (touching)
    k = n // 4
    q0[:k] = p0[:k] + rng.uniform(-0.02, 0.02, size=(k, 3))
    q1[:k] = q0[:k] + (p1[:k] - p0[:k]) * rng.uniform(-1.5, 1.5, size=(k, 1))
    q0[k : k + 10] = p1[k : k + 10]
    got = segment_distances(p0, p1, q0, q1)
    assert got.shape == (n,)
    np.testing.assert_allclose(got, reference_segment_distances(p0, p1, q0, q1), atol=1e-10, rtol=0)
    for i in range(n):
        brute = brute_force_distance(p0[i], p1[i], q0[i], q1[i])
        step = (np.linalg.norm(p1[i] - p0[i]) + np.linalg.norm(q1[i] - q0[i])) / 150
        assert got[i] <= brute + 1e-12
        assert brute - got[i] <= step
    np.testing.assert_allclose(got[k : k + 10], 0.0, atol=1e-15)


def test_segment_distances_broadcast() -> None:
    rng = np.random.default_rng(33)
    p0, p1 = rng.uniform(-1, 1, size=(2, 4, 1, 3))
    q0, q1 = rng.uniform(-1, 1, size=(2, 1, 6, 3))
    got = segment_distances(p0, p1, q0, q1)
    assert got.shape == (4, 6)
    for i in range(4):
        for j in range(6):
            assert got[i, j] == pytest.approx(segment_distances(p0[i, 0], p1[i, 0], q0[0, j], q1[0, j]), abs=1e-15)
