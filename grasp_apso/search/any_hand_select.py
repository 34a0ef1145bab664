"""Final verification, ranking and the result of a general hand's plan.

The candidates are the swarm's best and the leaders' archive (distinct wrists), decoded
again (the fittest with their pads turned to the surface, and strictly with only the
contacts whose pad points lie on it: :func:`grasp_apso.search.any_hand_pads.final_decodings`)
and taken in descending fitness: each gets the Ferrari-Canny epsilon and force
closure (:func:`grasp_apso.quality.measures.epsilon_quality`'s wrenches; the verdict
proven without the hull where it can be, :class:`grasp_apso.quality.closure_proof.Epsilon`),
and the python-fcl checks of the hand's exact collision geometry
(:mod:`grasp_apso.geometry.any_hand_fcl`: the object, the scene at the grasp, the approach
from the pre-grasp) when that module is
there; fingers whose exact geometry presses into the object are seated on it
(:mod:`.exact_seat`) and contacting fingers whose pad links stand off it closed onto it
(:mod:`.exact_touch`), their contacts and the grasp's closure then taken again. Ranked by :func:`grasp_apso.search.ranking.grasp_quality`, where a *balanced* force-closure
grasp counts as robust: the servos' squeezing forces along the contact normals can cancel
(:func:`grasp_apso.quality.closing.closing_forces`, imbalance at most
:data:`MAX_IMBALANCE`), so the closing does not shove or roll the object; within a class
the grasps are ordered by their hold score (:func:`hold_score`: robust epsilon times one
minus the imbalance), not by the fitness. Up to :data:`SPARE` (without ``simulate``
:data:`DEFAULT_SPARE`) times ``max_grasps`` distinct grasps are verified so that balanced
ones can be found, and the best ``max_grasps`` returned. Each candidate's squeeze exerts
contact forces balanced with friction at its pads (force vectors inside narrowed friction
cones, :func:`grasp_apso.quality.closing.balanced_forces`; ``q + J^T f / kp``,
:func:`grasp_apso.quality.closing.squeeze_toward_forces`). With
``simulate`` the verified grasps are checked in MuJoCo
(:func:`grasp_apso.simulation.any_hand.simulate_any_hand`) best first until ``max_grasps``
held or all were tried: a grasp that drops is tried once more with a firmer squeeze
(:mod:`.any_hand_squeeze`), a grasp that holds is held only if it holds with
DexGraspBench's parameters too (:mod:`.any_hand_simulate`), and the grasps below the best
class, left out without ``simulate``, are simulated last.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import PlanningError
from ..quality.closure_proof import Epsilon
from ..quality.measures import closure_wrenches
from ..quality.robustness import normal_uncertainty, robust_wrenches
from .any_hand_pads import final_decodings, pads_on
from .any_hand_simulate import simulate_any
from .any_hand_squeeze import balanced_squeeze, closing_imbalance, optional_module, sim_settings, squeeze_posture
from .archive import wrist_groups, wrists_distinct
from .exact_contacts import RECLOSE_FROM, exact_contacts
from .exact_seat import pad_body_distances, pad_body_rows, pad_nearest, seat_fingers
from .exact_touch import TOUCH_GAP, touch_pads
from .ranking import grasp_quality, rank_order, ranking_class
from .result import SIM_DROPPED, SIM_HELD, SIM_NOT_RUN, Contact, GraspCandidate, GraspResult
from .selection_report import Selection, SelectionCounts, append_note

__all__ = ["AnyChecked", "select_any", "build_result", "squeeze_posture", "best_class"]

#: Largest closing imbalance (net wrench of the squeezing forces / their sum) of a grasp
#: ranked as robust: friction (mu 0.5) absorbs a net force of up to about mu times the total,
#: half of it leaves a margin for the fingers that touch first.
MAX_IMBALANCE = 0.25
#: Distinct grasps verified per requested one (balanced ones are looked for among them;
#: with ``simulate`` they are simulated best first until ``max_grasps`` held).
SPARE = 3
#: Without ``simulate``, distinct grasps verified per requested one: the best ``max_grasps``
#: of them by class and hold score (:func:`hold_score`) are returned. Measured
#: (``bench/held_rate.py --seeds 3``, 21 objects on a table, 63 plans), 3 against 1: best
#: grasp held the same (Allegro-like 51, Shadow 49, LEAP 35), all returned grasps held a
#: little more (180/232 against 175/232, 199/262 against 192/262, 118/197 against
#: 120/197) but the median plan longer (1.3 against 1.3 s, 1.4 against 1.2 s, 2.5 against
#: 2.2 s: the python-fcl checks and seating of the extra grasps), so 1.
DEFAULT_SPARE = 1
#: Within a class (balanced robust force closure, force closure, ...) the grasps are ranked
#: by their hold score ``h = robust epsilon * (1 - closing imbalance)`` (:func:`hold_score`,
#: mapped to [0, 1) as ``h / (h + HOLD_SCALE)``), the fitness only breaking ties
#: (``FITNESS_SHARE`` of the score). MEASURED: see :func:`hold_score`.
HOLD_SCALE = 0.05
FITNESS_SHARE = 0.01
#: Grasps with two or more contacts analysed per requested one (epsilon, robust epsilon,
#: imbalance: about 2 ms each) to find the balanced ones before the collision checks.
ANALYSED = 8
#: When the pre-grasp's fingers hit the object on the approach, the verification tries
#: them opened these fractions of the way to their opening limits.
OPENING = (0.5, 1.0)
#: The reply's pre-grasp is the first of these fractions of the way from the grasp posture
#: back to the search's pre-shape whose approach is clear (else the pre-shape itself): the
#: fingers start just off their contacts, as DexGraspBench's pregrasp does, instead of wide
#: open, from where fingers arriving one after another shove the object before the others
#: touch it.
NEAR = (0.25, 0.5)


def _no_closure() -> Epsilon:
    return Epsilon(None)


@dataclass
class AnyChecked:
    """One verified candidate (object frame unless said)."""

    decoded: object          # AnyDecoded of one particle
    fitness: float
    valid: bool
    scene_clear: bool
    scene_distance: float
    fcl: object | None
    note: str = ""
    imbalance: float = 1.0
    squeeze: np.ndarray | None = None
    # The Ferrari-Canny epsilon and the robust one (_closure): verdicts known, values built
    # when read (the selection sorts by the verdicts; only the grasps it keeps are ranked).
    closure: Epsilon = field(default_factory=_no_closure)
    robust: Epsilon = field(default_factory=_no_closure)
    forces: np.ndarray | None = None   # (contacts, 3) N, the squeeze's contact forces (None: uniform squeeze)
    closure_known: bool = False        # closure and robust computed: _closure
    fallback: bool = False             # simulate: below the others' class, simulated after them

    @property
    def epsilon(self) -> float:
        """Ferrari-Canny epsilon (its hull built on the first read)."""
        return self.closure.value

    @property
    def force_closure(self) -> bool:
        return self.closure.force_closure

    @property
    def robust_epsilon(self) -> float:
        """The epsilon with the cones shrunk by the normals' uncertainty (built on the first read)."""
        return self.robust.value

    @property
    def robust_closure(self) -> bool:
        """Force closure that survives the normals' spread at edges and corners (robust epsilon > 0)."""
        return self.robust.force_closure

    @property
    def balanced(self) -> bool:
        """Robust force closure whose squeezing forces can cancel: ranked as robust."""
        return self.force_closure and self.robust_closure and self.imbalance <= MAX_IMBALANCE


