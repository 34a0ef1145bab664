"""Capsule candidates for a link's cover: spheres swept along straight segments.

A box needs hundreds of spheres with a 2 mm stray (its edges are covered only by spheres
centred within about 3 mm of them, each covering under 6 mm of edge); a capsule along the
edge covers it whole. :func:`capsule_candidates` sweeps candidate sphere centres along the
link's principal directions as far as the depth below the surface stays within a little of
the centre's own, and gives each segment the radius ``least depth along it + tolerance``
(less the half step the depth was sampled at: the signed distance is 1-Lipschitz), so a
capsule strays no more than a sphere does. :mod:`.spheres` offers them to its set cover
beside the spheres when asked (``cover_link(..., capsules=True)``).
"""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from .geometry import LinkGeometry

__all__ = ["capsule_candidates", "segment_distances", "principal_axes"]

#: Centres swept at most, the step (tolerances) and the most steps each way, the depth a
#: sweep may lose (tolerances), and the depth (tolerances) below which a centre is shallow.
_MAX_SWEPT = 900
_STEP = 0.5
_MAX_STEPS = 200
_DEPTH_LOSS = 0.25
_SHALLOW = 2.0
#: Grid cells (tolerances) that keep one swept centre each, and steps marched at a time.
_SHALLOW_CELL = 1.0
_DEEP_CELL = 3.0
_CHUNK = 8


def segment_distances(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from points to segments, row by row: (N, 3) x (N, 3) x (N, 3) -> (N,), m."""
    ab = b - a
    length2 = np.einsum("ij,ij->i", ab, ab)
    t = np.clip(np.einsum("ij,ij->i", points - a, ab) / np.maximum(length2, 1e-30), 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * ab), axis=1)


def principal_axes(geoms: Sequence[LinkGeometry], points: np.ndarray) -> np.ndarray:
    """Unit directions to sweep along: each geometry's frame axes and the principal axes of
    the surface samples, without near-duplicates. (A, 3)."""
    axes = [g.origin[:3, :3].T for g in geoms]
    centred = points - points.mean(axis=0)
    axes.append(np.linalg.svd(centred, full_matrices=False)[2])
    out: list[np.ndarray] = []
    for axis in np.vstack(axes):
        axis = axis / np.linalg.norm(axis)
        if all(abs(axis @ kept) < 0.99 for kept in out):
            out.append(axis)
    return np.array(out)


def _spread(centers: np.ndarray, depths: np.ndarray, tolerance: float,
            rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """At most ``_MAX_SWEPT`` centres spread over the link: one per cell of a grid (finer
    for shallow centres, which sweep along edges), cells in a seeded random order."""
    order = rng.permutation(len(centers))
    centers, depths = centers[order], depths[order]
    shallow = depths <= _SHALLOW * tolerance
    cell = np.where(shallow, _SHALLOW_CELL, _DEEP_CELL) * tolerance
    key = np.column_stack([np.floor(centers / cell[:, None]).astype(np.int64), shallow])
    _, first = np.unique(key, axis=0, return_index=True)
    first = np.sort(first)[:_MAX_SWEPT]
    return centers[first], depths[first]


def capsule_candidates(depth_of: Callable[[np.ndarray], np.ndarray], centers: np.ndarray, depths: np.ndarray,
                       axes: np.ndarray, reach: float, tolerance: float, margin: float,
                       rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Segments (a, b) and radii of capsules swept from candidate centres.

    depth_of : points (N, 3) -> depth below the surface (N,), m (< 0 outside).
    centers : (M, 3) candidate sphere centres, depths (M,) their depths, m.
    axes : (A, 3) unit directions; reach : m, the longest half-sweep.
    Returns a (C, 3), b (C, 3), radii (C,): radius = least depth along the segment less
    half a step + tolerance - margin (never more than the spheres at its ends would get).
    """
    centers, depths = _spread(centers, depths, tolerance, rng)
    step = _STEP * tolerance
    steps = int(min(np.ceil(reach / step), _MAX_STEPS))
    offsets = step * np.arange(1, steps + 1)
    floor = depths - _DEPTH_LOSS * tolerance
    out_a, out_b, out_r = [], [], []
    for axis in axes:
        # Both ways from every centre: rows (M, 2) flattened; march a chunk of steps at a
        # time, only the sweeps still inside (most stop within a step or two).
        start = np.repeat(centers, 2, axis=0)
        sign = np.tile([1.0, -1.0], len(centers))
        row_floor = np.repeat(floor, 2)
        taken = np.zeros(len(start), dtype=np.int64)
        least = np.repeat(depths, 2)
        alive = np.ones(len(start), dtype=bool)
        for first in range(0, steps, _CHUNK):
            rows = np.nonzero(alive)[0]
            if len(rows) == 0:
                break
            k = offsets[first:first + _CHUNK]
            pts = start[rows, None, :] + (sign[rows, None] * k[None, :])[:, :, None] * axis
            depth = depth_of(pts.reshape(-1, 3)).reshape(len(rows), len(k))
            ok = depth >= row_floor[rows, None]
            run = np.where(ok.all(axis=1), len(k), np.argmin(ok, axis=1))
            taken[rows] += run
            within = np.arange(len(k))[None, :] < run[:, None]
            least[rows] = np.minimum(least[rows], np.where(within, depth, np.inf).min(axis=1))
            alive[rows] = run == len(k)
        forward, backward = taken[0::2], taken[1::2]
        keep = forward + backward >= 2
        if not keep.any():
            continue
        idx = np.nonzero(keep)[0]
        a = centers[idx] + (forward[idx] * step)[:, None] * axis
        b = centers[idx] - (backward[idx] * step)[:, None] * axis
        both = np.minimum(least[0::2], least[1::2])[idx]
        radius = both - 0.5 * step + tolerance - margin
        good = radius > 0.5 * tolerance
        out_a.append(a[good])
        out_b.append(b[good])
        out_r.append(radius[good])
    if not out_a:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
    return np.vstack(out_a), np.vstack(out_b), np.concatenate(out_r)
