"""Fitness of decoded grasps (paper section 4.4), maximised, vectorised (P, D) -> (P,).

For an *active* particle (legal, at least 2 fingertip contacts)::

    fitness = W_SHAPE * shape + W_BALANCE * balance + W_EQUILIBRIUM * equilibrium
              + W_COUNT * count + W_FACTOR * factor

in [0, 1] (weights 0.20, 0.15, 0.35, 0.20, 0.10), with

- ``shape``: contact polygon quality, ``1 - Q`` with Q of eq. 8-10 (0 is the regular
  polygon) for nc >= 3; for nc = 2 the polygon is undefined and half the antipodality
  score is used (two point contacts cannot be force closure, so a pinch never beats a
  good tripod);
- ``balance``: eq. 11-12 as the paper states it, every finger pushes toward the centre
  of mass with a unit force: ``1 - |sum of unit forces| / nc``;
- ``equilibrium`` (our addition, for physically sound grasps): the paper's balance
  ignores torques and friction, so it accepts grasps that cannot hold and rejects
  four-finger-and-thumb grasps that can. ``1 - min(1, r)`` with ``r`` the distance from
  the origin to the convex hull of the contacts' unit normal wrenches
  (:func:`grasp_apso.quality.measures.normal_wrench_residual`): 0 when a squeeze along the
  contact normals in which every contact carries at least a quarter of the mean load
  balances force and torque, which with friction and three or more non-collinear
  contacts is force closure. Collinear contacts balance without being
  force closure, so for nc >= 3 the term is scaled by ``min(1, (1 - Q) / 0.5)`` (full
  for polygons better than Q = 0.5) and for nc = 2 by 0.5;
- ``count``: ``(nc - 1) / 4``, more fingertip contacts are better (2 -> 0.25, 5 -> 1);
- ``factor``: the GRG shape parameter factor's term (see :mod:`grasp_apso.search.grg`): how well
  the wrist matches the approach of the object's shape class, in [0, 1].

Contacts on an ill-defined normal (issue 13, part 6; ``docs/algorithm.md``, "Uncertain
contacts"): a contact ``i`` whose normal spread ``u_i`` (rad, the model's
:class:`~grasp_apso.geometry.normal_spread.NormalSpreadGrid` at the contact point: large at an
edge, a corner or a rim) approaches the friction cone's half-angle ``alpha = atan(mu)`` is
*uncertain* by ``e_i = clip((u_i - alpha / 2) / (alpha / 2), 0, 1)`` (0 below alpha / 2,
1 from alpha on). With ``E = sum_i e_i`` over the contacts::

    shape, balance, equilibrium  *=  1 - E / nc
    count = (nc - E / 2 - 1) / 4          (an uncertain contact counts half)

so the search steers toward contacts on well-defined patches. Where every ``e_i`` is 0
the fitness is unchanged bit for bit.

An *inactive* particle (nc < 2, or illegal: a blocked finger, a link penetrating the
object beyond the tolerance, fingers colliding) scores below every active one but still
points toward contact, so the simple PSO is not blind::

    legal, nc < 2:  -1 - g / G          illegal: -2 - g / G

with g the mean clearance of the three fingertip pads nearest the surface, clipped to
[0, G], G = 0.1 m.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import kernels as quality_kernels
from ..geometry.decoder import DecodedGrasps, GraspModel
from .measures import COINCIDENT_ATOL, COINCIDENT_RTOL

W_SHAPE = 0.20
W_BALANCE = 0.15
W_EQUILIBRIUM = 0.35
W_COUNT = 0.20
W_FACTOR = 0.10
GAP_SCALE = 0.1
#: Each contact carries at least this fraction of the mean share of the squeeze.
MIN_SHARE = 0.25
#: A contact is uncertain from this fraction of the friction cone's half-angle on ...
UNCERTAIN_FROM = 0.5
#: ... and fully uncertain at the half-angle itself; it then counts this much of a contact.
UNCERTAIN_COUNT = 0.5


@dataclass(frozen=True)
class FitnessTerms:
    """Fitness and its terms for a batch (P,) each; terms are NaN for inactive particles."""

    fitness: np.ndarray
    active: np.ndarray
    shape: np.ndarray
    balance: np.ndarray
    equilibrium: np.ndarray
    count: np.ndarray
    factor: np.ndarray
    #: (P,) float: the summed uncertainty E of the contacts (0 for well-defined normals).
    uncertain: np.ndarray | None = None


def contact_uncertainty(model: GraspModel, decoded: DecodedGrasps, mu: float) -> np.ndarray:
    """Uncertainty ``e`` in [0, 1] of every fingertip contact (P, 5), 0 for fingers
    without contact or a model without a spread grid: the normal spread ``u`` (rad) at the
    contact point ramped from 0 at ``UNCERTAIN_FROM * atan(mu)`` to 1 at ``atan(mu)``."""
    mask = decoded.contact
    if model.spread is None:
        return np.zeros(mask.shape)
    spread = model.spread.spread(decoded.contact_points)
    alpha = float(np.arctan(mu))
    low = UNCERTAIN_FROM * alpha
    return np.where(mask, np.clip((spread - low) / (alpha - low), 0.0, 1.0), 0.0)


def evaluate(
    model: GraspModel, decoded: DecodedGrasps, factor: np.ndarray, mu: float
) -> FitnessTerms:
    """Fitness of decoded particles.

    Parameters
    ----------
    model : GraspModel
    decoded : DecodedGrasps, batch of P
    factor : (P,) float in [0, 1]
        Shape-class term for each particle's wrist (:meth:`grasp_apso.search.grg.ShapeClass.wrist_score`).
    mu : float
        Friction coefficient.
    """
    mask = decoded.contact
    nc = mask.sum(axis=1)
    legal = decoded.legal(model.settings.max_penetration)
    active = legal & (nc >= 2)
    n = len(nc)
    shape, balance, residual = np.empty(n), np.empty(n), np.empty(n)
    # Every term in one compiled loop over the particles (the functions of
    # grasp_apso.quality.measures compute the same, with their input checks).
    quality_kernels.fitness_terms(
        np.ascontiguousarray(decoded.contact_points), np.ascontiguousarray(decoded.contact_normals),
        np.ascontiguousarray(mask), active, np.asarray(model.obj.center_of_mass, dtype=np.float64),
        float(model.obj.characteristic_radius), MIN_SHARE, COINCIDENT_RTOL, COINCIDENT_ATOL,
        shape, balance, residual,
    )
    # Collinear contacts balance without holding: scale by the polygon's regularity.
    regular = np.where(nc >= 3, np.clip(shape / 0.5, 0.0, 1.0), 0.5)  # shape = 1 - Q
    equilibrium = (1.0 - np.minimum(residual, 1.0)) * regular
    # Contacts on ill-defined normals (edges, corners, rims): see the module docstring.
    uncertain = contact_uncertainty(model, decoded, mu).sum(axis=1)
    if np.any(uncertain > 0.0):
        reliable = 1.0 - uncertain / np.maximum(nc, 1)
        shape, balance, equilibrium = shape * reliable, balance * reliable, equilibrium * reliable
    count = (nc - UNCERTAIN_COUNT * uncertain - 1) / 4.0
    score = (
        W_SHAPE * shape + W_BALANCE * balance + W_EQUILIBRIUM * equilibrium
        + W_COUNT * count + W_FACTOR * factor
    )

    gaps = np.sort(np.clip(decoded.tip_gap, 0.0, GAP_SCALE), axis=1)[:, :3].mean(axis=1)
    inactive_score = -1.0 - gaps / GAP_SCALE - (~legal).astype(float)
    fitness = np.where(active, score, inactive_score)
    nan = np.where(active, 1.0, np.nan)
    return FitnessTerms(
        fitness=fitness, active=active, shape=shape * nan, balance=balance * nan,
        equilibrium=equilibrium * nan, count=count * nan, factor=np.asarray(factor, dtype=float) * nan,
        uncertain=uncertain * nan,
    )
