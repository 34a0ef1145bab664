"""Guided Random Generation (paper section 4.2) and the shape "parameter factor".

GRG draws particles that are plausible grasps before any optimisation:

1. *Parameter factor*: :func:`classify_shape` compares the mesh with its bounding
   primitives and principal extents and puts it in a sub-class (sphere-like, box-like,
   cylinder-like, elongated). The class guides the wrist orientations sampled (approach a
   box along a face normal, a cylinder or elongated object across its long axis with the
   fingers spread along it, a sphere from anywhere) and scores wrists in the fitness
   (:meth:`ShapeClass.wrist_score`).
2. Random joint angles within the Table 2 limits, biased toward open anthropomorphic
   pre-shapes (low flexion, the thumb pivoted toward opposition), decoded by closing the
   fingers; a particle is kept when it makes at least 2 fingertip contacts.
3. *Verification test*: a finger that penetrates the object (already at its pre-shape,
   or a link deeper than the tolerance) or collides with another finger gets new values
   for that finger only, drawn from a more open range each round, and the particle is
   decoded again (a bounded number of rounds).

Every loop is bounded; :class:`PlanningError` says so when not enough valid
particles can be found.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from ..errors import PlanningError
from ..geometry.decoder import N_DIMS, STANDOFF_INDEX, GraspModel, decode, wrist_transforms
from ..geometry.scene_margins import palm_scene_margins
from ..model.hand import N_FINGERS, rotation_to_wrist_angles, wrist_rotation
from ..model.particle import LAYOUT

SHAPE_CLASSES: tuple[str, ...] = ("sphere-like", "box-like", "cylinder-like", "elongated")
#: With a support plane, this share of GRG's wrists approach straight down its normal
#: (then the usual ~10 degrees of noise); the others keep the class's approach, turned to
#: the free side (top or side grasps).
TOP_FRACTION = 0.5


@dataclass(frozen=True)
class ShapeClass:
    """The shape parameter factor of an object.

    Attributes
    ----------
    name : str
        One of :data:`SHAPE_CLASSES`.
    axes : (3, 3) float
        Principal axes (rows, unit, object frame), longest first.
    extents : (3,) float, m
        Sizes along the axes.
    box_fill : float
        Volume over oriented-bounding-box volume (1 box, 0.785 cylinder, 0.524 sphere).
    support : (K, 3) float
        Unit normals (object frame, pointing into free space) of the support planes the
        object rests on; empty in free space. Wrists are then sampled from the free side:
        the approach (palm normal, pointing into the object) never points up out of a
        support (the hand never comes from below the table), so an object on a table is
        grasped from above or from the side.
    across : bool
        A long (cylinder-like or elongated) object's guidance turned a quarter: the fingers
        (palm x) along the long axis instead of the spread (palm y). On a five-fingered hand
        the thumb opposes the fingers nearly along palm y, so this guidance pinches the
        object across its length (a pen picked off a desk); :meth:`turned`.
    """

    name: str
    axes: np.ndarray
    extents: np.ndarray
    box_fill: float
    support: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)), repr=False)
    across: bool = False

    @property
    def long(self) -> bool:
        """A cylinder-like or elongated object: guided along its long axis (which :meth:`turned` turns)."""
        return self.name in ("cylinder-like", "elongated")

    def turned(self) -> "ShapeClass":
        """This class with a long object's guidance turned (``across``); other classes unchanged."""
        return replace(self, across=True)

    def with_support(self, normals: np.ndarray) -> "ShapeClass":
        """This class with support planes of unit normals (K, 3) (object frame)."""
        n = np.asarray(normals, dtype=float).reshape(-1, 3)
        return replace(self, support=n / np.linalg.norm(n, axis=1, keepdims=True))

    @property
    def standoff_per_width(self) -> float:
        """GRG standoff range, in widths of the object: a sphere-like object is held far
        enough from the palm for the thumb to oppose the fingers (measured: the thumb's
        legal contacts on the 5 cm sphere need 24-50 mm); the others closer, where four
        fingers and the thumb reach around them."""
        return 1.0 if self.name == "sphere-like" else 0.6

    def sample_wrists(self, n: int, rng: np.random.Generator, guided_fraction: float = 0.8) -> np.ndarray:
        """Wrist rotations (palm in the object frame) guided by the class.

        Returns
        -------
        (n, 3, 3) float
            Columns: palm x (fingers), y (thumb side), z (palm normal, toward the object).
        """
        approach = _random_unit(rng, n)
        finger = _random_unit(rng, n)
        guided = rng.random(n) < guided_fraction
        e0, e1, e2 = self.axes
        if self.name == "box-like":
            k = rng.integers(0, 3, n)
            sign = rng.choice([-1.0, 1.0], n)
            approach_g = self.axes[k] * sign[:, None]
            j = (k + rng.integers(1, 3, n)) % 3
            finger_g = self.axes[j] * rng.choice([-1.0, 1.0], n)[:, None]
        elif self.long:
            phi = rng.uniform(0.0, 2.0 * math.pi, n)
            approach_g = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
            along = e0 * rng.choice([-1.0, 1.0], n)[:, None]
            # palm y along the long axis; turned, palm x (the fingers)
            finger_g = along if self.across else np.cross(along, approach_g)
        else:
            approach_g, finger_g = approach, finger
        approach = np.where(guided[:, None], approach_g, approach)
        finger = np.where(guided[:, None], finger_g, finger)
        if len(self.support):
            # Prefer grasps from above (the hand's reach from the side ends at the
            # support): a share of the approaches straight down the first support normal.
            top = rng.random(n) < TOP_FRACTION
            approach = np.where(top[:, None], -self.support[0], self.free_side(approach))
        rot = _frames(approach, finger)
        # A little noise (about 10 degrees) around the guided orientation.
        rot = _small_rotations(rng, n, math.radians(10.0)) @ rot
        if len(self.support):  # the noise may have tipped an approach under the support
            rot = _frames(self.free_side(rot[:, :, 2]), rot[:, :, 0])
        return rot

    def free_side(self, approach: np.ndarray) -> np.ndarray:
        """Approach directions (n, 3) turned to the free side of every support plane.

        An approach with a component along a support normal ``s`` (a hand coming from
        under the support) is flipped (a box-like object's face becomes the opposite
        face, a cylinder's side the other side), then any component left is removed
        (the approach made parallel to the plane); a bounded pass per plane.
        """
        z = np.array(approach, dtype=float)
        for _ in range(2):
            for s in self.support:
                up = z @ s
                z = np.where((up > 0.0)[:, None], -z, z)  # flip to the free side
        for s in self.support:
            up = z @ s
            z = z - np.maximum(up, 0.0)[:, None] * s  # a second plane may have flipped it back
        norm = np.linalg.norm(z, axis=1, keepdims=True)
        fallback = np.broadcast_to(-self.support[0], z.shape)
        return np.where(norm > 1e-6, z / np.maximum(norm, 1e-12), fallback)

    def wrist_score(self, rotations: np.ndarray) -> np.ndarray:
        """How well wrists match the class's approach, in [0, 1].

        rotations : (P, 3, 3) palm in the object frame -> (P,)
        """
        approach = rotations[:, :, 2]
        spread = rotations[:, :, 1]
        if self.name == "box-like":
            cos = np.abs(approach @ self.axes.T).max(axis=1)
            return np.clip((cos - math.sqrt(0.5)) / (1.0 - math.sqrt(0.5)), 0.0, 1.0)
        if self.long:
            along = np.abs(approach @ self.axes[0])
            lengthwise = rotations[:, :, 0] if self.across else spread
            return np.sqrt(np.clip(1.0 - along**2, 0.0, 1.0)) * np.abs(lengthwise @ self.axes[0])
        return np.ones(len(rotations))


