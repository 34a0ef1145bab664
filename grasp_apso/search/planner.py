"""Planner API: ``plan(obj, pose, options, rng) -> GraspResult`` (no ROS).

The planner prepares the object (signed-distance grid, cached by mesh hash), classifies
its shape (GRG parameter factor), runs APSO or the simple PSO over particles of
:mod:`grasp_apso.geometry.decoder` layout, and verifies the best grasp independently: the
Ferrari-Canny epsilon with friction cones (:mod:`grasp_apso.quality.measures`) and python-fcl
collision checks of the links against the mesh and between fingers
(:mod:`grasp_apso.geometry.collision`). Results are returned in the planning frame of ``pose``.
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Callable

import numpy as np

from ..errors import InputError, ObjectTooLargeError, PlanningError
from ..geometry.collision import object_bvh
from ..geometry.contact_settings import ContactSettings
from ..geometry.decoder import (
    N_DIMS, DecodedGrasps, GraspModel, decode, make_grasp_model, warm_scene_kernels,
    with_scene,
)
from ..model.builtin import builtin
from ..model.planning_hand import paper_hand_hash
from ..model.hands.model import HandModel as AnyHand
from ..model.hand import JOINT_NAMES, HandModel, load_hand
from ..model.particle import LAYOUT
from ..model.scene import Scene
from .any_hand_planner import plan_any_hand
from .archive import LeaderArchive
from .grg import GuidedGenerator, classify_shape
from .options import ALGORITHMS, PlanOptions
from .problem import ARCHIVE_FACTOR, SwarmProblem
from .result import Contact, GraspCandidate, GraspResult
from .selection import Checked, Verifier, select_candidates, to_candidates
from .simulated import SIMULATION_SPARE, simulate_until_held
from .swarm import IterationStats, run_swarm

__all__ = [
    "ALGORITHMS", "Contact", "GraspResult", "IterationStats", "Objective", "PlanOptions",
    "PlanningError", "plan", "prepare", "warm_up",
]

#: Objects whose smallest extent exceeds this cannot be held in a precision grasp.
MAX_GRASPABLE_WIDTH = 0.16
MIN_GRASPABLE_SIZE = 0.005


class GraspProblem(SwarmProblem):
    """The optimisation problem of one plan with the paper's hand: its decoder and GRG
    (:class:`~grasp_apso.search.problem.SwarmProblem` holds the rest)."""

    def make_generator(self, rng: np.random.Generator, should_stop: Callable[[], bool] | None) -> GuidedGenerator:
        return GuidedGenerator(self.model, self.shape, rng, self.wrist_position, should_stop=should_stop)

    def decode(self, x: np.ndarray) -> DecodedGrasps:
        return decode(self.model, x, self.wrist_position)


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
    scene: Scene | None = None,
) -> GraspResult:
    """Plan precision grasps of ``obj`` with APSO (or the simple PSO): up to
    ``options.max_grasps`` ranked, distinct, verified candidates.

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
        Hand description; the shipped paper hand when None. A general hand
        (:class:`grasp_apso.model.hands.HandModel`, :func:`grasp_apso.model.hands.load.load_hand`)
        is planned by :func:`grasp_apso.search.any_hand_planner.plan_any_hand`.
    progress : callable(IterationStats), optional
        Called once per iteration.
    should_stop : callable() -> bool, optional
        Polled before every iteration and between GRG's batches (the first particles of a
        large swarm); True stops the plan (``cancelled`` in the result).
        With ``simulate``, also polled while waiting for the convex decomposition of a new
        mesh and before each simulated grasp: True leaves the rest unsimulated
        (``sim_result`` -1, ``candidates_message`` says why), within about one grasp's
        simulation (0.2 s).
    scene : Scene, optional
        Support planes and obstacles in the planning frame. No returned grasp, pre-grasp
        or approach comes within ``options.clearance`` of it (checked in the decoder and
        again with python-fcl); wrists are sampled from the free side of the planes.

    Raises
    ------
    PlanningError
        The object cannot be grasped by this hand (too large, too small, no valid
        particle found by GRG), or the scene leaves no room for the hand ("no
        collision-free grasp").
    SceneError
        The object sinks into a support plane or penetrates an obstacle (``object_pose``).
    InputError
        Invalid options, pose or scene.
    """
    options = options or PlanOptions()
    rng = rng if rng is not None else np.random.default_rng()
    pose = np.eye(4) if pose is None else np.asarray(pose, dtype=float)
    if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
        raise InputError(f"pose: expected a finite (4, 4) transform, got shape {pose.shape}")
    scene_obj = _scene_in_object_frame(obj, pose, scene)
    if isinstance(hand, AnyHand):  # a general hand: its own path (the paper hand's below is unchanged)
        return plan_any_hand(obj, pose, options, rng, hand, progress, should_stop, scene_obj, scene)

    t0 = time.perf_counter()
    model = prepare(obj, hand, options)
    shape = classify_shape(obj)
    if scene_obj is not None:
        model = with_scene(model, scene_obj, options.clearance, options.approach_distance)
        if len(scene_obj.planes):
            shape = shape.with_support(scene_obj.planes[:, :3])
    preparation = time.perf_counter() - t0

    t1 = time.perf_counter()
    archive = LeaderArchive(ARCHIVE_FACTOR * options.max_grasps, options.min_orientation_gap,
                            options.min_position_gap)
    problem = GraspProblem(model, shape, options, rng, archive, should_stop)
    adaptive = options.algorithm == "apso"
    swarm = run_swarm(problem, options.swarm_options(), rng, adaptive, progress, should_stop)
    best = swarm.best if np.isfinite(swarm.best_fitness) else np.clip(swarm.best, model.lower, model.upper)
    verifier = Verifier(model, problem, options, pose, object_bvh(obj), scene_obj)
    primary, runner_up = verifier.check_one(best), False
    if not (primary.valid and primary.force_closure):
        # The fitness rewards balance but does not guarantee force closure: prefer a
        # slightly less fit grasp that the independent epsilon measure accepts.
        x = _closure_runner_up(model, problem, swarm, best, options, verifier)
        if x is not None:
            other = verifier.check_one(x)
            if other.valid and other.force_closure:
                primary, runner_up = other, True
    if scene_obj is not None and not primary.scene_clear:
        primary, runner_up = None, False
    wanted = options.max_grasps * (SIMULATION_SPARE if options.simulate else 1)
    others, considered, rejected = select_candidates(verifier, primary, archive, wanted,
                                                     closure_only=not options.simulate)
    checked = ([primary] if primary is not None else []) + others
    if not checked:
        raise PlanningError(
            f"scene: no collision-free grasp: none of the {len(archive) + 1} best distinct grasps the search "
            f"found keeps the clearance ({options.clearance * 1000:.1f} mm) from the support planes and "
            "obstacles at the grasp, the pre-grasp and along the approach (python-fcl)", "scene")
    sims, sim_note = None, ""
    if options.simulate:  # the simulation in the final selection: held grasps first, within the time bound
        checked, sims, sim_note = simulate_until_held(
            model.hand, obj, pose, checked, scene, options.friction, options.max_grasps,
            pinned_first=scene_obj is None, should_stop=should_stop,
            decomposition_timeout=options.decomposition_timeout)
    candidates, order = to_candidates(model.hand, checked, pose, options.approach_distance,
                                      pinned_first=scene_obj is None and sims is None, sims=sims)
    top = checked[int(order[0])]
    runner_up = runner_up and top is primary
    message = _candidates_message(len(candidates), options.max_grasps, len(archive), considered, rejected,
                                  scene_obj is not None)
    if sims is not None:
        n_held = sum(s is not None and s.held for s in sims)
        if n_held < len(candidates):
            message = (message + "; " if message else "") + (
                f"{n_held} of {len(candidates)} held in the simulation (the dropped ones rank last)")
    if sim_note:  # candidates not simulated (sim_result -1) or simulated on a coarser shape: why
        message = (message + "; " if message else "") + sim_note
    result = _result(top, candidates, message, runner_up, swarm, problem, options, pose, shape, preparation, t1)
    return replace(result, hand_hash=paper_hand_hash()) if hand is None else result


def _scene_in_object_frame(obj, pose: np.ndarray, scene) -> Scene | None:
    """The scene moved into the object frame (None when absent or empty), after checking
    that the object (placed by ``pose``) neither sinks into a plane nor penetrates an obstacle."""
    if scene is None:
        return None
    if not isinstance(scene, Scene):
        raise InputError(f"scene: expected a Scene, got {type(scene).__name__}", "scene")
    if scene.is_empty:
        return None
    vertices = np.asarray(obj.mesh.vertices, dtype=float) @ pose[:3, :3].T + pose[:3, 3]
    scene.check_object_placement(vertices, "object_pose")
    return scene.transformed(np.linalg.inv(pose))


def _candidates_message(n: int, wanted: int, archived: int, considered: int, rejected: int, scene: bool) -> str:
    """Why fewer than ``wanted`` candidates came back ("" when all did)."""
    if n >= wanted:
        return ""
    checks = "epsilon, python-fcl collisions with the object" + (
        ", the scene and the approach" if scene else "")
    return (
        f"{n} of {wanted} grasps: the search kept {archived} distinct leaders (wrists at least the "
        f"orientation or position gap apart), {considered} of them distinct from the best grasp, "
        f"{rejected} failed verification ({checks}) or were not force closure (only force-closure "
        f"grasps are returned once one is found); more particles or iterations find more"
    )


def warm_up() -> float:
    """Load the compiled kernels (:mod:`grasp_apso.geometry.kernels`,
    :mod:`grasp_apso.geometry.scene_kernels`, :mod:`grasp_apso.quality.kernels`, the
    archive's) before the first plan.

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
    # the scene kernels (their signatures do not depend on which primitives a scene holds)
    table = Scene.table_under(np.asarray(cube.mesh.vertices))
    warm_scene_kernels(with_scene(prepare(cube), table, 0.005, 0.08))
    return time.perf_counter() - t0


def _closure_runner_up(model, problem, swarm, best: np.ndarray, options: PlanOptions,
                       verifier: Verifier) -> np.ndarray | None:
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
        _, closure = verifier.epsilon(decoded.contact_points[i][contact], decoded.contact_normals[i][contact])
        if closure:
            return x[i]
    return None


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


def _result(top: Checked, candidates, message: str, runner_up: bool, swarm, problem, options: PlanOptions,
            pose: np.ndarray, shape, preparation: float, t1: float) -> GraspResult:
    """The GraspResult whose top-level fields are ``top`` = ``candidates[0]``."""
    best = candidates[0]
    rot, trans = pose[:3, :3], pose[:3, 3]
    return GraspResult(
        configuration=LAYOUT.cg(best.joint_positions),
        joint_names=JOINT_NAMES,
        joint_positions=best.joint_positions.copy(),
        standoff=float(top.closed[LAYOUT.standoff]),
        wrist_pose=best.wrist_pose.copy(),
        wrist_in_object=top.wrist_in_object.copy(),
        fitness=top.fitness,
        epsilon=top.epsilon,
        force_closure=top.force_closure,
        contacts=top.contacts,
        valid=top.valid,
        history=tuple(swarm.history),
        iterations_run=swarm.iterations_run,
        evaluations=problem.evaluations,
        planning_time=time.perf_counter() - t1,
        preparation_time=preparation,
        cancelled=swarm.cancelled,
        algorithm=options.algorithm,
        shape_class=shape.name,
        fcl=top.fcl,
        joints=top.joints @ rot.T + trans,
        max_penetration=top.max_penetration,
        tip_gaps=top.tip_gaps.copy(),
        runner_up=runner_up,
        candidates=candidates,
        candidates_message=message,
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
        pose = np.eye(4) if pose is None else np.asarray(pose, float)
        verifier = Verifier(self.model, self.problem, options, pose, object_bvh(self.model.obj))
        top = verifier.check_one(x_best)
        candidates, _ = to_candidates(self.model.hand, [top], pose, options.approach_distance, pinned_first=True)
        res = _result(top, candidates, "", False, swarm, self.problem, options, pose, self.shape,
                      self.preparation_time, self._started)
        return GraspResult(**{**res.__dict__, "algorithm": algorithm})
