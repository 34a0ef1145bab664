"""Guided Random Generation of a general hand (:mod:`grasp_apso.search.any_hand_grg`): its
draws are valid, and the hand's pre-shape layout is built once per hand, not per batch.

Validity is checked by decoding the returned particles again (the decoder's legality and
contact count, the property GRG promises), not by the generator's own flags.
"""
from __future__ import annotations

import numpy as np
import pytest

from grasp_apso.geometry.any_hand_decoder import decode_any, with_any_scene
from grasp_apso.model.builtin import builtin
from grasp_apso.model.hands.load import load_hand
from grasp_apso.model.scene import Scene
from grasp_apso.search.any_hand_grg import AnyHandGenerator, _draws, _layout, _owned
from grasp_apso.search.any_hand_planner import prepare_any_hand
from grasp_apso.search.grg import classify_shape
from grasp_apso.search.options import PlanOptions
from hand_files import write_allegro_like


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    """The Allegro-like hand and the cube on a table: the model and the shape class."""
    hand = load_hand(write_allegro_like(tmp_path_factory.mktemp("grg"), "mixed"))
    obj = builtin("cube")
    options = PlanOptions()
    table = Scene.table_under(np.asarray(obj.mesh.vertices))
    model = with_any_scene(prepare_any_hand(obj, hand, options), table, options.clearance, options.approach_distance)
    return model, classify_shape(obj).with_support(table.planes[:, :3])


def _valid(model, x: np.ndarray) -> np.ndarray:
    """(P,) bool: legal but for the scene, with two contacts or more (GRG's promise)."""
    d = decode_any(model, x)
    s = model.settings
    return (~d.finger_illegal(s.max_penetration).any(axis=1) & (d.palm_clearance >= -s.max_penetration)
            & (d.n_contacts >= 2))


def test_the_preshape_layout_is_built_once_per_hand(setup):
    model, _ = setup
    first = _layout(model)
    assert _layout(model) is first  # the cache's value, not rebuilt per batch
    draws = _draws(model.tables, tuple(f.is_thumb for f in model.hand.fingers))
    for a, b in zip(first[0], draws):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(first[1], _owned(model.tables))


def test_small_draws_are_valid_and_distinct(setup):
    model, shape = setup
    gen = AnyHandGenerator(model, shape, np.random.default_rng(3))
    x = np.concatenate([gen.draw(60)] + [gen.draw(6) for _ in range(10)])  # start, then replacements
    assert x.shape == (120, model.layout.dims)
    assert _valid(model, x).all()
    assert len(np.unique(x, axis=0)) == len(x)