def classify_shape(obj) -> ShapeClass:
    """Shape parameter factor of a :class:`~grasp_apso.model.objects.GraspObject`.

    Rules (a >= b >= c the principal extents, fill = volume / (a b c)):
    sphere-like when a / c < 1.3 and fill < 0.65; box-like when fill > 0.85 and a / b < 2;
    cylinder-like when a / b >= 1.3, b / c < 1.25 and 0.65 <= fill <= 0.9; elongated
    otherwise when a / b >= 1.3; remaining compact shapes count as box-like when
    fill > 0.7, else sphere-like.
    """
    extents = np.asarray(obj.principal_extents, dtype=float)
    axes = np.asarray(obj.principal_axes, dtype=float)
    a, b, c = extents
    volume = float(abs(obj.mesh.volume)) if obj.watertight else float(obj.mesh.convex_hull.volume)
    fill = volume / max(a * b * c, 1e-18)
    if a / c < 1.3 and fill < 0.65:
        name = "sphere-like"
    elif fill > 0.85 and a / b < 2.0:
        name = "box-like"
    elif a / b >= 1.3 and b / c < 1.25 and 0.65 <= fill <= 0.9:
        name = "cylinder-like"
    elif a / b >= 1.3:
        name = "elongated"
    else:
        name = "box-like" if fill > 0.7 else "sphere-like"
    return ShapeClass(name=name, axes=axes, extents=extents, box_fill=fill)


