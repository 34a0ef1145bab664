"""Guided Random Generation for a general hand (paper section 4.2, the hand as data).

Wrist orientations from the shape class (:meth:`grasp_apso.search.grg.ShapeClass.sample_wrists`,
which also turns them to the free side of support planes), standoffs in the hand's range
(biased toward the palm), pre-shapes within the joint limits: each closing joint in the
open part of its range (:data:`OPEN_FRACTION` from the limit opposite its closing sense; a
claw's from past its open posture where it can bend back, :data:`CLAW_OPEN_PAST`),
the thumb's and a claw's pre-shape joints anywhere in their range (the thumb's also where
they move another finger too), as is any pre-shape joint wider than :data:`WIDE_PRESHAPE`
(the Barrett hand's spread); the other fingers' abduction near its open value; the grasp
centre's shift across the palm zero in :data:`CENTRED_SHARE` of the draws (the paper's
rule), else uniform within its bounds. A particle is kept when its
decoding is legal with at least two pad contacts; an illegal finger gets a new, more open
pre-shape (:data:`REGENERATE_ROUNDS` bounded rounds).

The swarm asks for a few particles per iteration, each call a batch of a dozen draws or
so. The draws are sampled and verified in a pool of at least :data:`POOL_BATCH` at a time
(one decode per regeneration round for many calls' batches), and each call takes the batch
it would have drawn from that pool: the same draws in distribution (measured: 699
scene-clear and 1101 scene-violating valid draws in six Barrett-sphere runs of 40 calls,
against 696 and 1104 with a batch sampled per call), in fewer and larger decodes: GRG's
time per plan about halved (Shadow 360 -> 190 ms), plans 13-22 % quicker
(``bench/bench_any_hand.py``). Best grasps held over seeds 0-2 (``bench/held_rate.py
--seeds 3``): Inspire 46 -> 47, LEAP 39 -> 35 of 63; candidates held 190/256 -> 208/255,
105/180 -> 110/182.

A call's batch oversamples (:data:`DRAW_FACTOR`), and the valid draws it takes beyond the
k asked for wait for the next call instead of being dropped. Measured (the built-in
sphere, cube, barrel and the mug on a table, seeds 0-1): GRG's decodes per plan LEAP
2340 -> 1496, Shadow 1406 -> 1034. The draws handed out are clear of the scene less
often (LEAP 45 % -> 31 %, Shadow 64 % -> 46 %: the old order dropped the surplus, mostly
draws legal but for the scene). Best grasps held (``bench/held_rate.py --seeds 3``, 11
hands): seeds 0-2 495 -> 490 of 693, seeds 3-5 490 -> 493 (per hand -6..+5, within the
seeds' spread). Plan time with the exact check's saving on non-convex objects
(:func:`grasp_apso.geometry.any_hand_queries.object_distances`), ``bench/bench_any_hand.py
--runs 5``, three runs each interleaved: LEAP 2.8x, 2.6x, 2.6x -> 2.3x, 2.3x, 2.4x of the
paper hand's; ``--runs 2 --objects all`` (the 4 built-ins and 17 meshes): LEAP mean 0.85
-> 0.70 s, Inspire 0.75 -> 0.61 s, Shadow 0.63 -> 0.58 s. Earlier tries of the same
(README, "Tried and left out") found no plan quicker: whether a plan searches twice
decides much of its time.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from ..cache import cached
from ..errors import PlanningError
from ..geometry.any_hand_decoder import AnyHandModel, decode_any
from ..model.hand import rotation_to_wrist_angles
from ..model.hands.description import CONTINUOUS_RANGE
from .grg import ShapeClass

__all__ = ["AnyHandGenerator", "sample_any"]

OPEN_FRACTION = 0.5
#: ... for a hand whose fingers close ahead of their open tips (a claw:
#: ``HandTables.closes_ahead``): pre-curled half way, the tips already point inward or back
#: at the palm. Measured on dex-urdf's D'Claw, 600 draws on the sphere, cube, barrel and mug:
#: valid after GRG's regeneration 1-4 % of draws at 0.5, 6-13 % at 0.1.
CLAW_OPEN_FRACTION = 0.1
#: ... and a claw's closing joints that can open past the open posture (each finger of a
#: Schunk SDH bends back 90 degrees, a D'Claw's too) are drawn from this share of that
#: opening on: straight, a gripper's fingers stand too close together to take most objects
#: between them (the SDH's 6 cm apart: no grasp of a 7 cm cube).
CLAW_OPEN_PAST = 0.5
#: Pre-shape joints of the fingers other than the thumb: within this fraction of their
#: range either side of the open value (the thumb's: anywhere, for opposition).
SPREAD_FRACTION = 0.15
#: ... unless the joint turns its finger farther than this (rad): no finger's abduction
#: spans more than about 120 degrees (LEAP's 2.09 rad, the widest of the 13 hands measured); a
#: wider pre-shape joint swings its finger around the palm (the Barrett hand's spread, 180
#: degrees) and sets the grasp's type, as a claw's knuckle does: drawn anywhere in range.
#: Measured on dex-urdf's Barrett (``bench/held_rate.py --seeds 3 --dexgraspbench --hand
#: barrett``, 63 plans on a table): its two fingers' spread drawn within 27 degrees of
#: straight across from the thumb, where on the 5 cm sphere a half-closed finger swings its
#: pad outward and misses, no GRG draw touched with three fingers (4000 draws); drawn
#: anywhere, 3 % did. Best grasps held 37 -> 47 in our check and 45 -> 56 with
#: DexGraspBench's parameters (in ours the sphere 0 -> 2 of 3, the orange and the baseball
#: 0 -> 3, the cup 0 -> 2, the screwdriver 0 -> 2, the barrel 2 -> 0), median plan 1.3 ->
#: 0.9 s. The other 12 hands measured have no pre-shape joint this wide: their plans are
#: unchanged.
WIDE_PRESHAPE = 2.5
#: The share of draws whose grasp centre keeps the paper's rule (no shift across the palm:
#: on the line along the palm normal through the centre of mass); the others shift uniformly
#: within the bounds (``HandTables``, ``SHIFT_FRACTION``). With every draw shifted, fewer
#: balanced grasps come from one search where the centred ones were many: the Inspire's
#: plans on the cube took two or three searches (``bench/bench_any_hand.py --runs 5``: 2.6x
#: the paper hand's plan time, 1.6x before the shift); with half centred 1.5x. Best grasps
#: held with DexGraspBench's parameters (``bench/held_rate.py --seeds 3 --dexgraspbench``,
#: 13 hands) 703 -> 702 of 819, in our check 633 -> 640: per hand within the seeds'
#: spread (the Barrett 53 -> 58, the Allegro-like hand 56 -> 52).
CENTRED_SHARE = 0.5
#: Rounds of regenerating illegal fingers (each more open by REGENERATE_FACTOR) and fingers
#: without a pad contact (another pre-shape).
REGENERATE_ROUNDS = 4
REGENERATE_FACTOR = 0.5
#: Rounds of drawing batches and the batch size over the particles wanted.
DRAW_ROUNDS = 12
DRAW_FACTOR = 1.5
#: Batches are sized by the valid share seen so far (at least MIN_RATE), at most MAX_BATCH.
MIN_RATE = 0.05
MAX_BATCH = 400
#: The swarm asks for a few particles per iteration (``max_replacements`` of it), each call
#: a batch of a dozen draws or so: the draws are sampled and verified at least this many
#: at a time, and the calls take their batches from that pool.
POOL_BATCH = 64


def _draws(tables, thumbs: tuple[bool, ...]) -> tuple[np.ndarray, ...]:
    """The pre-shape's per-joint draws of a hand, in :func:`_preshape`'s order: (spread rows,
    their joints, their half widths; closing rows, their joints, their closing limits, how
    far past the open posture each is drawn from (rad, signed; 0 but for a claw's joints
    that open past it: :data:`CLAW_OPEN_PAST`)). Rows index the draws."""
    t = tables
    lo, hi = t.lower[t.layout.joints], t.upper[t.layout.joints]
    # The thumb's pre-shape joints are drawn anywhere, also where they move another finger
    # too (the Schunk SVH's thumb opposition turns the palm plate of the ring and little
    # fingers): drawn as that finger's abduction, near its open value, the thumb would
    # seldom oppose the fingers.
    thumb_joints = {int(t.j_index[f, k]) for f in range(t.n_fingers) if thumbs[f]
                    for k in range(int(t.j_count[f])) if np.isnan(t.j_target[f, k])}
    spread, spread_j, half, closing, closing_j, target, past = [], [], [], [], [], [], []
    row = 0
    for f in range(t.n_fingers):
        for k in range(int(t.j_count[f])):
            j = int(t.j_index[f, k])
            if np.isnan(t.j_target[f, k]):
                # abduction near its open value: spread fingers collide. A claw's fingers stand
                # apart around its palm, and its pre-shape joints set the grasp's type (the
                # Schunk SDH's knuckle turns two fingers from facing the thumb to a triangle):
                # anywhere in their range, as the thumb's; so is a joint that swings its
                # finger around the palm (WIDE_PRESHAPE).
                if j not in thumb_joints and not t.closes_ahead and hi[j] - lo[j] <= WIDE_PRESHAPE:
                    spread.append(row)
                    spread_j.append(j)
                    half.append(SPREAD_FRACTION * (hi[j] - lo[j]))
                    row += 1
                continue  # the thumb's pre-shape joints: anywhere in their range
            closing.append(row)
            closing_j.append(j)
            target.append(float(t.j_target[f, k]))
            opposite = lo[j] if target[-1] == hi[j] else hi[j]  # the limit against its closing sense
            past.append(CLAW_OPEN_PAST * (opposite - t.open_q[j]) if t.closes_ahead else 0.0)
            row += 1
    ints = (lambda v: np.array(v, dtype=np.int64))
    return (ints(spread), ints(spread_j), np.array(half, dtype=float), ints(closing), ints(closing_j),
            np.array(target, dtype=float), np.array(past, dtype=float))


def _owned(tables) -> np.ndarray | None:
    """(F, n) bool: the joints each finger closes or pre-shapes; None when a joint belongs
    to two fingers (then the fingers are regenerated one after the other)."""
    owned = np.zeros((tables.n_fingers, tables.layout.n_joints), dtype=bool)
    for f in range(tables.n_fingers):
        owned[f, tables.j_index[f, :int(tables.j_count[f])]] = True
    return None if (owned.sum(axis=0) > 1).any() else owned


def _layout(model: AnyHandModel) -> tuple[tuple[np.ndarray, ...], np.ndarray | None]:
    """The hand's draws (:func:`_draws`) and owned joints (:func:`_owned`), built once per
    hand: they depend on its tables only, and GRG asks for them on every batch (measured:
    about 3 % of a Shadow plan when built each time)."""
    t = model.tables
    return cached("grg_layout", model.hand.source_hash,
                  lambda: (_draws(t, tuple(f.is_thumb for f in model.hand.fingers)), _owned(t)))


def _preshape(model: AnyHandModel, n: int, rng: np.random.Generator, fraction: float) -> np.ndarray:
    """Pre-shapes (n, n_joints) within the limits (see the module docstring).

    Every drawn joint's n values come from one ``rng.random`` block in the order of the
    fingers and their joints, each as ``rng.uniform`` would make it (``low + (high - low)
    u``): the same values, bit for bit, as one ``rng.uniform`` call per joint."""
    t = model.tables
    lo, hi = t.lower[t.layout.joints], t.upper[t.layout.joints]
    q = rng.uniform(lo, hi, (n, len(lo)))
    spread, spread_j, half, closing, closing_j, target, past = _layout(model)[0]
    u = rng.random((len(spread) + len(closing), n))
    if len(spread):
        offset = (-half)[:, None] + (half - (-half))[:, None] * u[spread]
        q[:, spread_j] = np.clip(t.open_q[spread_j][:, None] + offset, lo[spread_j][:, None], hi[spread_j][:, None]).T
    if len(closing):
        start = t.open_q[closing_j][:, None]
        q[:, closing_j] = (start + (fraction * u[closing]) * (target[:, None] - start)).T
        wide = np.flatnonzero(past)
        if len(wide):  # a claw's joints that open past the open posture: from there on
            first = start[wide] + past[wide, None]
            end = start[wide] + fraction * (target[wide, None] - start[wide])
            q[:, closing_j[wide]] = (first + u[closing[wide]] * (end - first)).T
    return q


def _why_none(hand) -> str:
    """The likeliest reason no draw of ``hand`` made two pad contacts, for the message:
    finger joints the file leaves without limits (continuous: :data:`CONTINUOUS_RANGE`
    taken) when it has them, else the object's size."""
    lower, upper = np.asarray(hand.lower, float), np.asarray(hand.upper, float)
    free = [j for finger in hand.fingers for j in finger.joints
            if (lower[k := hand.actuated_joints.index(j)], upper[k]) == CONTINUOUS_RANGE]
    if free:
        shown = ", ".join(free[:6]) + (f" and {len(free) - 6} more" if len(free) > 6 else "")
        return (f"the file gives {len(free)} finger joints no limits ({shown}: continuous, [-pi, pi] taken), "
                "which no real finger joint is: a description that writes a finger's closed linkage as free "
                "joints (no <mimic> tying them) closes no finger as the hand does; describe the linkage's "
                "driven joints with their limits and couplings")
    return "the object may be too large or too small for this hand"


