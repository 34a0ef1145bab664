"""Exact distance from points to a triangle mesh (a compiled loop, no approximation).

trimesh's ``closest_point`` takes about 1 s for 3,000 points on a 5,000-face mesh; the
sphere cover of a hand link needs that many queries per link. Here each point first takes
the exact distance to the triangles of its nearest centroids (a k-d tree) as an upper
bound, then visits groups of neighbouring triangles (32 in Morton order), skipping a group
whose bounding sphere lies farther than the best distance so far, and within a group
measures only the triangles whose own bounding sphere (centroid, farthest vertex) comes
closer: exact, and 20x to 100x faster.

The sign comes from the angle-weighted pseudo-normal of the closest feature (face, edge
or vertex): exact for a closed, consistently oriented mesh, robust next to edges (where
ray parity miscounts), and free (no ray tracer: trimesh's own takes ~2 s for 5,000
points on 5,000 faces without embree).
"""

from __future__ import annotations

import math

import numba
import numpy as np
import trimesh
from scipy.spatial import cKDTree

__all__ = ["MeshDistance"]

_jit = numba.njit(cache=True, nogil=True)
#: Nearest centroids measured first to seed the bound; triangles per group.
_SEED_TRIANGLES = 4
_GROUP = 32


# Regions of a triangle a, b, c where the closest point lies (index into the pseudo-normals).
_FACE, _VA, _VB, _VC, _EAB, _EAC, _EBC = 0, 1, 2, 3, 4, 5, 6


@_jit
def _point_triangle_sq(px, py, pz, tri):
    """(squared distance, region, offset p - q) from a point to one triangle ``tri`` (3, 3),
    q its closest point (Ericson's Voronoi regions)."""
    ax, ay, az = tri[0, 0], tri[0, 1], tri[0, 2]
    abx, aby, abz = tri[1, 0] - ax, tri[1, 1] - ay, tri[1, 2] - az
    acx, acy, acz = tri[2, 0] - ax, tri[2, 1] - ay, tri[2, 2] - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return apx * apx + apy * apy + apz * apz, _VA, apx, apy, apz
    bpx, bpy, bpz = px - tri[1, 0], py - tri[1, 1], pz - tri[1, 2]
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return bpx * bpx + bpy * bpy + bpz * bpz, _VB, bpx, bpy, bpz
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        qx, qy, qz = apx - v * abx, apy - v * aby, apz - v * abz
        return qx * qx + qy * qy + qz * qz, _EAB, qx, qy, qz
    cpx, cpy, cpz = px - tri[2, 0], py - tri[2, 1], pz - tri[2, 2]
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return cpx * cpx + cpy * cpy + cpz * cpz, _VC, cpx, cpy, cpz
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        qx, qy, qz = apx - w * acx, apy - w * acy, apz - w * acz
        return qx * qx + qy * qy + qz * qz, _EAC, qx, qy, qz
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        bcx, bcy, bcz = tri[2, 0] - tri[1, 0], tri[2, 1] - tri[1, 1], tri[2, 2] - tri[1, 2]
        qx, qy, qz = bpx - w * bcx, bpy - w * bcy, bpz - w * bcz
        return qx * qx + qy * qy + qz * qz, _EBC, qx, qy, qz
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    qx = apx - abx * v - acx * w
    qy = apy - aby * v - acy * w
    qz = apz - abz * v - acz * w
    return qx * qx + qy * qy + qz * qz, _FACE, qx, qy, qz


@_jit
def _distances(points, triangles, centers, reach, seeds, pseudo, groups, group_center, group_reach, out, closest):
    """out[i] = signed distance from points[i] to the mesh (m, > 0 outside), closest[i] its
    closest point on the mesh (``closest`` (N, 3), or (0, 3): not written); seeds (N, k)
    are measured first. Triangles come in groups of neighbours (``groups[g]`` to
    ``groups[g + 1]``) with a bounding sphere each: a group that cannot come closer than
    the best so far is skipped whole. The sign: the offset from the closest point against
    the angle-weighted pseudo-normal of the closest feature (Baerentzen and Aanaes 2005),
    exact for a closed, consistently oriented mesh."""
    for i in range(points.shape[0]):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        best = np.inf
        best_t, best_r = 0, 0
        ox, oy, oz = 0.0, 0.0, 0.0
        for s in range(seeds.shape[1]):
            t = seeds[i, s]
            d, r, dx, dy, dz = _point_triangle_sq(px, py, pz, triangles[t])
            if d < best:
                best, best_t, best_r, ox, oy, oz = d, t, r, dx, dy, dz
        best_d = math.sqrt(best)
        for g in range(group_reach.shape[0]):
            gx, gy, gz = px - group_center[g, 0], py - group_center[g, 1], pz - group_center[g, 2]
            if math.sqrt(gx * gx + gy * gy + gz * gz) - group_reach[g] >= best_d:
                continue
            for t in range(groups[g], groups[g + 1]):
                cx, cy, cz = px - centers[t, 0], py - centers[t, 1], pz - centers[t, 2]
                lower = math.sqrt(cx * cx + cy * cy + cz * cz) - reach[t]
                if lower < best_d:
                    d, r, dx, dy, dz = _point_triangle_sq(px, py, pz, triangles[t])
                    if d < best:
                        best, best_t, best_r, ox, oy, oz = d, t, r, dx, dy, dz
                        best_d = math.sqrt(best)
        n = pseudo[best_t, best_r]
        out[i] = best_d if ox * n[0] + oy * n[1] + oz * n[2] >= 0.0 else -best_d
        if closest.shape[0] > 0:
            closest[i, 0], closest[i, 1], closest[i, 2] = px - ox, py - oy, pz - oz


