"""The final verification and selection of the candidates (issues 11 and 12).

Each grasp returned is verified independently of the swarm's fitness: fingertip contacts
decoded again, the Ferrari-Canny epsilon with friction cones
(:func:`grasp_apso.quality.measures.epsilon_quality`), python-fcl collisions of the links
with the object mesh and between fingers (:func:`grasp_apso.geometry.collision.verify_with_fcl`)
and, with a scene, python-fcl distances of the whole hand to the scene at the grasp, at
the pre-grasp and along the approach (:mod:`grasp_apso.geometry.hand_fcl`, not the
decoder's distances). A candidate is *valid* when the decoder finds it legal with 2 or
more contacts, fcl finds no penetration nor finger collision, and (scene) the hand keeps
the clearance from the scene at the grasp and along the approach from the pre-grasp,
where the open hand also stays off the object.

:func:`select_candidates` verifies the leaders' archive (:mod:`.archive`) in descending
fitness until ``max_grasps`` valid, *robust* force-closure grasps, pairwise distinct, are
found or the archive is exhausted (bounded by its capacity), then fills up with valid
force-closure grasps whose closure rests on a contact with an ill-defined normal (an edge,
a corner, a rim: :func:`grasp_apso.quality.robustness.robust_epsilon` is 0 for them), then
with (only when no force-closure grasp was found at all) the single best valid grasp that
is not. Ranking: :mod:`.ranking`.

Why robust: in the MuJoCo check (``bench/held_rate.py``) 6 of the 7 force-closure grasps
that dropped had a robust epsilon of 0 (a contact at an edge or a rim whose normal spread,
38-77 degrees, exceeds the friction cone's 26.6 degrees), while grasps with a robust
epsilon above 0 held 68 of 69 times.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..geometry import hand_fcl
from ..geometry.collision import FclReport, verify_with_fcl
from ..model.hand import FINGER_NAMES, HandModel
from ..quality.fitness import evaluate
from ..quality.measures import epsilon_quality
from ..quality.robustness import robust_epsilon
from .archive import LeaderArchive, wrists_distinct
from .candidates import make_candidate
from .ranking import grasp_quality, rank_order
from .result import Contact, GraspCandidate

__all__ = ["Checked", "Verifier", "select_candidates", "to_candidates"]


@dataclass(frozen=True)
class Checked:
    """One verified grasp (object frame unless named; contacts in the planning frame)."""

    x: np.ndarray                 # (19,) the particle: the open pre-shape
    closed: np.ndarray            # (19,) the closed configuration
    wrist_in_object: np.ndarray   # (4, 4)
    joints: np.ndarray            # (5, 4, 3) m, object frame
    fitness: float
    epsilon: float
    force_closure: bool
    contacts: tuple[Contact, ...]
    fcl: FclReport
    scene_distance: float         # m, whole hand (fcl), grasp + approach; inf without a scene
    scene_clear: bool
    valid: bool
    max_penetration: float
    tip_gaps: np.ndarray          # (5,)
    robust_epsilon: float = 0.0   # epsilon with the cones shrunk by the normal uncertainty

    @property
    def robust(self) -> bool:
        """Force closure that survives the contacts' normal uncertainty."""
        return self.force_closure and self.robust_epsilon > 0.0


