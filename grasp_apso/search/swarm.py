"""Adaptive Particle Swarm Optimization and the simple PSO (paper section 4.3).

Both share the paper's update (steps c-d), maximising the fitness::

    v = v + c1 r1 (pbest - p) + c2 r2 (gbest - p)     r1, r2 ~ U(0, 1) per dimension
    p = clamp(p + v)                                   velocity zeroed where clamped
    v = w v                                            w in [0, 1]

with the velocity also limited to ``velocity_max`` times each dimension's range.

APSO (``adaptive=True``): GRG initialisation (step a), and after each evaluation the
adaptive parts: inactive particles (fewer than 2 contacts or illegal) are taken off
and replaced by new GRG particles, and the particles are split into fixed
neighbourhoods of ``neighborhood_size``; a neighbourhood whose best fitness has not
improved by ``improvement`` over ``stall_iterations`` iterations has its worst particle
replaced by a new GRG particle. At most ``max_replacements`` of the swarm is replaced in
one iteration (the lowest fitness first).

Simple PSO (``adaptive=False``): uniform random initialisation, no replacement.

A general hand's APSO (``local_best``) replaces ``gbest`` in the update by the best
personal best of the particle's own neighbourhood (a local-best PSO over the same fixed
neighbourhoods) for the first part of the iterations.

An evaluation is one particle decoded (GRG candidates included), so the two can be
given the same budget (``max_evaluations``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, fields
from typing import Callable, Protocol

import numpy as np

from ..errors import InputError
from ..tunables import check, default


@dataclass(frozen=True)
class SwarmOptions:
    """Swarm parameters (paper defaults np = 60, nit = 50, neighbourhoods of 5).

    ``max_evaluations`` = 0 means no evaluation cap (only ``iterations``).
    """

    particles: int = default("particles")
    iterations: int = default("iterations")
    neighborhood_size: int = default("neighborhood_size")
    c1: float = default("c1")
    c2: float = default("c2")
    inertia: float = default("inertia")
    stall_iterations: int = default("stall_iterations")
    improvement: float = default("improvement")
    velocity_init: float = default("velocity_init")
    velocity_max: float = default("velocity_max")
    max_evaluations: int = default("max_evaluations")
    max_replacements: float = default("max_replacements")

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, check(f.name, getattr(self, f.name)))
        if self.neighborhood_size > self.particles:
            raise InputError(
                f"neighborhood_size: {self.neighborhood_size} is larger than particles ({self.particles})")


class Problem(Protocol):
    """What the swarm optimises (implemented by the planner)."""

    lower: np.ndarray  # (D,)
    upper: np.ndarray  # (D,)
    evaluations: int

    def evaluate(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """x (P, D) -> fitness (P,), active (P,) bool, fingertip contacts (P,) int."""

    def guided(self, k: int) -> np.ndarray:
        """k new GRG particles (k, D)."""


@dataclass(frozen=True)
class IterationStats:
    """Progress after one iteration (1-based)."""

    iteration: int
    iterations: int
    best_fitness: float
    mean_fitness: float
    active_particles: int
    best_contacts: int
    evaluations: int
    elapsed: float
    replaced: int = 0
    #: Distinct candidates the leaders' archive holds so far (:mod:`grasp_apso.search.archive`).
    distinct_candidates: int = 0


@dataclass
class SwarmResult:
    best: np.ndarray
    best_fitness: float
    #: (P, 19) personal bests and their fitness (P,) at the end (-inf: replaced, not yet evaluated).
    personal_best: np.ndarray | None = None
    personal_best_fitness: np.ndarray | None = None
    history: list[IterationStats] = field(default_factory=list)
    iterations_run: int = 0
    cancelled: bool = False


def _leaders(fitness: np.ndarray, starts: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """The index of the fittest particle (the first of ties) of each contiguous
    neighbourhood starting at ``starts`` (G,), ``groups`` (P,) each particle's
    neighbourhood: fitness (P,) -> (G,) int."""
    top = np.flatnonzero(fitness == np.maximum.reduceat(fitness, starts)[groups])
    return top[np.unique(groups[top], return_index=True)[1]]


def run_swarm(
    problem: Problem,
    options: SwarmOptions,
    rng: np.random.Generator,
    adaptive: bool,
    progress: Callable[[IterationStats], None] | None = None,
    should_stop: Callable[[], bool] | None = None,
    local_best: float = 0.0,
) -> SwarmResult:
    """Run APSO (``adaptive``) or the simple PSO for ``options.iterations`` iterations.

    Stops early when ``should_stop()`` turns true (checked before every iteration, so a
    cancel is honoured within one iteration) or the evaluation cap is reached.

    ``local_best`` (APSO only), a share of the iterations in [0, 1]: in the first
    ``local_best * iterations`` iterations the social term pulls each particle toward the
    best personal best of its own neighbourhood (the fixed neighbourhoods of
    ``neighborhood_size``) instead of the swarm's best, so that the neighbourhoods search
    apart and one early basin (a two-finger pinch) does not draw in the whole swarm; the
    swarm's best then refines the best basin found. The result's best is the swarm's best
    throughout. The paper hand's planner leaves it at 0 (the paper's update); the general
    hands' sets :data:`grasp_apso.search.any_hand_planner.LOCAL_BEST`.
    """
    if not 0.0 <= local_best <= 1.0:
        raise InputError(f"local_best: expected a share in [0, 1], got {local_best!r}", "local_best")
    start = time.perf_counter()
    lo, hi = np.asarray(problem.lower, dtype=float), np.asarray(problem.upper, dtype=float)
    span = hi - lo
    n, dims = options.particles, len(lo)

    def random_velocity(k: int) -> np.ndarray:
        return rng.uniform(-1.0, 1.0, (k, dims)) * options.velocity_init * span

    # a) initial population and velocities
    pos = problem.guided(n) if adaptive else rng.uniform(lo, hi, (n, dims))
    vel = random_velocity(n)
    pbest = pos.copy()
    pbest_f = np.full(n, -np.inf)
    gbest = pos[0].copy()
    gbest_f = -np.inf
    gbest_nc = 0
    groups = np.arange(n) // options.neighborhood_size
    group_starts = np.arange(0, n, options.neighborhood_size)  # neighbourhoods are contiguous
    group_hist: list[np.ndarray] = []
    vmax = options.velocity_max * span
    result = SwarmResult(best=gbest, best_fitness=gbest_f)

    for it in range(1, options.iterations + 1):
        if should_stop is not None and should_stop():
            result.cancelled = True
            break
        if options.max_evaluations and problem.evaluations >= options.max_evaluations:
            break
        # b, c) evaluate, personal and global bests
        fit, active, ncontacts = problem.evaluate(pos)
        improved = fit > pbest_f
        pbest[improved] = pos[improved]
        pbest_f[improved] = fit[improved]
        k = int(np.argmax(pbest_f))
        if pbest_f[k] > gbest_f:
            gbest, gbest_f = pbest[k].copy(), float(pbest_f[k])
            gbest_nc = int(ncontacts[k]) if improved[k] else gbest_nc

        # d) velocity and position update
        r1 = rng.random((n, dims))
        r2 = rng.random((n, dims))
        local = adaptive and it <= local_best * options.iterations
        social = pbest[_leaders(pbest_f, group_starts, groups)[groups]] if local else gbest
        vel = vel + options.c1 * r1 * (pbest - pos) + options.c2 * r2 * (social - pos)
        vel = np.clip(vel, -vmax, vmax)
        moved = pos + vel
        clamped = (moved < lo) | (moved > hi)
        pos = np.clip(moved, lo, hi)
        vel[clamped] = 0.0
        vel *= options.inertia

        replaced = 0
        if adaptive:
            # Inactive particles are taken off; stalled neighbourhoods lose their worst.
            out = ~active
            group_best = np.maximum.reduceat(pbest_f, group_starts)
            group_hist.append(group_best)
            if len(group_hist) > options.stall_iterations:
                gain = group_best - group_hist[-1 - options.stall_iterations]
                for g in np.flatnonzero(gain < options.improvement):
                    members = np.flatnonzero(groups == g)
                    out[members[np.argmin(fit[members])]] = True
                    group_hist[-1 - options.stall_iterations][g] = group_best[g] - 1.0  # restart its window
            # At most max_replacements of the swarm per iteration, the worst first: GRG
            # draws cost decodes, and the swarm needs continuity to converge.
            idx = np.flatnonzero(out)
            cap = int(np.ceil(options.max_replacements * n))
            if idx.size > cap:
                idx = idx[np.argsort(fit[idx])[:cap]]
            if idx.size:
                pos[idx] = problem.guided(idx.size)
                vel[idx] = random_velocity(idx.size)
                pbest[idx] = pos[idx]
                pbest_f[idx] = -np.inf
                replaced = idx.size

        mean_active = float(fit[active].mean()) if active.any() else float("nan")
        stats = IterationStats(
            iteration=it, iterations=options.iterations, best_fitness=gbest_f,
            mean_fitness=mean_active, active_particles=int(active.sum()), best_contacts=gbest_nc,
            evaluations=problem.evaluations, elapsed=time.perf_counter() - start, replaced=replaced,
            distinct_candidates=int(getattr(problem, "distinct_candidates", 0)),
        )
        result.history.append(stats)
        result.iterations_run = it
        if progress is not None:
            progress(stats)

    result.best, result.best_fitness = gbest, gbest_f
    result.personal_best, result.personal_best_fitness = pbest, pbest_f
    return result
