"""Guided Random Generation: shape factor, guided wrists, verification test, bounds."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from grasp_apso.geometry.decoder import decode
from grasp_apso.search.grg import (
    GuidedGenerator, PreshapeRanges, classify_shape, rotation_to_wrist_angles, sample_particles,
)
from grasp_apso.model.hand import load_hand, wrist_rotation
from grasp_apso.model.objects import from_arrays
from grasp_apso.model.builtin import builtin
from grasp_apso.search.planner import prepare


@pytest.mark.parametrize(
    "name, expected",
    [("sphere", "sphere-like"), ("cube", "box-like"), ("barrel", "cylinder-like"), ("fish", "elongated")],
)
def test_builtin_objects_fall_in_their_shape_class(name, expected):
    assert classify_shape(builtin(name)).name == expected


def test_wrist_angles_invert_the_wrist_rotation():
    rng = np.random.default_rng(3)
    angles = np.stack([rng.uniform(-3, 3, 200), rng.uniform(-1.5, 1.5, 200), rng.uniform(-3, 3, 200)], axis=1)
    rot = wrist_rotation(angles)
    np.testing.assert_allclose(wrist_rotation(rotation_to_wrist_angles(rot)), rot, atol=1e-9)


def test_guided_wrists_follow_the_shape_class():
    rng = np.random.default_rng(4)
    cube = classify_shape(builtin("cube"))
    approach = cube.sample_wrists(400, rng, guided_fraction=1.0)[:, :, 2]
    # Approach along a face normal, within the ~10 degree noise (a few sigma).
    assert (np.abs(approach @ cube.axes.T).max(axis=1) > np.cos(np.radians(35))).all()
    barrel = classify_shape(builtin("barrel"))
    rot = barrel.sample_wrists(400, rng, guided_fraction=1.0)
    along = np.abs(rot[:, :, 2] @ barrel.axes[0])
    spread = np.abs(rot[:, :, 1] @ barrel.axes[0])
    assert np.median(along) < np.sin(np.radians(15))   # across the long axis
    assert np.median(spread) > np.cos(np.radians(15))  # fingers spread along it
    assert barrel.wrist_score(rot).mean() > 0.8
    assert (barrel.wrist_score(rot) >= 0).all() and (barrel.wrist_score(rot) <= 1).all()


def test_turned_guidance_puts_the_fingers_along_a_long_object():
    """``ShapeClass.turned``: the guided wrists and the shape factor take palm x (the
    fingers), not palm y, along the long axis; a box-like object's guidance is unchanged."""
    barrel = classify_shape(builtin("barrel"))
    turned = barrel.turned()
    rot = turned.sample_wrists(400, np.random.default_rng(4), guided_fraction=1.0)
    axis = barrel.axes[0]
    assert np.median(np.abs(rot[:, :, 2] @ axis)) < np.sin(np.radians(15))  # still across the long axis
    assert np.median(np.abs(rot[:, :, 0] @ axis)) > np.cos(np.radians(15))  # fingers along it
    assert np.median(np.abs(rot[:, :, 1] @ axis)) < np.sin(np.radians(15))
    assert turned.wrist_score(rot).mean() > 0.8
    assert barrel.wrist_score(rot).mean() < 0.2  # the paper's guidance scores them low
    cube = classify_shape(builtin("cube"))
    np.testing.assert_array_equal(cube.turned().sample_wrists(50, np.random.default_rng(1)),
                                  cube.sample_wrists(50, np.random.default_rng(1)))
    assert not barrel.across and turned.across
    assert barrel.long and classify_shape(builtin("fish")).long and not cube.long
    assert not classify_shape(builtin("sphere")).long