def _analyse(model, decoded, fitness: float, options, obj) -> AnyChecked:
    """The analytic part of the verification of one decoded grasp (no collision check):
    legality and the closing imbalance (of three contacts or more); the epsilon, force
    closure and robust epsilon (:func:`_closure`) when the closing is balanced enough for
    the grasp to rank as balanced (the others get them when the selection reaches them).
    The squeeze of a grasp with closing forces is left to its verification (None until
    then)."""
    s = model.settings
    mask = decoded.contact[0]
    legal = bool(decoded.legal(s.max_penetration)[0])
    scene_clear = decoded.scene_margin is None or bool(decoded.scene_margin[0] >= 0.0)
    # Two contacts are never force closure (nor balanced), and the imbalance weighs only
    # force-closure grasps (:func:`hold_score`): solved for from three.
    imbalance, balanced = closing_imbalance(model, decoded, obj, solve_from=3)
    squeeze = None if balanced else squeeze_posture(model, decoded.q[0])
    c = AnyChecked(decoded, float(fitness), bool(legal and mask.sum() >= 2), scene_clear, math.inf, None, "",
                   imbalance, squeeze)
    if imbalance <= MAX_IMBALANCE:
        _closure(c, options, obj)
    return c


def _closure(c: AnyChecked, options, obj) -> None:
    """The epsilon and force closure of an analysed grasp, and its robust epsilon when it
    is force closure."""
    decoded = c.decoded
    mask = decoded.contact[0]
    c.closure_known = True
    c.closure, c.robust = _no_closure(), _no_closure()
    if mask.sum() < 2:
        return
    points, normals = decoded.contact_points[0][mask], decoded.contact_normals[0][mask]
    c.closure = Epsilon(closure_wrenches(points, normals, np.asarray(obj.center_of_mass, float), options.friction,
                                         torque_scale=float(obj.characteristic_radius)))
    if c.closure.force_closure:
        uncertainty = normal_uncertainty(obj, points)
        # Certain normals (contacts inside flat faces) leave the cones as they are: the
        # robust epsilon is the epsilon (same cones: the epsilon's 8 edges), its hull need
        # not be built again.
        same = not uncertainty.any() and options.friction_edges == 8
        c.robust = c.closure if same else Epsilon(robust_wrenches(
            obj, points, normals, mu=options.friction, uncertainty=uncertainty, edges=options.friction_edges,
            torque_scale=float(obj.characteristic_radius)))


