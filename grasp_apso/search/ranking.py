"""The ranking score ``grasp_quality`` of a candidate, in [0, 1].

One formula, in tiers, so that sorting by the score puts the grasps an arm should try
first at the top::

    grasp_quality = (tier + f) / T

    f     = clip(fitness, 0, 1)            the swarm's fitness (contact polygon, balance,
                                           equilibrium, contact count, shape factor)
    tier  = 2 * held + c                   held: 1 when the MuJoCo check held the object
                                           (only when it ran), else 0
    c     = 2  valid and force closure     (Ferrari-Canny epsilon > 0)
            1  valid, not force closure
            0  not valid
    T     = 6 when the simulation ran, else 3

So held grasps come before dropped ones, force-closure grasps before the others, and
within a tier the fitter first. The epsilon measure enters through its sign (force
closure): its magnitude is dominated by the object's size and the friction, while the
fitness already scores the contact geometry, and keeping the fitness as the order within
a tier keeps the swarm's best grasp first (today's behaviour). Ties are broken by epsilon
(:func:`rank_order`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["grasp_quality", "rank_order"]


def grasp_quality(fitness: np.ndarray, valid: np.ndarray, force_closure: np.ndarray,
                  held: np.ndarray | None = None) -> np.ndarray:
    """The ranking score (N,) in [0, 1] (see the module docstring).

    fitness : (N,) float; valid, force_closure : (N,) bool; held : (N,) bool or None
    (None: not simulated).
    """
    f = np.clip(np.nan_to_num(np.asarray(fitness, dtype=float), nan=0.0, neginf=0.0), 0.0, 1.0)
    valid = np.asarray(valid, dtype=bool)
    c = np.where(valid & np.asarray(force_closure, dtype=bool), 2.0, np.where(valid, 1.0, 0.0))
    if held is None:
        return (c + f) / 3.0
    return (2.0 * np.asarray(held, dtype=bool) + c + f) / 6.0


def rank_order(quality: np.ndarray, epsilon: np.ndarray) -> np.ndarray:
    """Indices (N,) that sort candidates by descending quality, then epsilon (stable)."""
    return np.lexsort((-np.asarray(epsilon, dtype=float), -np.asarray(quality, dtype=float)))
