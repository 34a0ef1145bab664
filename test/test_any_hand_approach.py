"""The object along a general hand's approach in the decoder
(:func:`grasp_apso.geometry.any_hand_approach.object_approach_margins`), checked against
python-fcl on the hand's exact collision geometry (:func:`grasp_apso.geometry.any_hand_fcl.approach_report`).

The Inspire hand (robosuite's MJCF) and the apple: seeded random particles, their root
poses and open pre-shapes. Where the decoder's spheres keep the margin along the whole
approach, python-fcl finds no link in the object beyond the contact zone; where a sphere
is well inside (more than the covers' stray), python-fcl finds the hit too.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from grasp_apso.geometry import any_hand_fcl as fcl_api
from grasp_apso.geometry import any_hand_kernels as hk
from grasp_apso.geometry.any_hand_approach import APPROACH_STEPS, CUTOFF, object_approach_margins
from grasp_apso.geometry.any_hand_decoder import make_any_hand_model, root_poses
from grasp_apso.geometry.hand_fcl import CONTACT_ZONE
from grasp_apso.model.hands.load import load_hand
from grasp_apso.model.mesh_files import from_file
from grasp_apso.model.scene import Scene
from hand_files import installed_hand

APPLE = Path(__file__).resolve().parents[1] / "grasp_apso" / "data" / "meshes" / "apple.stl"
APPROACH = 0.08
#: m: a sphere this deep is inside the exact geometry too (the covers stray at most 2 mm).
DEEP = 0.004


@pytest.fixture(scope="module")
def sampled():
    hand = load_hand(installed_hand("inspire"))
    apple = from_file(str(APPLE))
    model = make_any_hand_model(hand, apple)
    rng = np.random.default_rng(3)
    t = model.tables
    lay = model.layout
    x = np.empty((160, lay.dims))
    x[:, :lay.shift.start] = rng.uniform(t.lower[:lay.shift.start], t.upper[:lay.shift.start], (160, lay.shift.start))
    # the grasp centre shifted within a quarter of its bounds: the hand still over the apple
    # in most draws, so both clear and deep approaches are sampled
    x[:, lay.shift] = 0.25 * rng.uniform(t.lower[lay.shift], t.upper[lay.shift], (160, 2))
    root = root_poses(model, x)
    q_open = np.clip(x[:, model.layout.joints], hand.lower, hand.upper)
    margins = object_approach_margins(model, root[:, :3, :3], root[:, :3, 3], q_open, APPROACH)
    return hand, apple, model, root, q_open, margins


def _fcl_hits(hand, apple, model, root, q) -> bool:
    """python-fcl: a link of the open hand in the apple farther back than the contact zone
    (the decoder's own closing decides at the grasp)."""
    approach = root[:3, :3] @ model.tables.basis[:, 2]
    report = fcl_api.approach_report(fcl_api.HandCollision(hand), q, root, approach, APPROACH, Scene(), apple)
    return report.hits_object and report.hit_at > CONTACT_ZONE


def test_both_kinds_are_sampled(sampled):
    *_, margins = sampled
    assert (margins >= 0).sum() >= 20 and (margins < -DEEP).sum() >= 20, np.sort(margins)


def test_clear_in_the_decoder_is_clear_in_python_fcl(sampled):
    hand, apple, model, root, q_open, margins = sampled
    clear = np.flatnonzero(margins >= 0)[:25]
    hits = [i for i in clear if _fcl_hits(hand, apple, model, root[i], q_open[i])]
    assert len(hits) <= 1, (hits, margins[hits])


def test_deep_in_the_decoder_hits_in_python_fcl(sampled):
    hand, apple, model, root, q_open, margins = sampled
    deep = np.flatnonzero(margins < -DEEP)[:25]
    misses = [i for i in deep if not _fcl_hits(hand, apple, model, root[i], q_open[i])]
    assert len(misses) <= 1, (misses, margins[misses])


def _each_retreat(model, rot, trans, q_open, backs) -> np.ndarray:
    """The least clearance over the retreats, each measured on its own with no bound
    skipped (``cutoff`` inf: every link and the palm looked into): (P,)."""
    t, s = model.tables, model.sdf
    grid = (s._values64, s._origin64, float(s.spacing))
    approach = np.ascontiguousarray(rot @ t.basis[:, 2])
    n_p, n_f, lmax = len(rot), t.n_fingers, t.finger_link.shape[1]
    rows = np.array([(p, f) for p in range(n_p) for f in range(n_f)], dtype=np.int64)
    best = np.full(n_p, np.inf)
    for back in backs:
        moved = np.ascontiguousarray(trans - back * approach)
        link_clear = np.full((n_p, n_f, lmax), np.inf)
        pad_pos, pad_gap = np.empty((n_p, n_f, 3)), np.empty((n_p, n_f))
        hk.finger_clearances(*grid, rot, moved, q_open, rows, model.kin, np.inf, link_clear, pad_pos, pad_gap)
        palm = np.empty(n_p)
        hk.palm_clearance(*grid, rot, moved, t.palm_groups, t.palm_pose, t.palm_bound, model.kin, np.inf, palm)
        best = np.minimum(best, np.minimum(link_clear.min(axis=(1, 2)), palm))
    return best


@pytest.mark.parametrize("cutoff", [CUTOFF, 0.02])
def test_the_bounds_the_approach_skips_change_no_clearance_below_the_cut(sampled, cutoff):
    """The approach kernel skips a finger at a retreat by one bounding sphere of its links,
    and links, groups and the palm by theirs: the least clearance it returns is the one
    measured retreat by retreat with nothing skipped, exactly, wherever it is at most the
    cut (the decoder's, and 20 mm), and above the cut wherever that one is. (Not without a
    cut: beyond the distance grid, 47 mm off, a bound can read 0.1 mm above its spheres.)"""
    _, _, model, root, q_open, _ = sampled
    rot, trans = np.ascontiguousarray(root[:, :3, :3]), np.ascontiguousarray(root[:, :3, 3])
    q_open = np.ascontiguousarray(q_open)
    backs = np.ascontiguousarray([f * APPROACH for f in APPROACH_STEPS if f * APPROACH > CONTACT_ZONE])
    expected = _each_retreat(model, rot, trans, q_open, backs)
    got = np.empty(len(rot))
    hk.approach_clearance(model.sdf._values64, model.sdf._origin64, float(model.sdf.spacing), rot, trans,
                          np.ascontiguousarray(rot @ model.tables.basis[:, 2]), backs, q_open,
                          model.tables.palm_groups, model.tables.palm_pose, model.tables.palm_bound, model.kin,
                          cutoff, got)
    below = expected <= cutoff
    assert below.sum() >= 30, np.sort(expected)
    np.testing.assert_array_equal(got[below], expected[below])
    assert np.all(got[~below] > cutoff)
