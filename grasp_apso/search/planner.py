"""Planner API: ``plan(obj, pose, options, rng) -> GraspResult`` (no ROS).

The planner prepares the object (signed-distance grid, cached by mesh hash), classifies
its shape (GRG parameter factor), runs APSO or the simple PSO over particles of
:mod:`grasp_apso.geometry.decoder` layout, and verifies the best grasp independently: the
Ferrari-Canny epsilon with friction cones (:mod:`grasp_apso.quality.measures.measures`) and python-fcl
collision checks of the links against the mesh and between fingers
(:mod:`grasp_apso.geometry.collision`). Results are returned in the planning frame of ``pose``.
"""

from __future__ import annotations

import threading
import time
from collections import OrderedDict
from dataclasses import replace
from typing import Callable

import numpy as np

from ..errors import InputError, ObjectTooLargeError, PlanningError
from ..geometry.collision import FclReport, mesh_bvh, verify_with_fcl
from ..geometry.decoder import N_DIMS, ContactSettings, DecodedGrasps, GraspModel, decode, make_grasp_model
from ..quality.fitness import evaluate
from .grg import GuidedGenerator, ShapeClass, classify_shape
from ..model.builtin import builtin
from ..model.hand import FINGER_NAMES, JOINT_NAMES, HandModel, load_hand
from ..model.particle import LAYOUT
from ..quality.measures import epsilon_quality
from .candidates import make_candidate
from .options import ALGORITHMS, PlanOptions
from .result import Contact, GraspCandidate, GraspResult
from .swarm import IterationStats, run_swarm

__all__ = [
    "ALGORITHMS", "Contact", "GraspResult", "IterationStats", "Objective", "PlanOptions",
    "PlanningError", "plan", "prepare", "warm_up",
]

#: Objects whose smallest extent exceeds this cannot be held in a precision grasp.
MAX_GRASPABLE_WIDTH = 0.16
MIN_GRASPABLE_SIZE = 0.005


