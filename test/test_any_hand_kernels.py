"""The general hand's compiled kernels against independent references: the forward
kinematics of :func:`grasp_apso.geometry.any_hand_kernels.link_poses` against the hand
model's own (numpy, ``HandModel.link_transforms_batch``), the scene kernel's point distance
against ``Scene.signed_distance``, and the python-fcl pair distances with their
convex-hull bound against fcl's BVH distance of the exact meshes."""

from __future__ import annotations

import re

import fcl
import numba
import numpy as np
import pytest

from grasp_apso.geometry import any_hand_kernels as hk
from grasp_apso.geometry.any_hand_fcl import HandCollision
from grasp_apso.geometry.any_hand_queries import part_pair_distances
from grasp_apso.geometry.any_hand_scene import _scene_distance, packed_scene
from grasp_apso.geometry.any_hand_shapes import TOUCH_EPS
from grasp_apso.geometry.any_hand_tables import hand_tables
from grasp_apso.model.hands.load import load_hand
from grasp_apso.model.scene import BOX, CYLINDER, SPHERE, Obstacle, Scene
from hand_files import installed_hand, write_allegro_like

#: GJK's distance between separated convex shapes can exceed the exact one by this (m).
GJK_TOL = 2e-5


@pytest.fixture(scope="module")
def hands(tmp_path_factory):
    folder = tmp_path_factory.mktemp("hands")
    return {"shadow": load_hand(installed_hand("shadow")), "inspire": load_hand(installed_hand("inspire")),
            "allegro_like": load_hand(write_allegro_like(folder / "a", "mixed"))}


@pytest.mark.parametrize("name", ["shadow", "inspire", "allegro_like"])
def test_compiled_finger_poses_match_the_hand_models_kinematics(hands, name):
    """Every finger link's pose (root frame) at seeded random postures, couplings included."""
    hand = hands[name]
    t = hand_tables(hand)
    q = np.random.default_rng(3).uniform(hand.lower, hand.upper, (40, hand.n_joints))
    out = np.empty((len(q), t.n_fingers, t.finger_link.shape[1], 4, 4))
    hk.link_poses(np.ascontiguousarray(q), hk.kin(t), out)
    expected = hand.link_transforms_batch(q)
    checked = 0
    for f in range(t.n_fingers):
        for l in range(int(t.n_links[f])):
            np.testing.assert_allclose(out[:, f, l], expected[:, t.finger_link[f, l]], atol=1e-12)
            checked += 1
    assert checked >= 15
    # the postures move the links: the check is not of a constant
    assert np.ptp(out[:, 0, int(t.n_links[0]) - 1, :3, 3], axis=0).max() > 0.01


def test_mesh_pairs_keep_the_bvh_distance_or_a_hull_bound_below_it(hands):
    """Inspire's links are CAD meshes: a pair whose hulls stay farther than ``below`` apart
    keeps the hulls' gap, never more than the meshes' (fcl BVH) gap; the others the BVH
    distance itself."""
    hc = HandCollision(hands["inspire"])
    a, b = hc.shapes.pair_candidates
    rng = np.random.default_rng(5)
    below = 0.01
    bounded = exact = 0
    for _ in range(6):
        q = rng.uniform(hc.hand.lower, hc.hand.upper)
        poses = hc.part_poses(q, np.eye(4))
        objs = hc.place(poses)
        got = part_pair_distances(hc.shapes, objs, poses, a, b, below)
        for i, j, d in zip(a, b, got):
            bvh = float(fcl.distance(objs[i], objs[j], fcl.DistanceRequest(), fcl.DistanceResult()))
            if bvh <= TOUCH_EPS:
                assert d <= 0.0
            elif d < below:
                assert d == pytest.approx(bvh, abs=1e-9)
                exact += 1
            else:  # GJK converges from above: within its tolerance (micrometres) of the hulls' gap
                assert d <= bvh + GJK_TOL
                bounded += 1
    assert exact >= 4 and bounded >= 20, (exact, bounded)


