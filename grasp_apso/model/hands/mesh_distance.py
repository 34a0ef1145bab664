"""Exact distance from points to a triangle mesh (a compiled loop, no approximation).

trimesh's ``closest_point`` takes about 1 s for 3,000 points on a 5,000-face mesh; the
sphere cover of a hand link needs that many queries per link. Here each point first takes
the exact distance to the triangles of its nearest centroids (a k-d tree) as an upper
bound, then visits every triangle but measures only those whose bounding sphere (centroid,
farthest vertex) comes closer than the best distance so far: exact, and about 20x faster.

The sign (inside or outside) is the caller's business (:mod:`.geometry` uses the mesh's
ray-parity ``contains`` on a watertight mesh).
"""

from __future__ import annotations

import math

import numba
import numpy as np
import trimesh
from scipy.spatial import cKDTree

__all__ = ["MeshDistance"]

_jit = numba.njit(cache=True, nogil=True)
#: Nearest centroids measured first to seed the bound.
_SEED_TRIANGLES = 4


@_jit
def _point_triangle_sq(px, py, pz, tri):
    """Squared distance from a point to one triangle ``tri`` (3, 3) (Ericson's regions)."""
    ax, ay, az = tri[0, 0], tri[0, 1], tri[0, 2]
    abx, aby, abz = tri[1, 0] - ax, tri[1, 1] - ay, tri[1, 2] - az
    acx, acy, acz = tri[2, 0] - ax, tri[2, 1] - ay, tri[2, 2] - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return apx * apx + apy * apy + apz * apz
    bpx, bpy, bpz = px - tri[1, 0], py - tri[1, 1], pz - tri[1, 2]
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return bpx * bpx + bpy * bpy + bpz * bpz
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        qx, qy, qz = apx - v * abx, apy - v * aby, apz - v * abz
        return qx * qx + qy * qy + qz * qz
    cpx, cpy, cpz = px - tri[2, 0], py - tri[2, 1], pz - tri[2, 2]
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return cpx * cpx + cpy * cpy + cpz * cpz
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        qx, qy, qz = apx - w * acx, apy - w * acy, apz - w * acz
        return qx * qx + qy * qy + qz * qz
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        bcx, bcy, bcz = tri[2, 0] - tri[1, 0], tri[2, 1] - tri[1, 1], tri[2, 2] - tri[1, 2]
        qx, qy, qz = bpx - w * bcx, bpy - w * bcy, bpz - w * bcz
        return qx * qx + qy * qy + qz * qz
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    qx = apx - abx * v - acx * w
    qy = apy - aby * v - acy * w
    qz = apz - abz * v - acz * w
    return qx * qx + qy * qy + qz * qz


@_jit
def _distances(points, triangles, centers, reach, seeds, out):
    """out[i] = min over triangles of |points[i] - triangle| (m); seeds (N, k) first."""
    for i in range(points.shape[0]):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        best = np.inf
        for s in range(seeds.shape[1]):
            d = _point_triangle_sq(px, py, pz, triangles[seeds[i, s]])
            if d < best:
                best = d
        best_d = math.sqrt(best)
        for t in range(triangles.shape[0]):
            dx, dy, dz = px - centers[t, 0], py - centers[t, 1], pz - centers[t, 2]
            lower = math.sqrt(dx * dx + dy * dy + dz * dz) - reach[t]
            if lower < best_d:
                d = _point_triangle_sq(px, py, pz, triangles[t])
                if d < best:
                    best = d
                    best_d = math.sqrt(best)
        out[i] = best_d


class MeshDistance:
    """Exact unsigned point-to-mesh distance for one mesh (built once, reused).

    mesh : trimesh.Trimesh with at least one face.
    """

    def __init__(self, mesh: trimesh.Trimesh):
        self._triangles = np.ascontiguousarray(mesh.triangles, dtype=np.float64)
        self._centers = self._triangles.mean(axis=1)
        self._reach = np.linalg.norm(self._triangles - self._centers[:, None, :], axis=2).max(axis=1)
        self._tree = cKDTree(self._centers)

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """points : (N, 3) float, m -> (N,) float, m (>= 0)."""
        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        k = min(_SEED_TRIANGLES, len(self._centers))
        _, seeds = self._tree.query(pts, k=k)
        seeds = np.ascontiguousarray(np.asarray(seeds, dtype=np.int64).reshape(len(pts), k))
        out = np.empty(len(pts))
        _distances(pts, self._triangles, self._centers, self._reach, seeds, out)
        return out