def _verify(model, c: AnyChecked, options, pose, obj, scene, fcl_api, hc) -> AnyChecked:
    """The python-fcl checks of an analysed grasp against the hand's exact collision
    geometry: the object, the scene at the grasp and along the approach."""
    if fcl_api is None:
        c.note = "python-fcl verification of the hand not available (grasp_apso.geometry.any_hand_fcl)"
        return c
    decoded = c.decoded
    q, root = decoded.q[0], decoded.root[0]
    c.fcl = fcl_api.object_report(hc, q, root, obj)
    rest = None
    if not c.fcl.legal:
        # the sphere covers let an exact mesh press a little into the object: seat it
        q, c.fcl, rest = seat_fingers(fcl_api, hc, model.hand, q, decoded.q_pre[0], root, obj, c.fcl,
                                      model.settings.tolerance)
        decoded.q[0] = q
        decoded.closed[0, model.layout.joints] = q
    if c.fcl.legal:  # (a grasp refused at the object stays refused)
        q = _touch(model, c, fcl_api, hc, q, root, options, obj, rest)
        _on_surface(model, c, hc, q, root, options, obj)
    c.valid = c.valid and bool(c.fcl.legal)
    settings = sim_settings()
    if settings is not None and c.squeeze is None:
        c.squeeze, c.forces = balanced_squeeze(model, decoded, obj, options.friction, settings, c.fcl)
    if scene is not None and c.valid:  # (an invalid grasp is refused whatever its approach)
        root_plan = pose @ root
        approach = pose[:3, :3] @ (root[:3, :3] @ model.tables.basis[:, 2])
        distance = float(fcl_api.scene_distance(hc, q, root_plan, scene))
        reports, clear = [], False
        for posture in pre_grasp_postures(model.hand, q, decoded.q_pre[0]):
            # The nearest pre-grasp whose approach is clear: the closing then starts just off
            # the contacts (DexGraspBench's pregrasp); a pre-shape whose fingers sweep through
            # the object on the way in is opened wider (the pre-shape joints kept).
            reports.append(fcl_api.approach_report(hc, posture, root_plan, approach, options.approach_distance,
                                                   scene, obj, pose, decide_only=True))
            if not reports[-1].hits_object and reports[-1].min_scene_distance >= options.clearance:
                decoded.q_pre[0] = posture
                clear = True
                break
        # none clear: the search's pre-shape stays, its report says why
        path = reports[-1] if clear else reports[len(NEAR)]
        c.scene_distance = min(distance, float(path.min_scene_distance))
        c.scene_clear = c.scene_clear and c.scene_distance >= options.clearance and not path.hits_object
    return c


