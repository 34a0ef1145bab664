"""Force closure decided without the 6-D hull where a short proof exists, the epsilon
value built only when it is read.

A selection sorts many analysed grasps by whether they are force closure (and robust), but
ranks by their epsilon values only the few it keeps. qhull in 6-D costs 2-4 ms a grasp;
this module's proof about 40 us:

- :func:`closure_certificate` ``(wrenches (n, 6)) -> True | False | None``: False when
  :func:`~grasp_apso.quality.measures.origin_may_be_inside` proves the origin outside the
  wrench hull, True when a strictly positive combination of the wrenches proves epsilon
  above :data:`CERTIFIED_EPS`, None when neither (the hull decides).
- :class:`Epsilon`: a wrench set's Ferrari-Canny epsilon
  (:func:`~grasp_apso.quality.measures.hull_epsilon`, the same value) whose verdict is known
  on construction and whose value is computed on first read.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import nnls

from .measures import FORCE_CLOSURE_EPS, hull_only_epsilon, origin_may_be_inside

__all__ = ["CERTIFIED_EPS", "epsilon_lower_bound", "closure_certificate", "Epsilon"]

#: A proven lower bound on epsilon above this certifies force closure: a thousand times
#: :data:`~grasp_apso.quality.measures.FORCE_CLOSURE_EPS`, so the hull's rounding (about
#: 1e-15) cannot put the hull's value at or below that threshold.
CERTIFIED_EPS = 1000.0 * FORCE_CLOSURE_EPS


def epsilon_lower_bound(wrenches: NDArray[np.float64]) -> float:
    """A proven lower bound (may be negative: no proof) on the epsilon of ``wrenches`` (n, 6).

    Non-negative least squares of ``sum_i (1 + mu_i) w_i = 0`` (mu >= 0) gives weights
    ``l_i = 1 + mu_i >= l_min > 0`` with residual ``r = |sum_i l_i w_i|``; ``L = sum_i l_i``
    and ``s`` the least singular value of W (n, 6). For any unit u with ``h = max_i w_i.u``:
    every ``l_j (h - w_j.u) <= sum_i l_i (h - w_i.u) <= h L + r``, so ``min_i w_i.u >= h -
    (h L + r) / l_min``; and ``max_i |w_i.u| >= s / sqrt(n)``. Hence ``h >= (s / sqrt(n) -
    r / l_min) / (L / l_min - 1)`` for every u, and epsilon, the least such h over unit
    directions (the hull's nearest facet), is at least that."""
    n = wrenches.shape[0]
    if n < 7:  # fewer than 7 points never hold a 6-D ball
        return -1.0
    sigma = float(np.linalg.svd(wrenches, compute_uv=False)[-1])
    try:
        mu, _ = nnls(wrenches.T, -wrenches.sum(axis=0))
    except (RuntimeError, ValueError):  # no convergence: no proof
        return -1.0
    weights = 1.0 + mu
    residual = float(np.linalg.norm(wrenches.T @ weights))
    low, total = float(weights.min()), float(weights.sum())
    return (sigma / math.sqrt(n) - residual / low) / max(total / low - 1.0, 1.0)


def closure_certificate(wrenches: NDArray[np.float64]) -> bool | None:
    """Force closure of the wrench set (n, 6) when a short proof decides it: False when the
    origin is proven outside the hull (the quick test of
    :func:`~grasp_apso.quality.measures.hull_epsilon`, which then returns 0 too), True when
    :func:`epsilon_lower_bound` exceeds :data:`CERTIFIED_EPS`, None otherwise."""
    if not origin_may_be_inside(wrenches):
        return False
    return True if epsilon_lower_bound(wrenches) > CERTIFIED_EPS else None


class Epsilon:
    """The Ferrari-Canny epsilon of a wrench set (the value of
    :func:`~grasp_apso.quality.measures.hull_epsilon`): ``force_closure`` known on
    construction (:func:`closure_certificate`, else the hull), ``value`` computed on first
    read when only the proof was needed. ``Epsilon(None)``: no wrenches, 0."""

    __slots__ = ("force_closure", "_wrenches", "_value")

    def __init__(self, wrenches: NDArray[np.float64] | None):
        self._wrenches = wrenches
        self._value: float | None = 0.0
        if wrenches is None:
            self.force_closure = False
            return
        verdict = closure_certificate(wrenches)
        if verdict is None:
            self._value = hull_only_epsilon(wrenches)
            verdict = self._value > 0.0
        elif verdict:
            self._value = None  # proven; the hull when the value is read
        self.force_closure = bool(verdict)

    @classmethod
    def known(cls, value: float) -> "Epsilon":
        """An epsilon whose value is given (>= 0)."""
        eps = cls(None)
        eps._value = float(value)
        eps.force_closure = eps._value > 0.0
        return eps

    @property
    def value(self) -> float:
        """Epsilon (dimensionless), 0 when not force closure."""
        if self._value is None:
            self._value = hull_only_epsilon(self._wrenches)
        return self._value