class Verifier:
    """Verifies particles of one plan (see the module docstring).

    Parameters
    ----------
    model : GraspModel (with the scene check when there is a scene)
    problem : the planner's GraspProblem (decode, shape factor)
    options : PlanOptions
    pose : (4, 4) object -> planning frame
    bvh : fcl.BVHModel of the object (object frame)
    scene : Scene in the object frame, or None
    """

    def __init__(self, model, problem, options, pose: np.ndarray, bvh, scene=None):
        self.model, self.problem, self.options, self.pose, self.bvh = model, problem, options, pose, bvh
        self.scene = None if scene is None or scene.is_empty else scene
        self.verified = 0

    @property
    def hand(self) -> HandModel:
        return self.model.hand

    def epsilon(self, points: np.ndarray, normals: np.ndarray) -> tuple[float, bool]:
        """Ferrari-Canny epsilon and force closure of contacts (k, 3), object frame."""
        if len(points) < 2:
            return 0.0, False
        obj = self.model.obj
        return epsilon_quality(
            points, normals, np.asarray(obj.center_of_mass, dtype=float), mu=self.options.friction,
            edges=self.options.friction_edges, torque_scale=float(obj.characteristic_radius),
        )

    def robust_epsilon(self, points: np.ndarray, normals: np.ndarray) -> float:
        """Epsilon of contacts (k, 3), object frame, with each friction cone shrunk by the
        spread of the surface normals around the contact (0 when closure needs a contact
        at an edge or a corner)."""
        if len(points) < 2:
            return 0.0
        obj = self.model.obj
        return float(robust_epsilon(obj, points, normals, mu=self.options.friction,
                                    edges=self.options.friction_edges,
                                    torque_scale=float(obj.characteristic_radius)))

    def decode(self, x: np.ndarray):
        """Decode particles (k, 19) and their fitness: (DecodedGrasps, fitness (k,))."""
        decoded = self.problem.decode(x)
        terms = evaluate(self.model, decoded, self.problem.shape.wrist_score(decoded.wrist[:, :3, :3]),
                         self.options.friction)
        return decoded, terms.fitness

    def check(self, x: np.ndarray, decoded, fitness: np.ndarray, i: int,
              closure: tuple[float, bool] | None = None) -> Checked:
        """Verify particle ``i`` of a decoded batch (``closure``: its epsilon, if known)."""
        self.verified += 1
        model, hand = self.model, self.hand
        contact = decoded.contact[i]
        points = decoded.contact_points[i][contact]
        normals = decoded.contact_normals[i][contact]
        eps, fc = closure if closure is not None else self.epsilon(points, normals)
        robust = self.robust_epsilon(points, normals) if fc else 0.0
        report = verify_with_fcl(
            decoded.joints[i], np.array([*hand.link_radii[:2], hand.pad_radius]), self.bvh,
            FINGER_NAMES, penetration_tolerance=0.001, allowed_overlap=model.settings.finger_overlap,
        )
        rot, trans = self.pose[:3, :3], self.pose[:3, 3]
        contacts = tuple(
            Contact(finger=FINGER_NAMES[f], position=rot @ decoded.contact_points[i, f] + trans,
                    normal=rot @ decoded.contact_normals[i, f])
            for f in np.flatnonzero(contact)
        )
        legal = bool(decoded.legal(model.settings.max_penetration)[i])
        valid = legal and len(contacts) >= 2 and report.legal
        wrist = decoded.wrist[i]
        scene_distance, scene_clear = math.inf, True
        if self.scene is not None:
            clearance = model.scene_clearance
            scene_distance = hand_fcl.hand_scene_distance(hand, decoded.closed[i], wrist, self.scene)
            scene_clear = scene_distance >= clearance
            if scene_clear:  # the approach only when the grasp itself is clear
                approach = hand_fcl.approach_report(
                    hand, np.clip(x[i], model.lower, model.upper), wrist, model.approach_distance, self.scene,
                    self.bvh, None, clearance, obj_bounds=model.object_box)
                scene_distance = min(scene_distance, approach.min_scene_distance)
                scene_clear = bool(approach.clear)
            valid = valid and scene_clear
        return Checked(
            x=np.array(x[i], dtype=float), closed=decoded.closed[i].copy(), wrist_in_object=wrist.copy(),
            joints=decoded.joints[i].copy(), fitness=float(fitness[i]), epsilon=float(eps),
            force_closure=bool(fc), contacts=contacts, fcl=report, scene_distance=float(scene_distance),
            scene_clear=bool(scene_clear), valid=bool(valid),
            max_penetration=float(decoded.penetration[i].max()), tip_gaps=decoded.tip_gap[i].copy(),
            robust_epsilon=float(robust),
        )

    def check_one(self, x: np.ndarray) -> Checked:
        """Verify one particle (19,)."""
        x = np.asarray(x, dtype=float)[None, :]
        decoded, fitness = self.decode(x)
        return self.check(x, decoded, fitness, 0)