class GraspProblem:
    """The optimisation problem of one plan: decode + fitness, and GRG draws."""

    def __init__(self, model: GraspModel, shape: ShapeClass, options: PlanOptions, rng: np.random.Generator):
        self.model = model
        self.shape = shape
        self.mu = options.friction
        self.wrist_position = None if options.wrist_position is None else np.asarray(options.wrist_position, float)
        self.lower, self.upper = model.lower, model.upper
        self.generator = GuidedGenerator(model, shape, rng, self.wrist_position)
        self._evaluations = 0

    @property
    def evaluations(self) -> int:
        return self._evaluations + self.generator.evaluations

    def decode(self, x: np.ndarray) -> DecodedGrasps:
        return decode(self.model, x, self.wrist_position)

    def evaluate(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        decoded = self.decode(x)
        self._evaluations += len(x)
        terms = evaluate(self.model, decoded, self.shape.wrist_score(decoded.wrist[:, :3, :3]), self.mu)
        return terms.fitness, terms.active, decoded.n_contacts

    def guided(self, k: int) -> np.ndarray:
        return self.generator.draw(k)


_BVH_CACHE: "OrderedDict[str, object]" = OrderedDict()
_BVH_LOCK = threading.Lock()


def _cached_bvh(obj):
    with _BVH_LOCK:
        bvh = _BVH_CACHE.get(obj.mesh_hash)
        if bvh is None:
            bvh = mesh_bvh(obj.mesh)
            _BVH_CACHE[obj.mesh_hash] = bvh
            while len(_BVH_CACHE) > 8:
                _BVH_CACHE.popitem(last=False)
        return bvh


def prepare(obj, hand: HandModel | None = None, options: PlanOptions | None = None) -> GraspModel:
    """Build (or fetch from the cache) everything fixed for planning on ``obj``."""
    hand = hand or load_hand()
    options = options or PlanOptions()
    extents = np.asarray(obj.principal_extents, dtype=float)
    if extents[-1] > MAX_GRASPABLE_WIDTH:
        raise ObjectTooLargeError(
            f"object: too large for a precision grasp: its smallest extent is {extents[-1]:.3f} m, "
            f"the hand opens to about {MAX_GRASPABLE_WIDTH:.2f} m"
        )
    if extents[0] < MIN_GRASPABLE_SIZE:
        raise PlanningError(
            f"object: too small for a precision grasp: its largest extent is {extents[0] * 1000:.1f} mm"
        )
    settings = ContactSettings(tolerance=options.contact_tolerance)
    return make_grasp_model(hand, obj, settings)


def plan(
    obj,
    pose: np.ndarray | None = None,
    options: PlanOptions | None = None,
    rng: np.random.Generator | None = None,
    hand: HandModel | None = None,
    progress: Callable[[IterationStats], None] | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> GraspResult:
    """Plan a precision grasp of ``obj`` with APSO (or the simple PSO).

    Parameters
    ----------
    obj : GraspObject
        The object in its own frame (metres).
    pose : (4, 4) float, optional
        Object frame -> planning frame; identity when None.
    options : PlanOptions, optional
    rng : np.random.Generator, optional
        Source of all randomness; the same seed gives the same result.
    hand : HandModel, optional
        Hand description; the shipped paper hand when None.
    progress : callable(IterationStats), optional
        Called once per iteration.
    should_stop : callable() -> bool, optional
        Polled before every iteration; True stops the plan (``cancelled`` in the result).

    Raises
    ------
    PlanningError
        The object cannot be grasped by this hand (too large, too small, no valid
        particle found by GRG).
    ValueError
        Invalid options or pose.
    """
    options = options or PlanOptions()
    rng = rng if rng is not None else np.random.default_rng()
    pose = np.eye(4) if pose is None else np.asarray(pose, dtype=float)
    if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
        raise ValueError(f"pose: expected a finite (4, 4) transform, got shape {pose.shape}")

    t0 = time.perf_counter()
    model = prepare(obj, hand, options)
    shape = classify_shape(obj)
    preparation = time.perf_counter() - t0

    t1 = time.perf_counter()
    problem = GraspProblem(model, shape, options, rng)
    adaptive = options.algorithm == "apso"
    swarm = run_swarm(problem, options.swarm_options(), rng, adaptive, progress, should_stop)
    best = swarm.best if np.isfinite(swarm.best_fitness) else np.clip(swarm.best, model.lower, model.upper)
    result = _finish(model, problem, best[None, :], swarm, options, pose, shape, preparation, t1)
    if not (result.valid and result.force_closure):
        # The fitness rewards balance but does not guarantee force closure: prefer a
        # slightly less fit grasp that the independent epsilon measure accepts.
        x = _closure_runner_up(model, problem, swarm, best, options)
        if x is not None:
            other = _finish(model, problem, x[None, :], swarm, options, pose, shape, preparation, t1)
            if other.valid and other.force_closure:
                result = replace(other, runner_up=True)
    return result


def warm_up() -> float:
    """Load the compiled kernels (:mod:`grasp_apso.geometry.kernels`, :mod:`grasp_apso.quality.measures.kernels`)
    before the first plan.

    They are numba functions cached on disk: a process loads them on its first use,
    about 0.3 s, and once after an install compiles them, about 5 s. This plans a tiny
    grasp (the built-in cube, 2 particles, 1 iteration) so that a caller can pay that
    up front: the node does it in its worker thread before the first request, the
    command line before it times a plan. Idempotent; returns the seconds it took.
    """
    t0 = time.perf_counter()
    cube = builtin("cube")
    plan(cube, options=PlanOptions(particles=2, neighborhood_size=2, iterations=1), rng=np.random.default_rng(0))
    prepare(cube).sdf.distance(np.zeros(3))  # plain look-ups: the fixed-wrist path's palm check
    return time.perf_counter() - t0


def _closure_runner_up(model, problem, swarm, best: np.ndarray, options: PlanOptions) -> np.ndarray | None:
    """The fittest personal best after ``best`` that is legal and force closure, or None.

    The candidates are decoded in one batch; the epsilon measure (about 5 ms each) runs
    in descending fitness until one is force closure, at most ``closure_candidates - 1``.
    """
    candidates = _runner_ups(swarm, best, options.closure_candidates - 1)
    if not candidates:
        return None
    x = np.stack(candidates)
    decoded = problem.decode(x)
    legal = decoded.legal(model.settings.max_penetration)
    for i in np.flatnonzero(legal & (decoded.n_contacts >= 2)):
        contact = decoded.contact[i]
        _, closure = _epsilon(model, options, decoded.contact_points[i][contact],
                              decoded.contact_normals[i][contact])
        if closure:
            return x[i]
    return None


def _epsilon(model, options: PlanOptions, points: np.ndarray, normals: np.ndarray) -> tuple[float, bool]:
    """Ferrari-Canny epsilon and force closure of contacts (k, 3) on the model's object."""
    obj = model.obj
    return epsilon_quality(
        points, normals, np.asarray(obj.center_of_mass, dtype=float), mu=options.friction,
        edges=options.friction_edges, torque_scale=float(obj.characteristic_radius),
    )


def _runner_ups(swarm, best: np.ndarray, k: int) -> list[np.ndarray]:
    """Up to k distinct personal bests after ``best``, in descending fitness (finite only)."""
    if k <= 0 or swarm.personal_best is None:
        return []
    fitness = swarm.personal_best_fitness
    order = np.argsort(-fitness, kind="stable")
    out: list[np.ndarray] = []
    for i in order[np.isfinite(fitness[order])]:
        x = swarm.personal_best[i]
        if np.allclose(x, best) or any(np.allclose(x, y) for y in out):
            continue
        out.append(x)
        if len(out) == k:
            break
    return out


def _finish(model, problem, x, swarm, options, pose, shape, preparation, t1) -> GraspResult:
    decoded = problem.decode(x)
    terms = evaluate(model, decoded, shape.wrist_score(decoded.wrist[:, :3, :3]), options.friction)
    obj = model.obj
    contact = decoded.contact[0]
    points = decoded.contact_points[0][contact]
    normals = decoded.contact_normals[0][contact]
    if contact.sum() >= 2:
        eps, closure = _epsilon(model, options, points, normals)
    else:
        eps, closure = 0.0, False
    hand = model.hand
    report = verify_with_fcl(
        decoded.joints[0], np.array([*hand.link_radii[:2], hand.pad_radius]), _cached_bvh(obj),
        FINGER_NAMES, penetration_tolerance=0.001, allowed_overlap=model.settings.finger_overlap,
    )
    rot, trans = pose[:3, :3], pose[:3, 3]
    contacts = tuple(
        Contact(finger=FINGER_NAMES[f], position=rot @ decoded.contact_points[0, f] + trans,
                normal=rot @ decoded.contact_normals[0, f])
        for f in np.flatnonzero(contact)
    )
    closed = decoded.closed[0]
    wrist_in_object = decoded.wrist[0]
    legal = bool(decoded.legal(model.settings.max_penetration)[0])
    valid = legal and len(contacts) >= 2 and report.legal
    candidate = make_candidate(
        hand, 0, x[0], closed, wrist_in_object, pose, options.approach_distance,
        grasp_quality=0.0, fitness=float(terms.fitness[0]), epsilon=float(eps),
        force_closure=bool(closure), valid=valid, contacts=contacts,
    )
    return GraspResult(
        configuration=LAYOUT.cg(candidate.joint_positions),
        joint_names=JOINT_NAMES,
        joint_positions=candidate.joint_positions.copy(),
        standoff=float(closed[LAYOUT.standoff]),
        wrist_pose=pose @ wrist_in_object,
        wrist_in_object=wrist_in_object,
        fitness=float(terms.fitness[0]),
        epsilon=float(eps),
        force_closure=bool(closure),
        contacts=contacts,
        valid=valid,
        history=tuple(swarm.history),
        iterations_run=swarm.iterations_run,
        evaluations=problem.evaluations,
        planning_time=time.perf_counter() - t1,
        preparation_time=preparation,
        cancelled=swarm.cancelled,
        algorithm=options.algorithm,
        shape_class=shape.name,
        fcl=report,
        joints=decoded.joints[0] @ rot.T + trans,
        max_penetration=float(decoded.penetration[0].max()),
        tip_gaps=decoded.tip_gap[0].copy(),
        candidates=(candidate,),
    )


class Objective:
    """The planner's fitness as a plain objective, for external optimisers (e.g. pyswarms).

    ``objective(x)`` maps particles (P, 19) to fitness (P,) (maximised; a minimiser should
    use ``-objective(x)``); ``lower`` / ``upper`` are the particle bounds; ``evaluations``
    counts particle decodes. :meth:`result` verifies a best particle exactly as
    :func:`plan` does and returns a :class:`GraspResult`.
    """

    def __init__(self, obj, options: PlanOptions | None = None, hand: HandModel | None = None):
        self.options = options or PlanOptions()
        t0 = time.perf_counter()
        self.model = prepare(obj, hand, self.options)
        self.shape = classify_shape(obj)
        self.preparation_time = time.perf_counter() - t0
        self.problem = GraspProblem(self.model, self.shape, self.options, np.random.default_rng(0))
        self.lower, self.upper = self.model.lower, self.model.upper
        self._started = time.perf_counter()

    @property
    def evaluations(self) -> int:
        return self.problem.evaluations

    def __call__(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if x.ndim != 2 or x.shape[1] != N_DIMS:
            raise ValueError(f"x: expected (P, {N_DIMS}), got {x.shape}")
        return self.problem.evaluate(x)[0]

    def result(
        self, x_best: np.ndarray, pose: np.ndarray | None = None,
        history: tuple[IterationStats, ...] = (), algorithm: str = "external",
    ) -> GraspResult:
        """Verify a particle (19,) and build the result (planning time since construction)."""
        from .swarm import SwarmResult

        x_best = np.clip(np.asarray(x_best, dtype=float).reshape(N_DIMS), self.lower, self.upper)
        swarm = SwarmResult(best=x_best, best_fitness=float(self(x_best[None])[0]), history=list(history),
                            iterations_run=len(history))
        options = PlanOptions(**{**self.options.__dict__, "algorithm": "apso"})
        res = _finish(self.model, self.problem, x_best[None, :], swarm, options,
                      np.eye(4) if pose is None else np.asarray(pose, float), self.shape,
                      self.preparation_time, self._started)
        return GraspResult(**{**res.__dict__, "algorithm": algorithm})