def _random_unit(rng: np.random.Generator, n: int) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _frames(approach: np.ndarray, finger: np.ndarray) -> np.ndarray:
    """Rotations with z = approach and x = finger made orthogonal to it: (n, 3, 3)."""
    z = approach / np.linalg.norm(approach, axis=1, keepdims=True)
    x = finger - np.einsum("ni,ni->n", finger, z)[:, None] * z
    norm = np.linalg.norm(x, axis=1, keepdims=True)
    fallback = np.cross(z, np.where(np.abs(z[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]]))
    x = np.where(norm > 1e-6, x / np.maximum(norm, 1e-12), fallback / np.linalg.norm(fallback, axis=1, keepdims=True))
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=2)


def _small_rotations(rng: np.random.Generator, n: int, sigma: float) -> np.ndarray:
    """Random rotations with angle ~ |N(0, sigma)| about random axes: (n, 3, 3)."""
    axis = _random_unit(rng, n)
    angle = rng.normal(0.0, sigma, n)
    k = np.zeros((n, 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    k = k - k.transpose(0, 2, 1)
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    return np.eye(3) + s * k + (1.0 - c) * (k @ k)


@dataclass(frozen=True)
class PreshapeRanges:
    """Fractions of each joint range GRG samples pre-shapes from (anthropomorphic bias).

    Attributes
    ----------
    flexion_max : float
        Distal and proximal flexions are drawn in the lowest ``flexion_max`` of their
        range (an open hand that closes onto the object).
    thumb_pivot_min : float
        Thumb pivot drawn in the top ``1 - thumb_pivot_min`` of its range (opposition).
    standoff_max : float, m
        Standoff offsets drawn in [0, max(standoff_max, standoff_per_width * width)],
        width the object's smallest extent (the shape factor's standoff tuning: a big
        object is held away from the palm so the fingers can curl around it).
    standoff_per_width : float or None
        None: the shape class's value (:attr:`ShapeClass.standoff_per_width`).
    """

    flexion_max: float = 0.6
    thumb_pivot_min: float = 0.3
    standoff_max: float = 0.02
    standoff_per_width: float | None = None

    def opened(self, factor: float) -> "PreshapeRanges":
        """Ranges for regenerating an illegal finger: flexion range times ``factor``,
        thumb pivot nearer its upright end (the thumb then leans away from the object)."""
        return PreshapeRanges(
            flexion_max=self.flexion_max * factor,
            thumb_pivot_min=1.0 - (1.0 - self.thumb_pivot_min) * factor,
            standoff_max=self.standoff_max,
            standoff_per_width=self.standoff_per_width,
        )


def sample_fingers(model: GraspModel, n: int, rng: np.random.Generator, ranges: PreshapeRanges) -> np.ndarray:
    """Finger values (n, 15): pre-shapes within the joint limits, see :class:`PreshapeRanges`."""
    lo, hi = model.lower[LAYOUT.fingers], model.upper[LAYOUT.fingers]
    frac_hi = np.tile([ranges.flexion_max, ranges.flexion_max, 1.0], N_FINGERS)
    frac_lo = np.zeros(15)
    frac_lo[14] = ranges.thumb_pivot_min
    u = rng.uniform(frac_lo, frac_hi, (n, 15))
    return lo + u * (hi - lo)


#: Rounds of wrist sampling with a scene: each round draws WRIST_SCREEN_FACTOR times as
#: many wrists as it still needs (screening a wrist costs a fraction of a round's
#: overhead) and keeps the first ones whose palm keeps clear of the scene.
WRIST_SCREEN_ROUNDS = 6
WRIST_SCREEN_FACTOR = 4
#: Scene only: the GRG *local* share. When the fresh (class-guided) particles are found
#: valid less often than :data:`LOCAL_TARGET_RATE`, up to :data:`LOCAL_MAX_SHARE` of a
#: batch are valid particles found before, perturbed (wrist turned ~:data:`LOCAL_TURN`,
#: standoff moved ~:data:`LOCAL_STANDOFF` m, fingers moved ~:data:`LOCAL_FINGER` of their
#: range): the mix shifts toward the wrist directions and pre-shapes the scene leaves free.
LOCAL_TARGET_RATE = 0.5
LOCAL_MAX_SHARE = 0.8
LOCAL_TURN = math.radians(8.0)
LOCAL_STANDOFF = 0.004
LOCAL_FINGER = 0.06
#: Verification rounds for a particle with a finger too close to the scene.
SCENE_RETRY_ROUNDS = 1
#: Valid particles kept as the seeds of local sampling (the most recent).
ELITE_SIZE = 256


def _standoff_top(model: GraspModel, shape: ShapeClass, ranges: PreshapeRanges) -> float:
    per_width = shape.standoff_per_width if ranges.standoff_per_width is None else ranges.standoff_per_width
    return min(max(ranges.standoff_max, per_width * float(shape.extents[-1])), model.upper[STANDOFF_INDEX])


def sample_particles(
    model: GraspModel, shape: ShapeClass, n: int, rng: np.random.Generator, ranges: PreshapeRanges,
    wrist_position: np.ndarray | None = None,
) -> np.ndarray:
    """Unverified guided particles (n, 19).

    With a scene in the model, only wrists whose palm (swept over the approach) keeps the
    clearance from the scene are kept, drawn in at most :data:`WRIST_SCREEN_ROUNDS`
    rounds (the cheap part of the scene check, before any finger is closed); a particle
    no round finds one for keeps an unscreened wrist.
    """
    x = np.empty((n, N_DIMS))
    x[:, LAYOUT.fingers] = sample_fingers(model, n, rng, ranges)
    top = _standoff_top(model, shape, ranges)
    if model.scene is None:
        x[:, LAYOUT.wrist] = rotation_to_wrist_angles(shape.sample_wrists(n, rng))
        x[:, STANDOFF_INDEX] = rng.uniform(0.0, top, n)
        return x
    todo = np.arange(n)
    for round_ in range(WRIST_SCREEN_ROUNDS):
        m = max(WRIST_SCREEN_FACTOR * len(todo), 32)
        y = np.empty((m, N_DIMS))
        y[:, LAYOUT.wrist] = rotation_to_wrist_angles(shape.sample_wrists(m, rng))
        y[:, STANDOFF_INDEX] = rng.uniform(0.0, top, m)
        if round_ == 0:  # unscreened, for the particles no round finds a clear wrist for
            x[:, 15:] = y[:n, 15:]
        clear = np.flatnonzero(palm_scene_margins(model, wrist_transforms(model, y, wrist_position)) >= 0.0)
        k = min(len(clear), len(todo))
        x[todo[:k], 15:] = y[clear[:k], 15:]
        todo = todo[k:]
        if not len(todo):
            break
    return x


def perturb_particles(model: GraspModel, shape: ShapeClass, seeds: np.ndarray, n: int, rng: np.random.Generator,
                      ranges: PreshapeRanges) -> np.ndarray:
    """``n`` particles near ``seeds`` (S, 19) (valid particles found before): GRG's local
    sampling (see :data:`LOCAL_TARGET_RATE`), within the bounds."""
    x = seeds[rng.integers(0, len(seeds), n)].copy()
    lo, hi = model.lower, model.upper
    span = (hi - lo)[LAYOUT.fingers]
    x[:, LAYOUT.fingers] += rng.normal(0.0, LOCAL_FINGER, (n, 15)) * span
    rot = _small_rotations(rng, n, LOCAL_TURN) @ wrist_rotation(x[:, LAYOUT.wrist])
    if len(shape.support):
        rot = _frames(shape.free_side(rot[:, :, 2]), rot[:, :, 0])
    x[:, LAYOUT.wrist] = rotation_to_wrist_angles(rot)
    x[:, STANDOFF_INDEX] += rng.normal(0.0, LOCAL_STANDOFF, n)
    return np.clip(x, lo, hi)


@dataclass
class GuidedGenerator:
    """GRG with a reservoir of verified particles (APSO draws replacements from it).

    Attributes
    ----------
    refill : int
        Smallest number of particles a reservoir refill generates: a decode of 6
        particles costs a quarter of one of 60 (per-call overhead), so refills come in
        batches (measured with the numpy decoder, where 6 cost nearly as much as 60:
        plan time -10 to -20 %, same fitness).
    evaluations : int
        Particle decodes spent so far (each candidate decode counts as one).
    """

    model: GraspModel
    shape: ShapeClass
    rng: np.random.Generator
    wrist_position: np.ndarray | None = None
    ranges: PreshapeRanges = PreshapeRanges()
    verification_rounds: int = 3
    max_batches: int = 12
    refill: int = 64
    evaluations: int = 0
    #: Decodes the scene check rejected (a scene only).
    scene_rejections: int = 0
    #: Polled between batches: True stops generating (the plan's deadline or a cancel);
    #: what is missing is then filled with unverified particles, and nothing is raised.
    should_stop: Callable[[], bool] | None = None

    def stopped(self) -> bool:
        return self.should_stop is not None and bool(self.should_stop())

    def __post_init__(self) -> None:
        self._pool = np.empty((0, N_DIMS))
        self._elite = np.empty((0, N_DIMS))   # scene only: seeds of the local sampling
        self._fresh = [0, 0]                  # scene only: fresh particles valid, tried

    def _local_share(self) -> float:
        """Share of a batch drawn near earlier valid particles (scene only, see
        :data:`LOCAL_TARGET_RATE`): 0 without a scene or seeds, else growing as the
        fresh particles' valid rate falls below the target."""
        if self.model.scene is None or not len(self._elite):
            return 0.0
        valid, tried = self._fresh
        rate = (valid + 1.0) / (tried + 2.0)
        return float(np.clip(1.0 - rate / LOCAL_TARGET_RATE, 0.0, LOCAL_MAX_SHARE))

    def _sample(self, batch: int) -> tuple[np.ndarray, int]:
        """A batch of unverified particles; the first ``n_fresh`` are class-guided."""
        n_local = int(round(batch * self._local_share()))
        x = sample_particles(self.model, self.shape, batch - n_local, self.rng, self.ranges, self.wrist_position)
        if n_local:
            x = np.concatenate([x, perturb_particles(self.model, self.shape, self._elite, n_local, self.rng,
                                                     self.ranges)])
        return x, batch - n_local

    def verify(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The verification test: regenerate illegal fingers only, a bounded number of rounds.

        Only the particles with an illegal finger are decoded again, and of them only the
        regenerated fingers are closed again (the others keep their decoding; collisions
        between fingers are checked anew). A particle decoded again counts as one more
        evaluation, as a full decode would.

        x : (B, 19) -> (x after regeneration, (B,) bool valid: legal and >= 2 contacts)
        """
        limit = self.model.settings.max_penetration
        x = x.copy()
        valid = np.zeros(len(x), dtype=bool)
        todo = np.arange(len(x))
        decoded, bad = None, None
        for round_ in range(self.verification_rounds + 1):
            decoded = decode(self.model, x[todo], self.wrist_position, reuse=decoded, changed=bad)
            self.evaluations += len(todo)
            bad = decoded.finger_illegal(limit)
            valid[todo] = ~bad.any(axis=1) & (decoded.n_contacts >= 2)
            if decoded.palm_scene_margin is not None:
                valid[todo] &= decoded.palm_scene_margin >= 0.0
                self.scene_rejections += int(((decoded.scene_margin < 0).any(axis=1)
                                              | (decoded.palm_scene_margin < 0)).sum())
            retry = bad.any(axis=1)
            if decoded.palm_scene_margin is not None:
                # A palm too close stays so (its wrist is kept); a finger too close to
                # the scene rarely clears with a more open pre-shape (measured: 5 % in the
                # first round, about 1 % after): such particles get one round only.
                retry &= decoded.palm_scene_margin >= 0.0
                if round_ >= SCENE_RETRY_ROUNDS:
                    retry &= ~(decoded.scene_margin < 0.0).any(axis=1)
            if round_ == self.verification_rounds or not retry.any():
                break
            todo, bad, decoded = todo[retry], bad[retry], decoded.take(retry)
            ranges = self.ranges.opened(0.6 ** (round_ + 1))
            fresh = sample_fingers(self.model, len(todo), self.rng, ranges).reshape(-1, N_FINGERS, 3)
            fingers = x[todo, :15].reshape(-1, N_FINGERS, 3)
            fingers[bad] = fresh[bad]
            x[todo, :15] = fingers.reshape(-1, 15)
        return x, valid

    def generate(self, n: int) -> tuple[np.ndarray, int]:
        """Up to ``n`` verified particles.

        Returns
        -------
        x : (n, 19) float
            Valid particles first; when fewer than ``n`` were found within ``max_batches``
            batches, the rest are unverified candidates (APSO will replace them).
        n_valid : int
        """
        if n <= 0:
            raise ValueError(f"n: expected a positive count, got {n}")
        found: list[np.ndarray] = []
        spare = np.empty((0, N_DIMS))
        count = 0
        for i in range(self.max_batches):
            if i and self.stopped():
                break
            batch = max(2 * (n - count), 16)
            if self.model.scene is None:
                x, valid = self.verify(sample_particles(self.model, self.shape, batch, self.rng, self.ranges,
                                                        self.wrist_position))
            else:
                x, n_fresh = self._sample(batch)
                x, valid = self.verify(x)
                self._fresh[0] += int(valid[:n_fresh].sum())
                self._fresh[1] += n_fresh
                self._elite = np.concatenate([self._elite, x[valid]])[-ELITE_SIZE:]
            found.append(x[valid])
            spare = x[~valid]
            count += int(valid.sum())
            if count >= n:
                break
        good = np.concatenate(found)[:n] if found else np.empty((0, N_DIMS))
        if len(good) < n:
            good = np.concatenate([good, spare[: n - len(good)]])
        return good, min(count, n)

    def draw(self, k: int) -> np.ndarray:
        """``k`` verified particles from the reservoir (refilled in batches when low).

        Raises PlanningError when no valid particle can be generated.
        """
        if len(self._pool) < k:
            fresh, n_valid = self.generate(max(2 * k, self.refill))
            if n_valid == 0 and self.stopped():
                return fresh[:k]  # stopped: the swarm ends at its next check, nothing to verify
            if n_valid == 0 and self.model.scene is not None:
                raise PlanningError(
                    f"scene: no collision-free grasp: GRG found no grasp with 2 or more fingertip "
                    f"contacts that keeps the clearance ({self.model.scene_clearance * 1000:.1f} mm) from "
                    f"the support planes and obstacles at the grasp and along the approach "
                    f"({self.evaluations} candidate decodes, {self.scene_rejections} rejected by the scene); "
                    "the scene leaves no room for the hand", "scene"
                )
            if n_valid == 0:
                raise PlanningError(
                    f"object: GRG found no grasp with 2 or more fingertip contacts in {self.evaluations} "
                    f"candidate decodes (shape class {self.shape.name}, smallest extent "
                    f"{self.shape.extents[-1]:.3f} m); the object may not suit this hand"
                )
            self._pool = np.concatenate([self._pool, fresh[:n_valid]])
        k_avail = min(k, len(self._pool))
        out, self._pool = self._pool[:k_avail], self._pool[k_avail:]
        if k_avail < k:  # a reservoir refill found fewer than k: repeat what it has
            out = out[self.rng.integers(0, k_avail, k)]
        return out
