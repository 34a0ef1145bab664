"""Guided Random Generation of a general hand (:mod:`grasp_apso.search.any_hand_grg`): the
swarm asks for a few particles per iteration, so the generator verifies its draws in a pool
of ``POOL_BATCH`` at a time, each call taking the batch it would have drawn from the pool,
and keeps the valid draws a call did not hand out for the next.

Validity is checked by decoding the returned particles again (the decoder's legality and
contact count, the property GRG promises), not by the generator's own flags.
"""
from __future__ import annotations

import re

import numpy as np
import pytest

from grasp_apso.geometry.any_hand_decoder import decode_any, with_any_scene
from grasp_apso.model.builtin import builtin
from grasp_apso.model.hands.load import load_hand
from grasp_apso.model.scene import Scene
from grasp_apso.search import any_hand_grg
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


class CountingGenerator(AnyHandGenerator):
    """The generator, counting its verified batches (each decodes up to five times)."""

    batches = 0

    def _verified(self, x):
        self.batches += 1
        return super()._verified(x)


def test_small_draws_take_their_batches_from_a_verified_pool(setup):
    model, shape = setup
    gen = CountingGenerator(model, shape, np.random.default_rng(3))
    first = gen.draw(60)  # the swarm's start
    start = gen.batches
    later = [gen.draw(6) for _ in range(20)]  # the per-iteration replacements
    x = np.concatenate([first] + later)
    assert x.shape == (180, model.layout.dims)
    assert _valid(model, x).all()
    # every draw handed out once (the pool gives away what a call takes)
    assert len(np.unique(x, axis=0)) == len(x)
    # 20 calls of a dozen draws or two each, verified a pool of POOL_BATCH (64) at a time:
    # before the pool, every call verified its own batch (20 batches or more)
    assert gen.batches - start <= 8