def sample_any(model: AnyHandModel, shape: ShapeClass, n: int, rng: np.random.Generator) -> np.ndarray:
    """n GRG particles (n, D)."""
    t, lay = model.tables, model.layout
    x = np.empty((n, lay.dims))
    x[:, lay.wrist] = rotation_to_wrist_angles(shape.sample_wrists(n, rng))
    x[:, lay.standoff] = t.upper[lay.standoff] * rng.random(n) ** 1.5
    x[:, lay.joints] = _preshape(model, n, rng, _open_fraction(model))
    x[:, lay.shift] = rng.uniform(t.lower[lay.shift], t.upper[lay.shift], (n, 2))
    x[rng.random(n) < CENTRED_SHARE, lay.shift] = 0.0
    return x


def _open_fraction(model: AnyHandModel) -> float:
    """How far GRG pre-shapes the closing joints (:data:`OPEN_FRACTION`, a claw's
    :data:`CLAW_OPEN_FRACTION`)."""
    return CLAW_OPEN_FRACTION if model.tables.closes_ahead else OPEN_FRACTION


class AnyHandGenerator:
    """GRG draws for the swarm (``draw``), with the verification test; counts evaluations."""

    def __init__(self, model: AnyHandModel, shape: ShapeClass, rng: np.random.Generator,
                 wrist_position: np.ndarray | None = None, should_stop: Callable[[], bool] | None = None):
        self.model, self.shape, self.rng = model, shape, rng
        self.wrist_position = wrist_position
        self.should_stop = should_stop
        self.evaluations = 0
        self.rate = 1.0  # share of draws found valid so far (sizes the batches)
        # The pool of verified draws the calls take their batches from (x, good, near),
        # the next one at _pool_at.
        self._pool = (np.empty((0, model.layout.dims)), np.zeros(0, dtype=bool), np.zeros(0, dtype=bool))
        self._pool_at = 0
        # Valid draws a call took but did not hand out (its batch oversamples): scene-clear
        # ones and legal-but-for-the-scene ones, handed out first by the next calls.
        self._spare = (np.empty((0, model.layout.dims)), np.empty((0, model.layout.dims)))

    def _verified(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Regenerate illegal fingers in bounded rounds (only the changed particles are
        decoded again): (x, good (n,) bool, near (n,) bool: valid but for the scene)."""
        t, s = self.model.tables, self.model.settings
        fraction = _open_fraction(self.model)
        good = np.zeros(len(x), dtype=bool)
        near = np.zeros(len(x), dtype=bool)
        rows = np.arange(len(x))
        palm = None  # (n,) from the first round: the rounds change only joints
        for round_ in range(REGENERATE_ROUNDS + 1):
            decoded = decode_any(self.model, x[rows], self.wrist_position,
                                 palm=None if palm is None else palm[rows])
            if palm is None:
                palm = decoded.palm_clearance
            self.evaluations += len(rows)
            # Legal but for the scene counts too (the swarm's fitness guides it out of the
            # scene; the final selection requires it clear): scene-clear ones come first.
            illegal = decoded.finger_illegal(s.max_penetration)
            near[rows] = ~illegal.any(axis=1) & (decoded.palm_clearance >= -s.max_penetration) & (
                decoded.n_contacts >= 2)
            good[rows] = near[rows] & decoded.legal(s.max_penetration)
            bad = illegal & ~near[rows][:, None]
            # Fingers of particles not yet valid that made no pad contact try another
            # pre-shape (each finger closes on its own, so the others keep theirs): a pad
            # meets the surface only at some fingertip angles.
            retry = ~decoded.contact & ~illegal & ~near[rows][:, None]
            if round_ == REGENERATE_ROUNDS or not (bad.any() or retry.any()):
                break
            fraction *= REGENERATE_FACTOR
            fresh = _preshape(self.model, len(rows), self.rng, fraction)
            other = _preshape(self.model, len(rows), self.rng, _open_fraction(self.model))
            owned = _layout(self.model)[1]
            if owned is not None:  # all fingers at once (bad and retry exclude each other)
                joints = x[rows, t.layout.joints]
                joints = np.where((bad[:, :, None] & owned[None]).any(axis=1), fresh, joints)
                x[rows, t.layout.joints] = np.where((retry[:, :, None] & owned[None]).any(axis=1), other, joints)
            else:
                for f in range(t.n_fingers):
                    joints = 4 + t.j_index[f, :int(t.j_count[f])]
                    for sel, new in ((bad[:, f], fresh), (retry[:, f], other)):
                        x[np.ix_(rows[sel], joints)] = new[np.ix_(sel, joints - 4)]
            rows = rows[(bad | retry).any(axis=1)]
        return x, good, near & ~good

    def _take(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The next n verified draws (x, good, near as :meth:`_verified`), from a pool
        verified in batches of at least :data:`POOL_BATCH` (each decode costs about 0.35 ms
        besides its particles, and a batch decodes up to 1 + REGENERATE_ROUNDS times)."""
        if self._pool_at + n > len(self._pool[0]):
            rest = tuple(a[self._pool_at:] for a in self._pool)
            fresh = self._verified(sample_any(self.model, self.shape, max(n, POOL_BATCH), self.rng))
            self._pool = tuple(np.concatenate([a, b]) for a, b in zip(rest, fresh))
            self._pool_at = 0
        out = tuple(a[self._pool_at:self._pool_at + n] for a in self._pool)
        self._pool_at += n
        return out

    def draw(self, k: int) -> np.ndarray:
        """k particles: valid ones first (scene-clear ones, then legal but for the scene);
        filled with the last batch's others when the bounded rounds find fewer. The valid
        draws earlier calls took but did not hand out come first; then batches sized by the
        valid share seen so far, taken from the pool (:meth:`_take`); the valid draws this
        call does not hand out are kept for the next. PlanningError when no draw decodes to
        a valid grasp."""
        found: list[np.ndarray] = [self._spare[0]]
        close: list[np.ndarray] = [self._spare[1]]
        others: np.ndarray | None = None  # the last batch's draws that are not valid
        count = len(self._spare[0]) + len(self._spare[1])
        for _ in range(DRAW_ROUNDS):
            if count >= k or (self.should_stop is not None and self.should_stop()):
                break
            batch = int(min(MAX_BATCH, np.ceil(DRAW_FACTOR * (k - count) / max(self.rate, MIN_RATE))))
            x, good, near = self._take(batch)
            self.rate = 0.5 * self.rate + 0.5 * float(np.mean(good | near))
            found.append(x[good])
            close.append(x[near])
            count += int(good.sum()) + int(near.sum())
            others = x[~good & ~near]
        clear = np.concatenate(found)  # the scene-clear draws (``good`` in the batches)
        valid = np.concatenate([clear] + close)
        # what this call does not hand out (valid[k:]) waits for the next, in its kind
        self._spare = (clear[k:], valid[max(k, len(clear)):])
        if len(valid) == 0 and not (self.should_stop is not None and self.should_stop()):
            raise PlanningError(
                f"object: no valid grasp for hand {self.model.hand.name!r}: GRG decoded "
                f"{self.evaluations} candidates (shape class {self.shape.name}) and none made two legal pad "
                f"contacts; {_why_none(self.model.hand)}")
        if len(valid) >= k:
            return valid[:k]
        rest = others if others is not None and len(others) else sample_any(self.model, self.shape, k, self.rng)
        fill = rest[self.rng.integers(0, len(rest), k - len(valid))]
        return np.concatenate([valid, fill]) if len(valid) else fill