def _touch(model, c: AnyChecked, fcl_api, hc, q: np.ndarray, root: np.ndarray, options, obj,
           rest: np.ndarray | None = None) -> np.ndarray:
    """The contacting fingers whose pad links stand off the object (exact geometry) closed
    onto it (:func:`.exact_touch.touch_pads`): their contacts moved to where the links
    touch, the fingers that cannot touch with their pads (left where they are) no
    contacts; ``rest`` (F,) bool, the fingers the seating left resting on their pad body
    away from the pad point (:func:`.exact_seat.seat_fingers`), and the other contacts
    farther than :data:`.exact_touch.TOUCH_GAP` from their pad body's exact geometry
    (:func:`.exact_seat.pad_body_distances`): their contacts moved to where that body is
    nearest the object. The grasp's closure, closing forces and report follow. Returns
    the posture (n,)."""
    decoded = c.decoded
    q_new, moved, lost, points = touch_pads(hc, model.hand, q, root, obj, model.sdf, c.fcl, decoded.contact[0])
    rest = np.zeros(len(moved), dtype=bool) if rest is None else np.array(rest, dtype=bool)
    # A contact the pad sphere made where the pad body is not (a sphere wider than a thin
    # fingertip plate touches beside it, LEAP's) moves to where the pad body is nearest
    # the object, as the fingers the seating left resting on their pad body.
    kept = np.flatnonzero(decoded.contact[0] & ~moved & ~lost & ~rest)
    gaps = pad_body_distances(model.hand, q_new, root, kept, decoded.contact_points[0, kept])
    rest[kept] = (gaps > TOUCH_GAP) & np.isfinite(gaps)  # (inf: a pad body without collision geometry stays)
    if (rest := rest & decoded.contact[0] & ~moved & ~lost).any():
        for f in np.flatnonzero(rest):
            parts = np.flatnonzero(np.isin(hc.shapes.part_link, pad_body_rows(model.hand, hc, int(f))))
            points[f] = pad_nearest(hc, q_new, root, model.sdf, parts)[1]
        moved = moved | rest
    if not (moved.any() or lost.any()):
        return q
    decoded.q[0] = q_new
    decoded.closed[0, model.layout.joints] = q_new
    if moved.any():
        surface, normals = model.sdf.closest_surface_point(points[moved])
        decoded.contact_points[0, moved] = surface
        decoded.contact_normals[0, moved] = normals
    decoded.contact[0, lost] = False
    if not np.array_equal(q_new, q):  # (a pad body resting as seated leaves the posture)
        c.fcl = fcl_api.object_report(hc, q_new, root, obj)
    c.valid = c.valid and int(decoded.contact[0].sum()) >= 2
    c.imbalance, balanced = closing_imbalance(model, decoded, obj)
    _closure(c, options, obj)
    c.squeeze = None if balanced else squeeze_posture(model, q_new)
    return q_new