def _pseudo_normals(mesh: trimesh.Trimesh) -> np.ndarray:
    """(F, 7, 3) per triangle: its face normal, its vertices' angle-weighted normals (a, b,
    c) and its edges' normals (ab, ac, bc: the sum of the two faces' normals)."""
    faces = np.asarray(mesh.faces)
    normals = np.asarray(mesh.face_normals, dtype=np.float64)
    angles = np.nan_to_num(np.asarray(mesh.face_angles, dtype=np.float64))
    vertex = np.zeros((len(mesh.vertices), 3))
    for k in range(3):
        np.add.at(vertex, faces[:, k], angles[:, k, None] * normals)
    pairs = np.sort(np.stack([faces[:, [0, 1]], faces[:, [0, 2]], faces[:, [1, 2]]], axis=1).reshape(-1, 2), axis=1)
    _, edge_id = np.unique(pairs, axis=0, return_inverse=True)
    edge_id = edge_id.ravel()
    edge = np.zeros((edge_id.max() + 1, 3))
    np.add.at(edge, edge_id, np.repeat(normals, 3, axis=0))
    out = np.empty((len(faces), 7, 3))
    out[:, 0] = normals
    out[:, 1:4] = vertex[faces]
    out[:, 4:7] = edge[edge_id].reshape(-1, 3, 3)
    return np.ascontiguousarray(out)


def _morton_order(centers: np.ndarray) -> np.ndarray:
    """Indices that sort points along a Morton (Z-order) curve: neighbours stay together."""
    lo, hi = centers.min(axis=0), centers.max(axis=0)
    q = np.floor((centers - lo) / np.maximum(hi - lo, 1e-12) * 1023.0).astype(np.uint64)
    code = np.zeros(len(centers), dtype=np.uint64)
    for bit in range(10):
        for axis in range(3):
            code |= ((q[:, axis] >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit + axis)
    return np.argsort(code, kind="stable")


class MeshDistance:
    """Exact signed point-to-mesh distance for one mesh (built once, reused).

    mesh : a watertight, consistently oriented trimesh.Trimesh (outward normals).
    """

    def __init__(self, mesh: trimesh.Trimesh):
        triangles = np.asarray(mesh.triangles, dtype=np.float64)
        order = _morton_order(triangles.mean(axis=1))
        self._triangles = np.ascontiguousarray(triangles[order])
        self._centers = self._triangles.mean(axis=1)
        self._reach = np.linalg.norm(self._triangles - self._centers[:, None, :], axis=2).max(axis=1)
        self._tree = cKDTree(self._centers)
        self._pseudo = np.ascontiguousarray(_pseudo_normals(mesh)[order])
        self._groups = np.append(np.arange(0, len(order), _GROUP), len(order)).astype(np.int64)
        count = len(self._groups) - 1
        self._group_center = np.empty((count, 3))
        self._group_reach = np.empty(count)
        for g in range(count):
            a, b = self._groups[g], self._groups[g + 1]
            corners = self._triangles[a:b].reshape(-1, 3)
            self._group_center[g] = 0.5 * (corners.min(axis=0) + corners.max(axis=0))
            self._group_reach[g] = np.linalg.norm(corners - self._group_center[g], axis=1).max()

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """points : (N, 3) float, m -> (N,) float, m (> 0 outside)."""
        return self._query(points, False)[0]

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """points : (N, 3) float, m -> (signed distances (N,) m, > 0 outside; the closest
        points on the mesh (N, 3) m)."""
        return self._query(points, True)

    def _query(self, points: np.ndarray, with_closest: bool) -> tuple[np.ndarray, np.ndarray]:
        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        k = min(_SEED_TRIANGLES, len(self._centers))
        _, seeds = self._tree.query(pts, k=k)
        seeds = np.ascontiguousarray(np.asarray(seeds, dtype=np.int64).reshape(len(pts), k))
        out = np.empty(len(pts))
        closest = np.empty((len(pts) if with_closest else 0, 3))
        _distances(pts, self._triangles, self._centers, self._reach, seeds, self._pseudo, self._groups,
                   self._group_center, self._group_reach, out, closest)
        return out, closest
