"""The ranking score ``grasp_quality`` of a candidate, in [0, 1].

One formula, in tiers, so that sorting by the score puts the grasps an arm should try
first at the top::

    grasp_quality = (tier + f) / T

    f     = clip(fitness, 0, 1)            the swarm's fitness (contact polygon, balance,
                                           equilibrium, contact count, shape factor)
    tier  = 4 * held + c                   held: 1 when the MuJoCo check held the object
                                           (only when it ran), else 0
    c     = 3  valid, robust force closure (robust epsilon > 0: closure survives the
                                           normal uncertainty at edges and corners)
            2  valid and force closure     (Ferrari-Canny epsilon > 0)
            1  valid, not force closure
            0  not valid
    T     = 8 when the simulation ran, else 4

So held grasps come before dropped ones, robust force-closure grasps before fragile ones
(closure resting on an edge or a corner), those before the others, and within a tier the
fitter first. The epsilon measure enters through its sign (force
closure): its magnitude is dominated by the object's size and the friction, while the
fitness already scores the contact geometry, and keeping the fitness as the order within
a tier keeps the swarm's best grasp first (today's behaviour). Ties are broken by epsilon
(:func:`rank_order`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["grasp_quality", "rank_order", "ranking_class"]


def grasp_quality(fitness: np.ndarray, valid: np.ndarray, force_closure: np.ndarray,
                  held: np.ndarray | None = None, robust: np.ndarray | None = None) -> np.ndarray:
    """The ranking score (N,) in [0, 1] (see the module docstring).

    fitness : (N,) float; valid, force_closure : (N,) bool; held : (N,) bool or None
    (None: not simulated); robust : (N,) bool or None (None: every force-closure grasp
    counts as robust).
    """
    f = np.clip(np.nan_to_num(np.asarray(fitness, dtype=float), nan=0.0, neginf=0.0), 0.0, 1.0)
    c = ranking_class(valid, force_closure, robust)
    if held is None:
        return (c + f) / 4.0
    return (4.0 * np.asarray(held, dtype=bool) + c + f) / 8.0


def ranking_class(valid: np.ndarray, force_closure: np.ndarray, robust: np.ndarray | None = None) -> np.ndarray:
    """The class ``c`` of the formula (N,) float: 3 robust force closure, 2 force closure,
    1 valid, 0 not valid (arguments as :func:`grasp_quality`)."""
    valid = np.asarray(valid, dtype=bool)
    closure = valid & np.asarray(force_closure, dtype=bool)
    robust = closure if robust is None else closure & np.asarray(robust, dtype=bool)
    return np.where(robust, 3.0, np.where(closure, 2.0, np.where(valid, 1.0, 0.0)))


def rank_order(quality: np.ndarray, epsilon: np.ndarray) -> np.ndarray:
    """Indices (N,) that sort candidates by descending quality, then epsilon (stable)."""
    return np.lexsort((-np.asarray(epsilon, dtype=float), -np.asarray(quality, dtype=float)))
