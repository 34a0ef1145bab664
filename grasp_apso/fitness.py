"""Fitness of decoded grasps (paper section 4.4), maximised, vectorised (P, D) -> (P,).

For an *active* particle (legal, at least 2 fingertip contacts)::

    fitness = W_SHAPE * shape + W_BALANCE * balance + W_COUNT * count + W_FACTOR * factor

in [0, 1], with

- ``shape``: contact polygon quality, ``1 - Q`` with Q of eq. 8-10 (0 is the regular
  polygon) for nc >= 3; for nc = 2 the polygon is undefined and half the antipodality
  score is used (two point contacts cannot be force closure, so a pinch never beats a
  good tripod);
- ``balance``: eq. 11-12, every finger pushes toward the centre of mass;
  ``(1 - |sum of unit forces| / nc)``, times the friction-cone feasibility of the worst
  of those pushes: 1 when the push toward the centre of mass lies inside the contact's
  friction cone (half-angle atan(mu) about the inward normal), falling linearly to 0 at
  ``CONE_MARGIN`` beyond it. Forces through the centre of mass exert no torque, so when
  they balance and all lie inside their cones the fingers can squeeze the object, and
  three or more non-collinear contacts are then force closure;
- ``count``: ``(nc - 1) / 4``, more fingertip contacts are better (2 -> 0.25, 5 -> 1);
- ``factor``: the GRG shape parameter factor's term (see :mod:`grasp_apso.grg`): how well
  the wrist matches the approach of the object's shape class, in [0, 1].

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

from .contacts import DecodedGrasps, GraspModel
from .quality import antipodal_score, force_balance_residual, polygon_shape_q

W_SHAPE = 0.30
W_BALANCE = 0.30
W_COUNT = 0.30
W_FACTOR = 0.10
GAP_SCALE = 0.1
CONE_MARGIN = np.radians(15.0)


@dataclass(frozen=True)
class FitnessTerms:
    """Fitness and its terms for a batch (P,) each; terms are NaN for inactive particles."""

    fitness: np.ndarray
    active: np.ndarray
    shape: np.ndarray
    balance: np.ndarray
    count: np.ndarray
    factor: np.ndarray


def cone_feasibility(points: np.ndarray, normals: np.ndarray, com: np.ndarray, mu: float) -> np.ndarray:
    """How well a push from each contact toward the centre of mass fits its friction cone:
    1 inside, 0 from ``CONE_MARGIN`` outside.

    points, normals : (P, F, 3) (outward unit normals); com : (3,) -> (P, F) in [0, 1]
    """
    to_com = com - points
    to_com /= np.maximum(np.linalg.norm(to_com, axis=-1, keepdims=True), 1e-12)
    angle = np.arccos(np.clip(np.einsum("pfi,pfi->pf", to_com, -normals), -1.0, 1.0))
    half = np.arctan(mu)
    return np.clip((half + CONE_MARGIN - angle) / CONE_MARGIN, 0.0, 1.0)


def evaluate(
    model: GraspModel, decoded: DecodedGrasps, factor: np.ndarray, mu: float
) -> FitnessTerms:
    """Fitness of decoded particles.

    Parameters
    ----------
    model : GraspModel
    decoded : DecodedGrasps, batch of P
    factor : (P,) float in [0, 1]
        Shape-class term for each particle's wrist (:meth:`grasp_apso.grg.ShapeClass.wrist_score`).
    mu : float
        Friction coefficient.
    """
    mask = decoded.contact
    nc = mask.sum(axis=1)
    legal = decoded.legal(model.settings.max_penetration)
    active = legal & (nc >= 2)
    com = np.asarray(model.obj.center_of_mass, dtype=float)
    pts, nrm = decoded.contact_points, decoded.contact_normals

    shape = np.full(len(nc), np.nan)
    poly = nc >= 3
    if poly.any():
        shape[poly] = 1.0 - polygon_shape_q(pts[poly], mask[poly])
    pair = nc == 2
    if pair.any():
        shape[pair] = 0.5 * antipodal_score(pts[pair], nrm[pair], mask[pair])
    residual = force_balance_residual(pts, mask, com)
    cone = cone_feasibility(pts, nrm, com, mu)
    cone_worst = np.where(nc > 0, np.where(mask, cone, 1.0).min(axis=1), 0.0)
    balance = (1.0 - residual) * cone_worst
    count = (nc - 1) / 4.0
    score = W_SHAPE * shape + W_BALANCE * balance + W_COUNT * count + W_FACTOR * factor

    gaps = np.sort(np.clip(decoded.tip_gap, 0.0, GAP_SCALE), axis=1)[:, :3].mean(axis=1)
    inactive_score = -1.0 - gaps / GAP_SCALE - (~legal).astype(float)
    fitness = np.where(active, score, inactive_score)
    nan = np.where(active, 1.0, np.nan)
    return FitnessTerms(
        fitness=fitness, active=active, shape=shape * nan, balance=balance * nan,
        count=count * nan, factor=np.asarray(factor, dtype=float) * nan,
    )
