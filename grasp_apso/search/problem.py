"""The optimisation problem the swarm (:func:`grasp_apso.search.swarm.run_swarm`) solves,
shared by the paper hand's path (:class:`grasp_apso.search.planner.GraspProblem`) and a
general hand's (:class:`grasp_apso.search.any_hand_planner.AnyHandProblem`): decode + fitness
over (P, D) particles, GRG draws, the evaluation counters, the leaders' archive. A subclass
names its decoder and its generator only.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from ..quality.fitness import evaluate
from .archive import LeaderArchive
from .options import PlanOptions

__all__ = ["ARCHIVE_FACTOR", "SCENE_GUIDE", "SwarmProblem"]

#: The leaders' archive holds this many times ``max_grasps`` distinct grasps.
ARCHIVE_FACTOR = 4
#: Scene-illegal particles score up to 1 lower, by their depth inside the clearance over
#: this (m), so that the simple PSO is guided out of the scene too.
SCENE_GUIDE = 0.02


class SwarmProblem:
    """Decode + fitness, and GRG draws, of one plan.

    ``archive`` (optional) observes every evaluation: the leaders' archive of the
    candidates (:mod:`grasp_apso.search.archive`); it changes nothing in the search.
    ``should_stop`` reaches GRG's batches (a deadline or a cancel during a large start).
    """

    def __init__(self, model: Any, shape: Any, options: PlanOptions, rng: np.random.Generator,
                 archive: LeaderArchive | None = None, should_stop: Callable[[], bool] | None = None):
        self.model = model
        self.shape = shape
        self.mu = options.friction
        self.wrist_position = None if options.wrist_position is None else np.asarray(options.wrist_position, float)
        self.lower, self.upper = model.lower, model.upper
        self.generator = self.make_generator(rng, should_stop)
        self.archive = archive
        self._evaluations = 0

    def make_generator(self, rng: np.random.Generator, should_stop: Callable[[], bool] | None) -> Any:
        """The GRG of this hand (``draw(k) -> (k, D)``, ``evaluations``)."""
        raise NotImplementedError

    def decode(self, x: np.ndarray) -> Any:
        """Decoded grasps of particles ``x`` (P, D)."""
        raise NotImplementedError

    @property
    def evaluations(self) -> int:
        return self._evaluations + self.generator.evaluations

    @property
    def distinct_candidates(self) -> int:
        """Entries of the leaders' archive so far (the action feedback)."""
        return 0 if self.archive is None else len(self.archive)

    def fitness(self, decoded: Any) -> tuple[np.ndarray, np.ndarray]:
        """(P,) fitness and (P,) active flags of decoded particles (scene-illegal ones guided out)."""
        terms = evaluate(self.model, decoded, self.shape.wrist_score(decoded.wrist[:, :3, :3]), self.mu)
        fitness = terms.fitness
        if self.model.scene is not None:
            fitness = fitness - np.minimum(decoded.scene_violation / SCENE_GUIDE, 1.0)
        return fitness, terms.active

    def evaluate(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(P, D) -> fitness (P,), active (P,), contact counts (P,)."""
        decoded = self.decode(x)
        self._evaluations += len(x)
        fitness, active = self.fitness(decoded)
        if self.archive is not None:
            self.archive.offer(x, fitness, active, decoded.wrist)
        return fitness, active, decoded.n_contacts

    def guided(self, k: int) -> np.ndarray:
        return self.generator.draw(k)