def test_verification_regenerates_only_the_offending_finger():
    model = prepare(builtin("cube"), load_hand())
    shape = classify_shape(builtin("cube"))
    rng = np.random.default_rng(11)
    x = sample_particles(model, shape, 200, rng, PreshapeRanges())
    # Force a collision: the thumb raised and flexed into the object at its pre-shape.
    x[:, 12] = 0.0                # thumb distal
    x[:, 13] = np.radians(40.0)   # thumb proximal
    x[:, 14] = np.radians(60.0)   # thumb pivot
    before = decode(model, x)
    forced = before.blocked[:, 4] | before.finger_collision[:, 4]
    assert forced.mean() > 0.9, "the forced thumb should be illegal in most particles"
    illegal_before = before.finger_illegal(model.settings.max_penetration)
    # One round: exactly the fingers found illegal get new values; the rest and the
    # wrist are untouched.
    one = GuidedGenerator(model, shape, np.random.default_rng(5), verification_rounds=1)
    fixed, _ = one.verify(x)
    for f in range(5):
        keep = ~illegal_before[:, f]
        np.testing.assert_array_equal(fixed[keep, 3 * f:3 * f + 3], x[keep, 3 * f:3 * f + 3])
    np.testing.assert_array_equal(fixed[:, 15:], x[:, 15:])
    assert (fixed[forced, 12:15] != x[forced, 12:15]).any(axis=1).all()
    # Three rounds (a regenerated thumb may newly collide with a neighbour, which is then
    # regenerated in turn): most forced particles become legal, validity is reported
    # truthfully, and the wrists are still untouched.
    gen = GuidedGenerator(model, shape, np.random.default_rng(5), verification_rounds=3)
    fixed, valid = gen.verify(x)
    after = decode(model, fixed)
    np.testing.assert_array_equal(fixed[:, 15:], x[:, 15:])
    legal_after = after.legal(model.settings.max_penetration)
    assert legal_after[forced].mean() > 0.6
    np.testing.assert_array_equal(valid, legal_after & (after.n_contacts >= 2))
    assert gen.evaluations >= 200


def test_generation_is_bounded_when_no_grasp_exists():
    # A thin rod far thinner than the tolerance band cannot make two fingertip contacts
    # that are legal... use a large flat-ish slab instead: fingers are blocked or miss.
    slab = trimesh.creation.box(extents=[0.15, 0.15, 0.15])
    obj = from_arrays(slab.vertices, slab.faces, name="big box")
    model = prepare(obj, load_hand())
    gen = GuidedGenerator(model, classify_shape(obj), np.random.default_rng(0), max_batches=3)
    x, n_valid = gen.generate(60)
    assert x.shape == (60, 19)
    assert gen.evaluations <= 3 * 120 * (gen.verification_rounds + 1)
    assert n_valid <= 60


def test_generation_stops_between_batches_when_asked():
    """A plan's deadline reaches GRG's start (issue 19.6): with ``should_stop`` true,
    generation ends after its first batch and returns what it has, without raising,
    even for an object where no grasp exists."""
    slab = trimesh.creation.box(extents=[0.15, 0.15, 0.15])
    obj = from_arrays(slab.vertices, slab.faces, name="big box")
    model = prepare(obj, load_hand())
    free = GuidedGenerator(model, classify_shape(obj), np.random.default_rng(0), max_batches=3)
    free.generate(60)
    polls = []
    stopped = GuidedGenerator(model, classify_shape(obj), np.random.default_rng(0), max_batches=3,
                              should_stop=lambda: polls.append(1) or True)
    x = stopped.draw(60)  # no valid particle: would raise PlanningError if not stopped
    assert x.shape == (60, 19) and np.all(np.isfinite(x))
    assert polls, "the stop predicate was never polled"
    one_batch = 2 * max(2 * 60, stopped.refill) * (stopped.verification_rounds + 1)
    assert stopped.evaluations <= one_batch < free.evaluations


def test_a_plan_stopped_at_once_spends_about_one_grg_batch():
    """plan() hands its stop predicate to GRG: a 1000-particle plan stopped from the first
    poll decodes at most GRG's first batch (2000 particles and their verification rounds)
    and no iteration."""
    from grasp_apso.search.planner import PlanOptions, plan

    result = plan(builtin("sphere"), options=PlanOptions(particles=1000, iterations=10000),
                  rng=np.random.default_rng(1), should_stop=lambda: True)
    assert result.cancelled
    assert result.iterations_run == 0
    assert result.evaluations <= 2 * 1000 * 4 + 5000  # one batch + the final verification's decodes
