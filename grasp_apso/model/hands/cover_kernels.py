"""Which surface samples lie inside which candidate sphere or capsule: a compiled query.

The set cover in :mod:`.spheres` needs, for thousands of candidates, the samples each one
covers. scipy's ``query_ball_point`` returns Python lists (most of the cover's time went
into building them); here the samples are bucketed once in a uniform grid and each
candidate visits the cells its bounding box overlaps, in two passes (count, then fill).
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["covered_pairs"]

_jit = numba.njit(cache=True, nogil=True)
#: Grid cells at most (the cell grows beyond).
_MAX_CELLS = 2_000_000


@_jit
def _segment_sq(px, py, pz, ax, ay, az, bx, by, bz):
    dx, dy, dz = bx - ax, by - ay, bz - az
    length2 = dx * dx + dy * dy + dz * dz
    t = 0.0
    if length2 > 0.0:
        t = ((px - ax) * dx + (py - ay) * dy + (pz - az) * dz) / length2
        t = min(1.0, max(0.0, t))
    qx, qy, qz = px - ax - t * dx, py - ay - t * dy, pz - az - t * dz
    return qx * qx + qy * qy + qz * qz


@_jit
def _pairs(points, order, cell_start, lo, cell, dims, a, b, reach, fill, rows, cols):
    """Count (fill False) or write (fill True) the (element, sample) pairs; returns the count."""
    n = 0
    for m in range(a.shape[0]):
        r = reach[m]
        if r <= 0.0:
            continue
        r2 = r * r
        first = np.empty(3, np.int64)
        last = np.empty(3, np.int64)
        for k in range(3):
            low = min(a[m, k], b[m, k]) - r
            high = max(a[m, k], b[m, k]) + r
            first[k] = max(0, int(np.floor((low - lo[k]) / cell)))
            last[k] = min(dims[k] - 1, int(np.floor((high - lo[k]) / cell)))
        for i in range(first[0], last[0] + 1):
            for j in range(first[1], last[1] + 1):
                for k in range(first[2], last[2] + 1):
                    c = (i * dims[1] + j) * dims[2] + k
                    for s in range(cell_start[c], cell_start[c + 1]):
                        p = order[s]
                        d2 = _segment_sq(points[p, 0], points[p, 1], points[p, 2], a[m, 0], a[m, 1], a[m, 2],
                                         b[m, 0], b[m, 1], b[m, 2])
                        if d2 <= r2:
                            if fill:
                                rows[n] = m
                                cols[n] = p
                            n += 1
    return n


def covered_pairs(a: np.ndarray, b: np.ndarray, reach: np.ndarray, points: np.ndarray,
                  cell: float) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols): sample ``cols[i]`` lies within ``reach[rows[i]]`` of the segment
    from ``a[rows[i]]`` to ``b[rows[i]]`` (a point when they are equal).

    a, b : (M, 3) m; reach : (M,) m; points : (S, 3) m; cell : grid cell, m (about the
    typical reach).
    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    lo = points.min(axis=0) - 1e-9
    span = points.max(axis=0) - lo + 1e-9
    cell = max(float(cell), float((np.prod(span) / _MAX_CELLS) ** (1.0 / 3.0)), 1e-6)
    dims = np.maximum(np.ceil(span / cell).astype(np.int64), 1)
    key = np.minimum(np.floor((points - lo) / cell).astype(np.int64), dims - 1)
    linear = (key[:, 0] * dims[1] + key[:, 1]) * dims[2] + key[:, 2]
    order = np.argsort(linear, kind="stable").astype(np.int64)
    cell_start = np.searchsorted(linear[order], np.arange(int(np.prod(dims)) + 1)).astype(np.int64)
    args = (points, order, cell_start, lo, cell, dims, np.ascontiguousarray(a, dtype=np.float64),
            np.ascontiguousarray(b, dtype=np.float64), np.ascontiguousarray(reach, dtype=np.float64))
    empty = np.zeros(0, np.int64)
    count = _pairs(*args, False, empty, empty)
    rows, cols = np.empty(count, np.int64), np.empty(count, np.int64)
    _pairs(*args, True, rows, cols)
    return rows, cols