def select_candidates(
    verifier: Verifier, primary: Checked | None, archive: LeaderArchive, max_grasps: int,
    closure_only: bool = True,
) -> tuple[list[Checked], int, int]:
    """Verified, pairwise distinct candidates besides ``primary`` from the archive.

    The archive's entries are verified in descending fitness; an entry too close to the
    primary (or to an earlier accepted one) is skipped; the cheap checks run first (the
    decoder's legality, then epsilon), python-fcl only for those that pass. Stops once
    ``max_grasps`` force-closure grasps (the primary included) are found (robust ones
    first, then fragile ones). ``closure_only`` (without the simulation): a grasp that is
    not force closure is added only when neither the primary nor any archive entry is
    valid and force closure, and then only one; otherwise (the simulation will judge)
    valid grasps that are not force closure fill up the list. Bounded by the archive size.

    Returns
    -------
    others : list of Checked (valid ones only, unsorted)
    considered : int -- archive entries distinct from the primary
    rejected : int -- of those, found invalid
    """
    options = verifier.options
    want = max_grasps - (1 if primary is not None and primary.valid else 0)
    if want <= 0 or not len(archive):
        return [], 0, 0
    x = archive.x
    keep = np.ones(len(x), dtype=bool)
    if primary is not None:
        w = primary.wrist_in_object
        keep = wrists_distinct(w[:3, :3], w[:3, 3], archive.rot, archive.pos,
                               options.min_orientation_gap, options.min_position_gap)
    x = x[keep]
    if not len(x):
        return [], 0, 0
    decoded, fitness = verifier.decode(x)
    legal = decoded.legal(verifier.model.settings.max_penetration) & (decoded.n_contacts >= 2)
    order = np.argsort(-fitness, kind="stable")
    closure_found: list[Checked] = []
    fragile: list[Checked] = []  # valid force closure, but not robust: used only if needed
    spare: list[int] = []  # legal, not force closure: verified only if needed
    epsilons: dict[int, tuple[float, bool]] = {}
    rejected = 0
    for i in order:
        if len(closure_found) >= want:
            break
        if not legal[i]:
            rejected += 1
            continue
        contact = decoded.contact[i]
        epsilons[i] = verifier.epsilon(decoded.contact_points[i][contact], decoded.contact_normals[i][contact])
        if not epsilons[i][1]:
            spare.append(int(i))
            continue
        c = verifier.check(x, decoded, fitness, int(i), epsilons[i])
        if not c.valid:
            rejected += 1
        elif c.robust:
            closure_found.append(c)
        else:
            fragile.append(c)
    out = list(closure_found) + fragile[:max(0, want - len(closure_found))]
    # Candidates are force closure (DESIGN: "all are valid and force closure when the
    # search found that many; fewer are returned only when it did not"): a grasp that is
    # not force closure is returned only as the single best grasp when the search found
    # no force-closure grasp at all (the top-level fields need a grasp).
    # With the simulation (``closure_only`` False) the held ones are chosen in MuJoCo,
    # which judges grasps that are not force closure by the epsilon measure too.
    primary_ok = primary is not None and primary.valid
    if closure_only and (out or primary_ok):
        spare = []
    elif closure_only:
        spare = spare[:1]
    for i in spare:
        if len(out) >= want:
            break
        c = verifier.check(x, decoded, fitness, i, epsilons[i])
        if c.valid:
            out.append(c)
        else:
            rejected += 1
    return out, int(len(x)), rejected


def to_candidates(
    hand: HandModel, checked: list[Checked], pose: np.ndarray, approach_distance: float, pinned_first: bool,
    sims: list | None = None,
) -> tuple[GraspCandidate, ...]:
    """Rank verified grasps and build the candidates (planning frame), best first.

    ``pinned_first``: ``checked[0]`` stays first whatever its score (the free-space plan's
    best grasp, as before); the others are sorted by :func:`~.ranking.grasp_quality`.
    ``sims``: one :class:`~grasp_apso.simulation.SimResult` per entry of ``checked`` when
    the simulation ran (held grasps then rank first, and the ``sim_*`` fields are filled),
    None for a grasp it did not reach in time (ranked as not held, ``sim_result`` -1).
    Returns the candidates and the order (indices into ``checked``).
    """
    if not checked:
        return (), np.zeros(0, dtype=int)
    held = None if sims is None else np.array([s is not None and s.held for s in sims], dtype=bool)
    quality = grasp_quality(np.array([c.fitness for c in checked]), np.array([c.valid for c in checked]),
                            np.array([c.force_closure for c in checked]), held,
                            robust=np.array([c.robust for c in checked]))
    eps = np.array([c.epsilon for c in checked])
    if pinned_first:
        rest = 1 + rank_order(quality[1:], eps[1:])
        order = np.concatenate([[0], rest]).astype(int)
    else:
        order = rank_order(quality, eps)
    out = []
    for rank, i in enumerate(order):
        c = checked[i]
        out.append(make_candidate(
            hand, rank, c.x, c.closed, c.wrist_in_object, pose, approach_distance,
            grasp_quality=float(quality[i]), fitness=c.fitness, epsilon=c.epsilon,
            force_closure=c.force_closure, valid=c.valid, contacts=c.contacts, scene_distance=c.scene_distance,
            sim=None if sims is None else sims[i],
        ))
    return tuple(out), order