def test_a_call_whose_batch_is_in_the_pool_decodes_nothing(setup):
    model, shape = setup
    gen = CountingGenerator(model, shape, np.random.default_rng(5))
    gen.draw(6)  # the first call verifies a pool of POOL_BATCH and takes its batch
    assert gen.batches == 1
    left = len(gen._pool[0]) - gen._pool_at
    assert left > 0
    evaluations = gen.evaluations
    x = gen.draw(min(6, left // 4))  # a batch of 1.5 x k / (valid share) <= left
    assert (gen.evaluations, gen.batches) == (evaluations, 1)
    assert _valid(model, x).all()


def test_valid_draws_a_call_does_not_hand_out_go_to_the_next_call(setup):
    """A call's batch oversamples (DRAW_FACTOR): its valid draws beyond the k asked for
    are the next call's first ones, not decoded again and not thrown away."""
    model, shape = setup
    gen = CountingGenerator(model, shape, np.random.default_rng(7))
    first = gen.draw(20)
    kept_good, kept_near = (a.copy() for a in gen._spare)
    kept = len(kept_good) + len(kept_near)
    assert kept > 0  # a batch of 1.5 x k / (valid share) left some
    evaluations, batches = gen.evaluations, gen.batches
    x = gen.draw(kept)
    assert (gen.evaluations, gen.batches) == (evaluations, batches)  # nothing decoded
    # the kept draws, scene-clear ones first, every one valid and none handed out twice
    np.testing.assert_array_equal(x, np.concatenate([kept_good, kept_near]))
    assert _valid(model, x).all()
    assert len(np.unique(np.concatenate([first, x]), axis=0)) == len(first) + len(x)
    assert all(len(a) == 0 for a in gen._spare)


def test_the_preshape_layout_is_built_once_per_hand(setup):
    model, _ = setup
    first = _layout(model)
    assert _layout(model) is first  # the cache's value, not rebuilt per batch
    draws = _draws(model.tables, tuple(f.is_thumb for f in model.hand.fingers))
    for a, b in zip(first[0], draws):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(first[1], _owned(model.tables))


def test_a_thumb_joint_that_moves_another_finger_is_drawn_as_the_thumbs(tmp_path):
    """A thumb's pre-shape joint that also moves another finger (the Schunk SVH's thumb
    opposition turns the palm plate of its ring and little fingers) is drawn anywhere in
    its range, as the thumb's pre-shape joints are, not near its open value as the other
    fingers' abduction is: else GRG's thumb seldom opposes the fingers."""
    path = write_allegro_like(tmp_path, "none")
    text = path.read_text()
    end = text.index("</joint>", text.index('<joint name="ring_joint_0"'))
    # the ring finger's base turns with the thumb's rotation (a mimic joint)
    path.write_text(text[:end] + '<mimic joint="thumb_joint_0" multiplier="0.2" offset="-0.15"/>\n  ' + text[end:])
    hand = load_hand(path)
    fingers = [f for f in hand.fingers if "thumb_joint_0" in f.joints]
    assert sorted(f.is_thumb for f in fingers) == [False, True]  # the thumb's and the ring's
    model = prepare_any_hand(builtin("cube"), hand, PlanOptions())
    j = hand.actuated_joints.index("thumb_joint_0")
    assert j not in _draws(model.tables, tuple(f.is_thumb for f in hand.fingers))[1]
    q = any_hand_grg._preshape(model, 2000, np.random.default_rng(0), 0.5)[:, j]
    low, high = hand.lower[j], hand.upper[j]
    # anywhere in its range (near the open value: within 15 % of the range either side)
    assert q.min() < low + 0.05 * (high - low) and q.max() > high - 0.05 * (high - low)


def test_a_preshape_joint_that_swings_its_finger_around_the_palm_is_drawn_anywhere(tmp_path):
    """A non-thumb pre-shape joint wider than ``WIDE_PRESHAPE`` (the Barrett hand's spread
    swings a finger 180 degrees around the palm, from across the thumb to beside it) sets the
    grasp's type: drawn anywhere in its range, not within ``SPREAD_FRACTION`` of it either side
    of its open value as a finger's abduction is (the Barrett's fingers then met a 5 cm sphere
    with two fingers only). The other fingers' abduction stays near its open value."""
    path = write_allegro_like(tmp_path, "none")
    text = path.read_text()
    start = text.index('<joint name="index_joint_0"')
    end = text.index("</joint>", start)
    wide = text[start:end].replace('lower="-0.47" upper="0.47"', 'lower="0.0" upper="3.1"')
    assert wide != text[start:end]
    path.write_text(text[:start] + wide + text[end:])
    hand = load_hand(path)
    model = prepare_any_hand(builtin("cube"), hand, PlanOptions())
    spread_joints = _draws(model.tables, tuple(f.is_thumb for f in hand.fingers))[1]
    j, k = hand.actuated_joints.index("index_joint_0"), hand.actuated_joints.index("middle_joint_0")
    assert j not in spread_joints and k in spread_joints
    q = any_hand_grg._preshape(model, 2000, np.random.default_rng(0), 0.5)
    assert q[:, j].min() < 0.05 * 3.1 and q[:, j].max() > 0.95 * 3.1  # anywhere in [0, 3.1]
    assert np.abs(q[:, k]).max() <= any_hand_grg.SPREAD_FRACTION * 0.94 + 1e-9  # near its open value, 0


def _same(a, b, skip: tuple[str, ...] = ()) -> None:
    for name in a.__dataclass_fields__:
        if name not in skip:
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_a_particle_decodes_alone_and_the_shortcuts_of_its_variants_change_nothing(setup):
    """What GRG's rounds and the selection's pad alignment rely on: a particle's decoding is
    the same in any batch; the palm clearance of a decoded wrist given back is used as it
    is; a decoding without the scene check differs only in the scene margin; the strict
    reading (``pads_on``) changes only the grasps with a contact whose pad point is off the
    surface."""
    from grasp_apso.geometry.any_hand_decoder import PAD_ON
    from grasp_apso.search.any_hand_grg import sample_any

    model, shape = setup
    x = sample_any(model, shape, 300, np.random.default_rng(5))
    d = decode_any(model, x)
    assert d.scene_margin is not None and (d.n_contacts >= 2).sum() > 30
    order = np.random.default_rng(6).permutation(len(x))
    _same(decode_any(model, x[order]), d.take(order))
    _same(decode_any(model, x, palm=d.palm_clearance), d)
    # the palm given is the one used (a palm deep in the object: nothing legal)
    assert not decode_any(model, x, palm=np.full(len(x), -1.0)).legal(model.settings.max_penetration).any()
    bare = decode_any(model, x, scene_check=False)
    assert bare.scene_margin is None
    _same(bare, d, skip=("scene_margin",))
    strict = decode_any(model, x, pads_on=True)
    off = (d.contact & (d.pad_offset > PAD_ON)).any(axis=1)
    assert off.any() and (~off).any()
    _same(strict.take(np.flatnonzero(~off)), d.take(np.flatnonzero(~off)))
    assert (strict.contact[off] != d.contact[off]).any(axis=1).all()


def test_no_valid_draw_names_finger_joints_the_file_leaves_without_limits(setup, tmp_path):
    # OYMotion's ROHand URDF writes each finger's linkage as free continuous joints (no
    # <mimic>): no draw made two pad contacts, and the message blamed the object's size.
    model, _ = setup
    assert any_hand_grg._why_none(model.hand) == "the object may be too large or too small for this hand"
    path = write_allegro_like(tmp_path, "none")
    text = path.read_text()
    for joint in ("index_joint_2", "index_joint_3", "thumb_joint_2", "thumb_joint_3"):  # continuous, no <limit>
        text, count = re.subn(rf'(<joint name="{joint}" type=")revolute(">(?:(?!</joint>).)*?)\s*<limit [^>]*/>',
                              r"\1continuous\2", text, flags=re.S)
        assert count == 1
    path.write_text(text)
    hand = load_hand(path, spheres=False)
    why = any_hand_grg._why_none(hand)
    assert why.startswith("the file gives 4 finger joints no limits (")
    for joint in ("index_joint_2", "index_joint_3", "thumb_joint_2", "thumb_joint_3"):
        assert joint in why
    assert "closed linkage as free joints" in why


def test_the_grasp_centre_shifts_across_the_palm_within_half_the_reach(setup):
    """The particle's shift moves the grasp centre across the palm (palm x and y), never
    along its normal and never turning it: the line along the palm normal passes beside the
    centre of mass by the shift. GRG keeps the paper's rule (no shift) in about
    ``CENTRED_SHARE`` of its draws and draws the others over the whole range, half the
    hand's reach (half its longest finger) either way."""
    from grasp_apso.geometry.any_hand_decoder import root_poses
    from grasp_apso.geometry.any_hand_tables import SHIFT_FRACTION
    from grasp_apso.search.any_hand_grg import CENTRED_SHARE

    model, shape = setup
    t, lay = model.tables, model.layout
    hand = model.hand
    assert lay.dims == 6 + hand.n_joints and lay.shift == slice(4 + hand.n_joints, 6 + hand.n_joints)
    # the reach, independently: half the longest finger, its first link's origin to its pad, open
    poses = hand.link_transforms(hand.open_configuration())
    reach = 0.5 * max(np.linalg.norm(poses[f.pad_link][:3, :3] @ f.pad_center + poses[f.pad_link][:3, 3]
                                     - poses[hand.finger_links(f)[0]][:3, 3]) for f in hand.fingers)
    np.testing.assert_allclose(t.upper[lay.shift], SHIFT_FRACTION * reach, rtol=1e-9)
    np.testing.assert_allclose(t.lower[lay.shift], -SHIFT_FRACTION * reach, rtol=1e-9)
    x = AnyHandGenerator(model, shape, np.random.default_rng(5)).draw(200)
    s = x[:, lay.shift]
    assert np.all((s >= t.lower[lay.shift]) & (s <= t.upper[lay.shift]))
    # centred: both values exactly zero, in about CENTRED_SHARE of the verified draws (the
    # verification keeps centred and shifted draws at somewhat different rates)
    centred_rows = np.all(s == 0.0, axis=1)
    assert abs(centred_rows.mean() - CENTRED_SHARE) < 0.2, centred_rows.mean()
    moved = s[~centred_rows]
    assert np.all(moved != 0.0)
    assert np.all(moved.min(axis=0) < 0.6 * t.lower[lay.shift]) and np.all(moved.max(axis=0) > 0.6 * t.upper[lay.shift])
    centred = x.copy()
    centred[:, lay.shift] = 0.0
    shifted, plain = root_poses(model, x), root_poses(model, centred)
    np.testing.assert_array_equal(shifted[:, :3, :3], plain[:, :3, :3])
    move = shifted[:, :3, 3] - plain[:, :3, 3]
    palm = plain[:, :3, :3] @ t.basis  # (P, 3, 3): palm x, y, z in the object frame
    np.testing.assert_allclose(np.einsum("pi,pi->p", move, palm[:, :, 2]), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.einsum("pij,pi->pj", palm[:, :, :2], move), s, atol=1e-12)
