"""Bounded-variable least squares, compiled (numba): ``min |A x - b|`` with ``lb <= x <= ub``.

SciPy's ``lsq_linear(A, b, bounds, method="bvls")`` (Stark and Parker's algorithm) step for
step: the unbounded least-squares solution when it lies within the bounds, else BVLS
started from it (SciPy's initialisation loop, then its loops A and B, its tolerance and
iteration limit), each least-squares solve LAPACK's ``gelsd`` with SciPy's ``rcond``. Why:
the selection solves a few hundred of these problems per plan (six or seven rows, one column
per contact: :func:`grasp_apso.quality.closing.closing_forces`), where SciPy's per-call
overhead (0.25-0.4 ms) was most of the time; compiled, a problem takes microseconds.
``test_closing.py`` compares it with SciPy on random and rank-deficient problems.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["bounded_lsq"]

#: SciPy's default tolerance of ``lsq_linear``.
TOL = 1e-10

_jit = numba.njit(cache=True, nogil=True)


@_jit
def _kkt(g, on_bound):
    """The largest violation of the KKT conditions (SciPy's ``compute_kkt_optimality``)."""
    out = -np.inf
    for i in range(g.shape[0]):
        v = abs(g[i]) if on_bound[i] == 0 else g[i] * on_bound[i]
        out = max(out, v)
    return out


@_jit
def _solve_free(a, b, x, on_bound, free, rcond):
    """The least-squares solution over the ``free`` columns with the others fixed at x
    (SciPy's ``lstsq(A[:, free], b - A (x * active))``)."""
    m = a.shape[0]
    rhs = b - a @ (x * (on_bound != 0.0))
    sub = np.empty((m, free.shape[0]))
    for k in range(free.shape[0]):
        sub[:, k] = a[:, free[k]]
    return np.linalg.lstsq(sub, rhs, rcond)[0]


@_jit
def _bvls(a, b, lb, ub, tol, max_iter):
    m, n = a.shape
    x = np.linalg.lstsq(a, b, -1.0)[0]
    inside = True
    for i in range(n):
        if not (x[i] >= lb[i] and x[i] <= ub[i]):
            inside = False
    if inside:
        return x
    rcond = np.finfo(np.float64).eps * max(m, n)  # numpy's default: SciPy's BVLS passes None
    on_bound = np.zeros(n)
    for i in range(n):
        if x[i] <= lb[i]:
            x[i] = lb[i]
            on_bound[i] = -1.0
        if x[i] >= ub[i]:
            x[i] = ub[i]
            on_bound[i] = 1.0
    free = np.flatnonzero(on_bound == 0.0)
    r = a @ x - b
    cost = 0.5 * np.dot(r, r)
    g = a.T @ r
    # SciPy's initialisation: the free variables' solution, violators set to their bounds
    while free.shape[0] > 0:  # (each pass fixes a variable or ends: at most n)
        z = _solve_free(a, b, x, on_bound, free, rcond)
        keep = np.ones(free.shape[0], dtype=np.bool_)
        for k in range(free.shape[0]):
            j = free[k]
            if z[k] < lb[j]:
                x[j] = lb[j]
                on_bound[j] = -1.0
                keep[k] = False
            elif z[k] > ub[j]:
                x[j] = ub[j]
                on_bound[j] = 1.0
                keep[k] = False
        for k in range(free.shape[0]):
            if keep[k]:
                x[free[k]] = z[k]
        r = a @ x - b
        cost = 0.5 * np.dot(r, r)
        g = a.T @ r
        if keep.all():
            break
        free = free[keep]
    optimality = _kkt(g, on_bound)
    for _ in range(max_iter):  # loop A
        if optimality < tol:
            break
        on_bound[np.argmax(g * on_bound)] = 0.0
        for _ in range(n + 1):  # loop B: each pass but the last puts a free variable on a bound
            free = np.flatnonzero(on_bound == 0.0)
            x_free = x[free]
            z = _solve_free(a, b, x, on_bound, free, rcond) if free.shape[0] else np.empty(0)
            # the first violator (lower bounds first, then upper) at the least step
            best, alpha, side = -1, np.inf, 0.0
            for k in range(free.shape[0]):
                j = free[k]
                if z[k] < lb[j]:
                    step = (lb[j] - x_free[k]) / (z[k] - x_free[k])
                    if step < alpha:
                        best, alpha, side = k, step, -1.0
            for k in range(free.shape[0]):
                j = free[k]
                if z[k] > ub[j]:
                    step = (ub[j] - x_free[k]) / (z[k] - x_free[k])
                    if step < alpha:
                        best, alpha, side = k, step, 1.0
            if best >= 0:
                for k in range(free.shape[0]):
                    x[free[k]] = x_free[k] * (1.0 - alpha) + alpha * z[k]
                on_bound[free[best]] = side
            else:
                for k in range(free.shape[0]):
                    x[free[k]] = z[k]
                break
        r = a @ x - b
        cost_new = 0.5 * np.dot(r, r)
        done = cost - cost_new < tol * cost
        cost = cost_new
        g = a.T @ r
        optimality = _kkt(g, on_bound)
        if done:
            break
    return x


def bounded_lsq(a: np.ndarray, b: np.ndarray, lb: float, ub: float, tol: float = TOL) -> np.ndarray:
    """``argmin |a x - b|`` subject to ``lb <= x <= ub`` (SciPy's ``lsq_linear`` with
    ``method="bvls"``, compiled).

    Parameters
    ----------
    a : (m, n) float
    b : (m,) float
    lb, ub : float
        The same bounds for every variable, ``lb < ub``.
    tol : float
        SciPy's tolerance (stops when the KKT violation or the relative cost change is below it).

    Returns
    -------
    (n,) float
    """
    a = np.ascontiguousarray(a, dtype=np.float64)
    b = np.ascontiguousarray(b, dtype=np.float64)
    if a.ndim != 2 or b.shape != (a.shape[0],):
        raise ValueError(f"a, b: expected (m, n) and (m,), got {a.shape} and {b.shape}")
    if not lb < ub:
        raise ValueError(f"lb, ub: expected lb < ub, got {lb} and {ub}")
    n = a.shape[1]
    return _bvls(a, b, np.full(n, float(lb)), np.full(n, float(ub)), float(tol), n)
