"""Planning with a general hand (:class:`grasp_apso.model.hands.HandModel`), next to the
paper hand's path: :func:`grasp_apso.search.planner.plan` comes here when ``hand`` is one.

The swarm (:func:`grasp_apso.search.swarm.run_swarm`) optimises particles of the hand's
layout (:mod:`grasp_apso.geometry.any_hand_tables`) decoded by
:mod:`grasp_apso.geometry.any_hand_decoder`, scored by the paper's fitness
(:func:`grasp_apso.quality.fitness.evaluate` over F fingers); GRG is
:mod:`grasp_apso.search.any_hand_grg`; the leaders' archive offers the distinct
candidates, verified and ranked in :mod:`grasp_apso.search.any_hand_select`.
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np

from ..errors import InputError, PlanningError
from ..geometry.any_hand_decoder import AnyDecoded, AnyHandModel, decode_any, make_any_hand_model, with_any_scene
from ..geometry.contact_settings import ContactSettings
from ..quality.fitness import evaluate
from .archive import LeaderArchive
from .any_hand_grg import AnyHandGenerator
from .any_hand_select import build_result, select_any
from .grg import classify_shape
from .options import PlanOptions
from .swarm import IterationStats, run_swarm

__all__ = ["AnyHandProblem", "plan_any_hand", "prepare_any_hand", "warm_up_any_hand"]

#: As the paper path (search.planner): archive size over max_grasps, the scene guide (m).
ARCHIVE_FACTOR = 4
SCENE_GUIDE = 0.02


class AnyHandProblem:
    """The optimisation problem of one plan (the swarm's ``Problem``): decode + fitness, GRG."""

    def __init__(self, model: AnyHandModel, shape, options: PlanOptions, rng: np.random.Generator,
                 archive: LeaderArchive | None = None, should_stop: Callable[[], bool] | None = None):
        self.model, self.shape, self.mu = model, shape, options.friction
        self.wrist_position = None if options.wrist_position is None else np.asarray(options.wrist_position, float)
        self.lower, self.upper = model.lower, model.upper
        self.generator = AnyHandGenerator(model, shape, rng, self.wrist_position, should_stop)
        self.archive = archive
        self._evaluations = 0

    @property
    def evaluations(self) -> int:
        return self._evaluations + self.generator.evaluations

    @property
    def distinct_candidates(self) -> int:
        return 0 if self.archive is None else len(self.archive)

    def decode(self, x: np.ndarray) -> AnyDecoded:
        return decode_any(self.model, x, self.wrist_position)

    def fitness(self, decoded: AnyDecoded):
        """The fitness terms of decoded particles (scene-illegal ones guided out)."""
        terms = evaluate(self.model, decoded, self.shape.wrist_score(decoded.wrist[:, :3, :3]), self.mu)
        fitness = terms.fitness
        if self.model.scene is not None:
            fitness = fitness - np.minimum(decoded.scene_violation / SCENE_GUIDE, 1.0)
        return fitness, terms.active

    def evaluate(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        decoded = self.decode(x)
        self._evaluations += len(x)
        fitness, active = self.fitness(decoded)
        if self.archive is not None:
            self.archive.offer(x, fitness, active, decoded.wrist)
        return fitness, active, decoded.n_contacts

    def guided(self, k: int) -> np.ndarray:
        return self.generator.draw(k)


def prepare_any_hand(obj, hand, options: PlanOptions) -> AnyHandModel:
    """The model of ``obj`` with ``hand`` (grids and tables cached)."""
    extents = np.asarray(obj.principal_extents, dtype=float)
    if extents[0] < 0.005:
        raise PlanningError(f"object: too small for a precision grasp: its largest extent is {extents[0] * 1000:.1f} mm")
    return make_any_hand_model(hand, obj, ContactSettings(tolerance=options.contact_tolerance))


def plan_any_hand(obj, pose: np.ndarray, options: PlanOptions, rng: np.random.Generator, hand,
                  progress: Callable[[IterationStats], None] | None, should_stop: Callable[[], bool] | None,
                  scene_obj, scene) -> "GraspResult":  # noqa: F821
    """The general hand's plan; arguments as :func:`grasp_apso.search.planner.plan`
    (``scene_obj``: the scene in the object frame, or None; ``scene`` as given)."""
    if options.wrist_position is not None and np.shape(options.wrist_position) != (3,):
        raise InputError("wrist_position: expected (3,)", "wrist_position")
    t0 = time.perf_counter()
    model = prepare_any_hand(obj, hand, options)
    shape = classify_shape(obj)
    if scene_obj is not None:
        model = with_any_scene(model, scene_obj, options.clearance, options.approach_distance)
        if len(scene_obj.planes):
            shape = shape.with_support(scene_obj.planes[:, :3])
    preparation = time.perf_counter() - t0
    t1 = time.perf_counter()
    archive = LeaderArchive(ARCHIVE_FACTOR * options.max_grasps, options.min_orientation_gap,
                            options.min_position_gap)
    problem = AnyHandProblem(model, shape, options, rng, archive, should_stop)
    swarm = run_swarm(problem, options.swarm_options(), rng, options.algorithm == "apso", progress, should_stop)
    checked, message = select_any(model, problem, swarm, archive, options, pose, obj, scene)
    return build_result(model, checked, message, swarm, problem, options, pose, shape, preparation, t1, obj,
                        scene, should_stop)


def warm_up_any_hand(hand) -> float:
    """Load (or, once after an install, compile: about 20 s) the general hand's kernels and
    build the hand's tables before its first plan: a tiny plan of the built-in cube on a
    table. The node calls it for a configured general hand as it calls
    :func:`grasp_apso.search.planner.warm_up` for the paper hand. Returns the seconds it took."""
    from ..model.builtin import builtin
    from ..model.scene import Scene

    t0 = time.perf_counter()
    cube = builtin("cube")
    table = Scene.table_under(np.asarray(cube.mesh.vertices))
    options = PlanOptions(particles=4, iterations=1, neighborhood_size=2, max_grasps=1)
    try:
        plan_any_hand(cube, np.eye(4), options, np.random.default_rng(0), hand, None, None, table, table)
    except PlanningError:
        pass  # the kernels ran; a tiny swarm may find no grasp
    return time.perf_counter() - t0