def test_compiled_scene_distance_matches_the_scene():
    """The scene kernel's point distance against ``Scene.signed_distance`` (numpy) at seeded
    points around a table, a box, a sphere and a cylinder (posed, rotated)."""
    @numba.njit(cache=False)
    def distances(points, S):
        out = np.empty(points.shape[0])
        for n in range(points.shape[0]):
            out[n] = _scene_distance(points[n], S)
        return out

    turn = np.eye(4)
    turn[:3, :3] = [[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]]
    obstacles = []
    for kind, dims, centre in ((BOX, (0.04, 0.02, 0.06), (0.1, 0.0, 0.05)), (SPHERE, (0.03,), (-0.1, 0.0, 0.05)),
                               (CYLINDER, (0.08, 0.02), (0.0, 0.1, 0.05))):
        pose = turn.copy()
        pose[:3, 3] = centre
        obstacles.append(Obstacle(kind, dims, pose))
    scene = Scene(planes=np.array([[0.0, 0.0, 1.0, 0.0]]), obstacles=tuple(obstacles))
    points = np.random.default_rng(2).uniform([-0.15, -0.05, -0.02], [0.15, 0.15, 0.12], (3000, 3))
    got = distances(points, packed_scene(scene))
    np.testing.assert_allclose(got, scene.signed_distance(points), atol=1e-12)
    assert (got < 0).sum() > 50  # some points inside the solids


@pytest.mark.parametrize("name", ["shadow", "inspire", "allegro_like"])
def test_the_links_a_closing_does_not_move_keep_their_poses_along_it(hands, name):
    """The closing sweep poses only the links the tables mark as moved by the finger's
    closing (``HandTables.moving``): every other link of the finger keeps its pose from the
    pre-shape to the closing limits (seeded random pre-shapes, couplings included), and the
    marked ones do move."""
    hand = hands[name]
    t = hand_tables(hand)
    rng = np.random.default_rng(4)
    q0 = rng.uniform(hand.lower, hand.upper, (30, hand.n_joints))
    lmax = t.finger_link.shape[1]
    moved_any = np.zeros((t.n_fingers, lmax), dtype=bool)
    for f in range(t.n_fingers):
        closed = q0.copy()
        for k in range(int(t.j_count[f])):
            if not np.isnan(t.j_target[f, k]):
                closed[:, t.j_index[f, k]] = t.j_target[f, k]
        before, after = (np.empty((len(q0), t.n_fingers, lmax, 4, 4)) for _ in range(2))
        hk.link_poses(np.ascontiguousarray(q0), hk.kin(t), before)
        hk.link_poses(np.ascontiguousarray(closed), hk.kin(t), after)
        for l in range(int(t.n_links[f])):
            same = np.abs(after[:, f, l] - before[:, f, l]).max(axis=(1, 2)) <= 1e-12
            if not t.moving[f, l]:
                assert same.all(), (f, l)
            moved_any[f, l] = not same.all()
    assert np.array_equal(moved_any[:, :], t.moving.astype(bool))


def _shared_closing_hand(folder):
    """The Allegro-like hand with the middle finger's middle joint mimicking the index
    finger's: one actuated joint closes two fingers (the one closed last sets it)."""
    path = write_allegro_like(folder, "none")
    text = re.sub(r'(<joint name="middle_joint_2" type="revolute">.*?)(\s*</joint>)',
                  r'\1\n    <mimic joint="index_joint_2" multiplier="1" offset="0"/>\2', path.read_text(), count=1,
                  flags=re.S)
    path.write_text(text)
    return load_hand(path)