def _on_surface(model, c: AnyChecked, hc, q: np.ndarray, root: np.ndarray, options, obj) -> None:
    """The grasp's contacts moved onto the object's mesh and, where the grid placed one away
    from its finger's pad body, to where that body is nearest the object
    (:func:`.exact_contacts.exact_contacts`); the closure and the closing imbalance follow
    when one moved more than :data:`.exact_contacts.RECLOSE_FROM`."""
    from ..geometry.any_hand_shapes import object_shape

    decoded = c.decoded
    fingers = np.flatnonzero(decoded.contact[0])
    points, normals = exact_contacts(model, hc, object_shape(obj), q, root, fingers,
                                     decoded.contact_points[0, fingers], decoded.contact_normals[0, fingers])
    moved = np.linalg.norm(points - decoded.contact_points[0, fingers], axis=1)
    decoded.contact_points[0, fingers], decoded.contact_normals[0, fingers] = points, normals
    if len(moved) and moved.max() > RECLOSE_FROM:
        c.imbalance, balanced = closing_imbalance(model, decoded, obj)
        _closure(c, options, obj)
        c.squeeze = None if balanced else squeeze_posture(model, q)


def pre_grasp_postures(hand, q: np.ndarray, q_open: np.ndarray) -> list[np.ndarray]:
    """The pre-grasp postures (n,) tried for the grasp posture q, in order of preference:
    each :data:`NEAR` fraction of the way from q back to the search's pre-shape ``q_open``
    (the fingers just off their contacts), ``q_open`` itself, then ``q_open`` opened
    :data:`OPENING` of the way to the opening limits."""
    q, q_open = np.asarray(q, dtype=float), np.asarray(q_open, dtype=float)
    return ([q + f * (q_open - q) for f in NEAR] + [q_open.copy()]
            + [opened(hand, q_open, f) for f in OPENING])


def opened(hand, q_pre: np.ndarray, fraction: float) -> np.ndarray:
    """The pre-grasp posture q_pre (n,) with every closing joint moved ``fraction`` of the
    way to its opening limit (the limit against its closing sense); pre-shape joints (no
    closing sense) unchanged."""
    out = np.array(q_pre, dtype=float)
    for finger in hand.fingers:
        for joint, sense in zip(finger.joints, finger.closing):
            if sense:
                j = hand.actuated_joints.index(joint)
                limit = hand.lower[j] if sense > 0 else hand.upper[j]
                out[j] += fraction * (limit - out[j])
    return out


