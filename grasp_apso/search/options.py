"""What a plan can be told: :class:`PlanOptions` (SI units), validated at construction.

Defaults and ranges come from :mod:`grasp_apso.tunables` (one source of truth); this only
lists which tunables a plan takes and the few per-call values that are not tunables
(``wrist_position``).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from ..errors import InputError
from ..tunables import check, default
from .swarm import SwarmOptions

__all__ = ["ALGORITHMS", "PlanOptions"]

ALGORITHMS: tuple[str, ...] = ("apso", "pso")


@dataclass(frozen=True)
class PlanOptions:
    """Everything a plan can be told (SI units). Invalid values raise :class:`InputError`
    (a ``ValueError``) naming the field; ranges and meanings: :mod:`grasp_apso.tunables`.

    Attributes
    ----------
    algorithm : "apso" | "pso"
    particles, iterations, neighborhood_size, c1, c2, inertia, stall_iterations,
    improvement, max_evaluations
        Swarm parameters (:class:`~grasp_apso.search.swarm.SwarmOptions`).
    contact_tolerance : float, m
    friction : float
        Coulomb friction coefficient of the fitness and the Ferrari-Canny epsilon.
    friction_edges : int
    closure_candidates : int
        When the global best is not force closure, up to this many of the next-best
        distinct personal bests are verified and the first force-closure one is returned.
    wrist_position : (3,) float or None, m
        Fixed wrist position in the object frame; None computes it per particle.
    clearance : float, m
        Least distance between the hand and the scene (support planes, obstacles), at the
        grasp and along the approach.
    approach_distance : float, m
        The pre-grasp wrist is retreated this far along minus the approach direction.
    max_grasps : int
        Ranked, distinct candidates returned (1..50).
    min_orientation_gap : float, rad
    min_position_gap : float, m
        Two candidates are distinct when their wrists differ by at least one of these.
    simulate : bool
        Check every candidate in the MuJoCo simulation (:mod:`grasp_apso.simulation`).
    decomposition_timeout : float, s
        Bound of one convex decomposition run of a new non-convex mesh for the simulation
        (:mod:`grasp_apso.simulation.convex`); the plan itself waits for it only until
        its ``should_stop`` turns true.
    """

    algorithm: str = default("algorithm")
    particles: int = default("particles")
    iterations: int = default("iterations")
    neighborhood_size: int = default("neighborhood_size")
    c1: float = default("c1")
    c2: float = default("c2")
    inertia: float = default("inertia")
    stall_iterations: int = default("stall_iterations")
    improvement: float = default("improvement")
    max_evaluations: int = default("max_evaluations")
    contact_tolerance: float = default("contact_tolerance")
    friction: float = default("friction")
    friction_edges: int = default("friction_edges")
    closure_candidates: int = default("closure_candidates")
    wrist_position: tuple[float, float, float] | None = None
    clearance: float = default("clearance")
    approach_distance: float = default("approach_distance")
    max_grasps: int = default("max_grasps")
    min_orientation_gap: float = default("min_orientation_gap")
    min_position_gap: float = default("min_position_gap")
    simulate: bool = False
    decomposition_timeout: float = default("decomposition_timeout")

    def __post_init__(self) -> None:
        for f in fields(self):
            if f.name in ("wrist_position", "simulate"):
                continue
            object.__setattr__(self, f.name, check(f.name, getattr(self, f.name)))
        if not isinstance(self.simulate, (bool, np.bool_)):
            raise InputError(f"simulate: expected true or false, got {self.simulate!r}")
        if self.wrist_position is not None:
            wp = np.asarray(self.wrist_position, dtype=float)
            if wp.shape != (3,) or not np.all(np.isfinite(wp)):
                raise InputError(f"wrist_position: expected 3 finite numbers, got {self.wrist_position!r}")
        self.swarm_options()  # validates the swarm parameters together

    def swarm_options(self) -> SwarmOptions:
        """The swarm's share of the options."""
        return SwarmOptions(
            particles=self.particles, iterations=self.iterations,
            neighborhood_size=self.neighborhood_size, c1=self.c1, c2=self.c2,
            inertia=self.inertia, stall_iterations=self.stall_iterations,
            improvement=self.improvement, max_evaluations=self.max_evaluations,
        )