@pytest.mark.parametrize("name", ["shadow", "inspire", "allegro_like", "shared"])
def test_the_closing_writes_pad_points_facings_and_distances_at_the_closed_posture(hands, name, tmp_path):
    """The pad point, its facing and the signed distance there that the closing kernel
    writes for each finger are those of the closed posture it returns (and its clearances
    at the pre-shape those of :func:`finger_clearances` there), by the hand model's
    own kinematics (``HandModel.link_transforms_batch``) and the grid's own look-ups
    (``SignedDistanceGrid.distance`` and ``distance_and_gradient``): seeded random particles
    on the barrel. ``shared``: a joint two fingers close, where the first finger's pad point
    moves with the second's closing."""
    from grasp_apso.geometry.any_hand_decoder import CUTOFF, REFINE_STEPS, make_any_hand_model, root_poses
    from grasp_apso.model.builtin import builtin

    hand = _shared_closing_hand(tmp_path) if name == "shared" else hands[name]
    model = make_any_hand_model(hand, builtin("barrel"))
    t, s, sdf = model.tables, model.settings, model.sdf
    x = np.random.default_rng(6).uniform(model.lower, model.upper, (400, len(model.lower)))
    root = root_poses(model, x)
    rot, trans = np.ascontiguousarray(root[:, :3, :3]), np.ascontiguousarray(root[:, :3, 3])
    q0 = np.ascontiguousarray(x[:, model.layout.joints])
    n_p, n_f, lmax = len(x), t.n_fingers, t.finger_link.shape[1]
    q, s_out, start = np.empty_like(q0), np.empty((n_p, n_f)), np.empty((n_p, n_f))
    stopped, link_clear = np.empty((n_p, n_f), dtype=bool), np.empty((n_p, n_f, lmax))
    pad_pos, pad_gap, pads = np.empty((n_p, n_f, 3)), np.empty((n_p, n_f)), np.empty((n_p, n_f, 3))
    facing, pad_dist = np.empty((n_p, n_f)), np.empty((n_p, n_f))
    open_clear, open_pad, open_gap = np.full((n_p, n_f, lmax), np.inf), np.empty((n_p, n_f, 3)), np.empty((n_p, n_f))
    grid = (sdf._values64, sdf._origin64, float(sdf.spacing))
    hk.close_fingers(*grid, rot, trans, q0, model.kin, int(s.coarse_steps), REFINE_STEPS, CUTOFF, t.pad_point, q,
                     s_out, start, stopped, link_clear, pad_pos, pad_gap, pads, facing, pad_dist, open_clear,
                     open_pad, open_gap)
    # at the pre-shape (where a finger without contact goes back to): finger_clearances' values
    rows = np.argwhere(np.ones((n_p, n_f), dtype=bool)).astype(np.int64)
    ref_clear, ref_pad, ref_gap = np.full((n_p, n_f, lmax), np.inf), np.empty((n_p, n_f, 3)), np.empty((n_p, n_f))
    hk.finger_clearances(*grid, rot, trans, q0, rows, model.kin, CUTOFF, ref_clear, ref_pad, ref_gap)
    np.testing.assert_array_equal(open_clear, ref_clear)
    np.testing.assert_array_equal(open_pad, ref_pad)
    np.testing.assert_array_equal(open_gap, ref_gap)
    np.testing.assert_array_equal(open_clear.min(axis=2), start)
    links = hand.link_transforms_batch(q)
    for f, finger in enumerate(hand.fingers):
        pose = links[:, hand.link_index(finger.pad_link)]
        expected = np.einsum("pij,pj->pi", rot, pose[:, :3, :3] @ np.asarray(finger.pad_center, float)
                             + pose[:, :3, 3]) + trans
        np.testing.assert_allclose(pads[:, f], expected, atol=1e-12)
    np.testing.assert_allclose(pad_dist, sdf.distance(pads), atol=1e-12)
    normal = pads - pad_pos
    normal /= np.linalg.norm(normal, axis=2, keepdims=True)
    np.testing.assert_allclose(facing, -(normal * sdf.distance_and_gradient(pad_pos)[1]).sum(axis=2), atol=1e-9)
    assert stopped.mean() > 0.1 and (np.abs(pad_gap) < 0.002).sum() > 50  # fingers met the barrel
    assert facing.min() < 0.0 < facing.max()
    if name == "shared":
        # the index finger's pad point is where the middle finger's closing left their joint
        j = hand.actuated_joints.index("index_joint_2")
        assert (np.abs(q[:, j] - q0[:, j]) > 1e-3).any()