def select_any(model, problem, swarm, archive, options, pose, obj, scene,
               prior: tuple[AnyChecked, ...] = ()) -> tuple[list[AnyChecked], Selection]:
    """Verified candidates: valid and (with a scene) clear of it, only the force-closure
    ones when there are any, and of those only the robust ones (robust epsilon > 0) when
    there are any.

    The pool is the swarm's best, the leaders' archive and the particles' personal bests.
    Those with two or more contacts in the first :data:`ANALYSED` times ``max_grasps``
    groups of like wrists (:func:`_first_groups`), in descending fitness, are analysed
    (:func:`_analyse`, only those that can still be verified); then verified with
    python-fcl in the order balanced, robust force closure, other force closure, the rest, fitness
    within each (stable), distinct wrists only, until :data:`DEFAULT_SPARE` (with
    ``simulate``: :data:`SPARE`) times ``max_grasps`` are kept (:func:`build_result`
    returns the best ``max_grasps`` of them). Without a scene at least the best one even
    when not valid.

    ``prior``: an earlier round's verified grasps (a search run again because its best
    grasp was not balanced, :func:`grasp_apso.search.any_hand_planner.plan_any_hand`). They
    join this round's, which must be distinct from them, and only grasps that can rank
    above the prior's best class are verified (their python-fcl checks are most of a
    round's selection time): the balanced ones always, the other force-closure ones only
    when no prior grasp is force closure, the rest only when none is valid.

    Returns the grasps and the :class:`Selection` (what became of this search's distinct
    grasps: the reply says it when fewer than ``max_grasps`` come back)."""
    pool = [np.clip(swarm.best, model.lower, model.upper)]
    if len(archive):
        pool.extend(archive.x)
    personal = getattr(swarm, "personal_best", None)
    if personal is not None:
        finite = np.isfinite(np.asarray(swarm.personal_best_fitness, float))
        pool.extend(np.clip(personal[finite], model.lower, model.upper))
    x = np.stack(pool)
    _, first_rows = np.unique(x, axis=0, return_index=True)
    x = x[np.sort(first_rows)]  # the archive's leaders are often personal bests too
    decoded = final_decodings(model, problem, x, options.max_grasps)  # as searched, and pads on the surface
    fitness, _ = problem.fitness(decoded)
    order = np.argsort(-fitness, kind="stable")
    contacts = decoded.contact.sum(axis=1)
    eligible, n_groups = _first_groups([i for i in order if contacts[i] >= 2], decoded.wrist,
                                       ANALYSED * options.max_grasps, options)
    if not eligible:  # nothing with two contacts: the fittest, to report why
        eligible = [int(order[0])]
    # the grasps whose pads lie on the surface first (stable: by fitness within), so that
    # within each class below they are verified first
    on = pads_on(decoded)
    eligible.sort(key=lambda i: not on[i])
    fcl_api = optional_module("grasp_apso.geometry.any_hand_fcl")
    hc = fcl_api.HandCollision(model.hand) if fcl_api is not None else None
    kept: list[AnyChecked] = []
    first: AnyChecked | None = None
    rejected = 0
    wanted = (SPARE if options.simulate else DEFAULT_SPARE) * options.max_grasps

    prior = tuple(prior)
    floor = best_class(prior) if prior else -1

    def distinct(one) -> bool:
        return all(wrists_distinct(k.decoded.wrist[0, :3, :3], k.decoded.wrist[0, :3, 3], one.wrist[:, :3, :3],
                                   one.wrist[:, :3, 3], options.min_orientation_gap, options.min_position_gap)[0]
                   for k in (*prior, *kept))

    def verify(c: AnyChecked) -> None:
        nonlocal first, rejected
        checked = _verify(model, c, options, pose, obj, scene, fcl_api, hc)
        if checked.squeeze is None:  # not squeezed by the verification (no python-fcl)
            checked.squeeze, checked.forces = balanced_squeeze(model, checked.decoded, obj, options.friction,
                                                               sim_settings())
        first = first or checked
        if checked.valid and checked.scene_clear:
            kept.append(checked)
        else:
            rejected += 1

    # Verified in the order balanced, robust force closure, other force closure, the rest,
    # by fitness within each (stable), distinct wrists only. Lazily, with the same outcome: the
    # balanced ones are verified as the fitness order reaches them, the others after; a
    # grasp not distinct from the grasps kept when the fitness order reaches it is never
    # verified (the kept ones only grow), so it is not analysed either.
    later: list[AnyChecked] = []
    for i in eligible:
        if len(kept) >= wanted:
            break
        one = decoded.take(np.array([i]))
        if not distinct(one):
            continue
        c = _analyse(model, one, fitness[i], options, obj)
        if c.balanced:
            verify(c)
        else:
            later.append(c)
    if floor >= 2:  # an earlier round's force-closure grasp: only balanced ones (above) rank higher
        later = []
    fragile: list[AnyChecked] = []
    rest: list[AnyChecked] = []
    for c in later:  # robust force closure first (known now, for the grasps still distinct), then the rest
        if len(kept) >= wanted:
            break
        if not distinct(c.decoded):
            continue
        if not c.closure_known:
            _closure(c, options, obj)
        if c.force_closure and c.robust_closure:
            verify(c)
        else:
            (fragile if c.force_closure else rest).append(c)
    for c in fragile + (rest if floor < 1 else []):
        if len(kept) >= wanted:
            break
        if distinct(c.decoded):
            verify(c)
    if prior:
        if not kept:  # nothing to add: the earlier rounds' grasps as they were
            return list(prior), Selection(SelectionCounts(n_groups, rejected), unchanged=True)
        kept = list(prior) + kept
    if not kept:
        if scene is not None or first is None:
            raise PlanningError(
                f"scene: no collision-free grasp: none of the {len(x)} best distinct grasps the search found with "
                f"hand {model.hand.name!r} is valid and keeps the clearance ({options.clearance * 1000:.1f} mm) "
                "from the support planes and obstacles at the grasp and along the approach", "scene")
        kept, rejected = [first], rejected - 1  # returned, not valid: it says so itself
    fallback: list[AnyChecked] = []
    if any(c.force_closure for c in kept):
        # Grasps without force closure are not returned next to ones with it: measured on the
        # Shadow hand, 1 of 46 held in the simulation (force closure: 31 of 55).
        fallback = [c for c in kept if not c.force_closure]
        kept = [c for c in kept if c.force_closure]
    if any(c.robust_closure for c in kept):
        # ... nor fragile ones (no force closure left once the normals' spread at an edge or
        # a rim is allowed for) next to robust ones: on 21 objects on a table, robust
        # candidates held 52 of 53 (Inspire), 31 of 34 (Allegro), 23 of 33 (LEAP); the
        # others 2 of 24, 3 of 13, 0 of 10.
        fallback = [c for c in kept if not c.robust_closure] + fallback
        kept = [c for c in kept if c.robust_closure]
    selection = Selection(SelectionCounts(n_groups, rejected, len(fallback)), kept[0].note)
    if options.simulate:
        # With the simulation they are its last resort: simulated after the others, and
        # returned only when one of them holds and none of the others does (simulate_any).
        for c in fallback:
            c.fallback = True
        kept = kept + fallback
    return kept, selection


