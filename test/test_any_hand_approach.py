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
from grasp_apso.geometry.any_hand_approach import object_approach_margins
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
    x = rng.uniform(t.lower, t.upper, size=(160, len(t.lower)))
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