def best_class(checked) -> int:
    """The ranking class of the best of verified grasps (the ranking puts it first): the
    highest of theirs (:func:`grasp_apso.search.ranking.ranking_class`), 3 balanced robust
    force closure, 2 force closure, 1 valid, 0 not valid."""
    return int(ranking_class(np.array([c.valid for c in checked]), np.array([c.force_closure for c in checked]),
                             np.array([c.balanced for c in checked])).max())


def _first_groups(rows: list[int], wrist: np.ndarray, groups: int, options) -> tuple[list[int], int]:
    """The rows (in their order) of the first ``groups`` groups of like wrists
    (:func:`grasp_apso.search.archive.wrist_groups`): the grasps the selection may analyse;
    and how many groups they form.
    Capped by rows instead, a swarm converged on one grasp filled the cap with near copies
    of it (which the selection skips once it is kept) and left its archive's other leaders
    out: measured on the Allegro-like hand's sphere, seeds 0 and 1, one grasp returned where
    the archive held 20 distinct ones, and a second search run."""
    if not rows:
        return [], 0
    group, _ = wrist_groups(wrist[rows, :3, :3], wrist[rows, :3, 3], options.min_orientation_gap,
                            options.min_position_gap)
    return [r for r, g in zip(rows, group) if g < groups], min(groups, int(group.max()) + 1)


def hold_score(checked: list[AnyChecked]) -> np.ndarray:
    """The order of the verified grasps within a ranking class (N,) in [0, 1):
    ``(1 - FITNESS_SHARE) * h / (h + HOLD_SCALE) + FITNESS_SHARE * fitness``, ``h`` the
    robust epsilon times one minus the closing imbalance. A force-closure grasp without a
    robust epsilon counts with its epsilon instead (0 without force closure): such grasps
    are returned only when no robust one was found (:func:`select_any`), and the fitness
    alone would then order them (on the Allegro hand's bowl, seed 0, the fittest of five
    such grasps dropped the bowl, with epsilon 0.009 and imbalance 0.58; three with epsilon
    0.02-0.05 and imbalance 0.3 held).

    Measured (``bench/held_rate.py``, 21 objects on a table, seeds 0-2, every one of up to
    15 verified grasps per plan simulated in MuJoCo): in pairs of a held and a dropped
    robust grasp of one plan (about 470, Allegro-like and Shadow), the held one had the
    larger robust epsilon in 76 % of them, the smaller closing imbalance in 77 %, the larger
    fitness in 63 %. Each plan's best chosen by this score instead of the fitness: held
    45 -> 47 of 63 plans (Allegro-like; 49 had a grasp that held), 44 -> 47 (Shadow; 47).
    """
    fitness = np.clip(np.nan_to_num(np.array([c.fitness for c in checked], float), nan=0.0, neginf=0.0), 0.0, 1.0)
    h = np.array([(c.robust_epsilon if c.robust_closure else max(c.epsilon, 0.0) * c.force_closure)
                  * max(1.0 - c.imbalance, 0.0) for c in checked], float)
    return (1.0 - FITNESS_SHARE) * h / (h + HOLD_SCALE) + FITNESS_SHARE * fitness


def build_result(model, checked, message, swarm, problem, options, pose, shape, preparation, t1, obj, scene,
                 should_stop) -> GraspResult:
    """The ranked candidates (the best ``max_grasps`` of ``checked``) and the GraspResult
    of a general hand's plan."""
    hand, t = model.hand, model.tables
    sims = None
    if options.simulate:
        checked, sims, note = simulate_any(model, checked, pose, obj, scene, options, should_stop)
        message = append_note(message, note)
    held = None if sims is None else np.array([s is not None and s.held for s in sims])
    quality = grasp_quality(hold_score(checked), np.array([c.valid for c in checked]),
                            np.array([c.force_closure for c in checked]), held,
                            robust=np.array([c.balanced for c in checked]))
    order = rank_order(quality, np.array([c.epsilon for c in checked]))[:options.max_grasps]
    rot, trans = pose[:3, :3], pose[:3, 3]
    candidates = []
    for rank, i in enumerate(order):
        c, d = checked[i], checked[i].decoded
        root = pose @ d.root[0]
        approach = rot @ (d.root[0, :3, :3] @ t.basis[:, 2])
        pre = root.copy()
        pre[:3, 3] -= options.approach_distance * approach
        sim = None if sims is None else sims[i]
        contacts = tuple(Contact(hand.fingers[f].name, rot @ d.contact_points[0, f] + trans,
                                 rot @ d.contact_normals[0, f]) for f in np.flatnonzero(d.contact[0]))
        candidates.append(GraspCandidate(
            id=f"g{rank}", rank=rank, joint_positions=d.q[0].copy(), pre_grasp_positions=d.q_pre[0].copy(),
            wrist_pose=root, pre_grasp_pose=pre, approach=approach, approach_distance=options.approach_distance,
            grasp_quality=float(quality[i]), fitness=c.fitness, epsilon=c.epsilon, force_closure=c.force_closure,
            valid=c.valid, contacts=contacts, scene_distance=c.scene_distance,
            sim_result=SIM_NOT_RUN if sim is None else (SIM_HELD if sim.held else SIM_DROPPED),
            sim_max_shift=math.nan if sim is None else float(sim.max_shift),
            sim_max_turn=math.nan if sim is None else float(sim.max_turn),
            wrist_in_object=d.root[0].copy(), joints=np.zeros((0, 4, 3)), pre_grasp_joints=np.zeros((0, 4, 3)),
            squeeze_positions=c.squeeze.copy()))
    top, best = checked[int(order[0])], candidates[0]
    d = top.decoded
    return GraspResult(
        configuration=best.joint_positions.copy(), joint_names=tuple(hand.actuated_joints),
        joint_positions=best.joint_positions.copy(), standoff=float(d.closed[0, t.layout.standoff]),
        wrist_pose=best.wrist_pose.copy(), wrist_in_object=best.wrist_in_object.copy(), fitness=top.fitness,
        epsilon=top.epsilon, force_closure=top.force_closure, contacts=best.contacts, valid=top.valid,
        history=tuple(swarm.history), iterations_run=swarm.iterations_run, evaluations=problem.evaluations,
        planning_time=time.perf_counter() - t1, preparation_time=preparation, cancelled=swarm.cancelled,
        algorithm=options.algorithm, shape_class=shape.name, fcl=top.fcl, joints=np.zeros((0, 4, 3)),
        max_penetration=float(d.penetration[0].max()), tip_gaps=d.tip_gap[0].copy(), runner_up=False,
        candidates=tuple(candidates), candidates_message=message, hand_name=hand.name, hand_hash=hand.source_hash)
