"""Signed distance to the object surface: a grid built once per mesh, vectorised look-ups.

Exact point-to-mesh queries cost about 200 us each (python-fcl) or far more (trimesh), and
a plan makes hundreds of thousands of them (``shared/notes/geometry-speed.md``). So the
signed distance is sampled once on a regular grid around the object and read back by
trilinear interpolation (a compiled loop, :mod:`grasp_apso.geometry.kernels`).

Building the grid (:func:`build_sdf_grid`):

1. voxelise the surface, flood-fill it for inside/outside, and take a Euclidean
   distance transform for the coarse distance away from the surface;
2. in a narrow band around the surface (12 mm outside, 4 mm inside by default), find
   for every node the nearest of area-weighted surface samples (seeded,
   ``scipy.spatial.cKDTree``) and take the exact distance to the triangle that sample
   lies on; the sign from the side of that triangle's plane (for nodes level with the
   plane, from the neighbouring sample the node lies most squarely over).

Outside the grid box, the distance is the value at the nearest box point plus the
distance to the box, an over-estimate that only matters far from the object, where
nothing is decided. Negative values are inside the object. Grids are cached by mesh hash
(:func:`cached_sdf_grid`): in memory, and on disk under ``<cache root>/sdf_grids/`` so that a
new process (a command-line run, a batch worker, a restarted node) reads a mesh's grid
back instead of building it again.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy
import trimesh
from scipy import ndimage
from scipy.spatial import cKDTree

from ..cache import cached, disk_arrays
from . import kernels

#: Bump when :func:`build_sdf_grid` returns other values for the same input (the grids kept
#: on disk are keyed by it).
SDF_GRID_VERSION = 1


@dataclass(frozen=True)
class SignedDistanceGrid:
    """Signed distance samples on a regular grid (immutable).

    Attributes
    ----------
    origin : (3,) float, m
        Position of node (0, 0, 0) in the object frame.
    spacing : float, m
        Node spacing (cubic cells).
    values : (nx, ny, nz) float, m
        Signed distance at the nodes (negative inside).
    """

    origin: np.ndarray
    spacing: float
    values: np.ndarray

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.values.shape  # type: ignore[return-value]

    @property
    def upper(self) -> np.ndarray:
        """(3,) float, m: position of the last node."""
        return self.origin + self.spacing * (np.array(self.shape) - 1)

    def distance_xyz(self, x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
        """Signed distance at points given as separate coordinate arrays.

        Parameters
        ----------
        x, y, z : (...) float, m, object frame (same shape)

        Returns
        -------
        (...) float, m (negative inside)
        """
        shape = np.shape(x)
        if not shape == np.shape(y) == np.shape(z):
            raise ValueError(f"x, y, z: expected the same shape, got {shape}, {np.shape(y)}, {np.shape(z)}")
        x, y, z = (np.ascontiguousarray(v, dtype=np.float64).reshape(-1) for v in (x, y, z))
        out = np.empty(x.shape[0])
        kernels.grid_distances(self._values64, self._origin64, float(self.spacing), x, y, z, out)
        return out.reshape(shape)

    @cached_property
    def _values64(self) -> np.ndarray:
        """The node values as one C-contiguous float64 block (what the kernels read)."""
        return np.ascontiguousarray(self.values, dtype=np.float64)

    @cached_property
    def _origin64(self) -> np.ndarray:
        return np.ascontiguousarray(self.origin, dtype=np.float64)

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance at points (trilinear interpolation).

        Parameters
        ----------
        points : (..., 3) float, m, object frame

        Returns
        -------
        (...,) float, m (negative inside)
        """
        points = np.asarray(points, dtype=float)
        return self.distance_xyz(points[..., 0], points[..., 1], points[..., 2])

    def distance_and_gradient(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed distance and its unit gradient (the outward normal near the surface).

        The gradient is a central difference over half a cell.

        points : (..., 3) float, m -> ((...,) float m, (..., 3) float unit)
        """
        points = np.asarray(points, dtype=np.float64)
        if points.shape[-1:] != (3,):
            raise ValueError(f"points: expected (..., 3), got {points.shape}")
        flat = np.ascontiguousarray(points).reshape(-1, 3)
        distance = np.empty(len(flat))
        gradient = np.empty((len(flat), 3))
        kernels.grid_distances_gradients(self._values64, self._origin64, float(self.spacing), flat, distance,
                                         gradient)
        return distance.reshape(points.shape[:-1]), gradient.reshape(points.shape)

    def gradient(self, points: np.ndarray) -> np.ndarray:
        """Unit gradient of the signed distance (outward surface normal near the surface).

        points : (..., 3) float, m -> (..., 3) float, unit vectors
        """
        return self.distance_and_gradient(points)[1]

    def closest_surface_point(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project points onto the zero level set (one Newton step).

        points : (..., 3) float, m -> (surface points (..., 3), outward normals (..., 3))
        """
        value, normal = self.distance_and_gradient(points)
        return points - value[..., None] * normal, normal


def _surface_samples(mesh: trimesh.Trimesh, spacing: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Area-weighted surface samples and the index of the face each lies on."""
    count = int(np.clip(4.0 * mesh.area / (0.5 * spacing) ** 2, 20_000, 400_000))
    points, face_index = trimesh.sample.sample_surface(mesh, count, seed=seed)
    return np.asarray(points), np.asarray(face_index)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", a, b)


def _point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    t = np.clip(_dot(p - a, ab) / np.maximum(_dot(ab, ab), 1e-30), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1)


def point_triangle_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Exact distance from points to triangles, row by row.

    p, a, b, c : (N, 3) float, m -> (N,) float, m
    """
    n = np.cross(b - a, c - a)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    height = _dot(p - a, n)
    q = p - height[:, None] * n  # projection on the triangle's plane
    # Inside when q is on the inner side of all three edges.
    inside = (
        (_dot(np.cross(b - a, q - a), n) >= 0)
        & (_dot(np.cross(c - b, q - b), n) >= 0)
        & (_dot(np.cross(a - c, q - c), n) >= 0)
    )
    edges = np.minimum(
        np.minimum(_point_segment_distance(p, a, b), _point_segment_distance(p, b, c)),
        _point_segment_distance(p, c, a),
    )
    return np.where(inside, np.abs(height), edges)


def build_sdf_grid(
    mesh: trimesh.Trimesh,
    padding: float = 0.03,
    max_nodes: int = 240_000,
    min_spacing: float = 0.001,
    seed: int = 0,
    band_width: float = 0.012,
    inside_band_width: float = 0.004,
) -> SignedDistanceGrid:
    """Sample the signed distance of a closed mesh on a grid around it.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Object surface in the object frame, m. Should be closed; for an open mesh the
        sign far from the surface falls back to "outside".
    padding : float, m
        Margin around the bounding box covered by the grid.
    max_nodes : int
        Node budget; sets the spacing for large objects.
    min_spacing : float, m
        Finest spacing used for small objects.
    seed : int
        Seed of the surface sampling (the grid is deterministic).
    band_width, inside_band_width : float, m
        Distances outside / inside the surface within which values are accurate
        (sub-millimetre); beyond them they come from a distance transform (error about
        one spacing).

    Returns
    -------
    SignedDistanceGrid
    """
    if padding <= 0 or max_nodes < 1000 or min_spacing <= 0:
        raise ValueError("build_sdf_grid: padding, min_spacing must be > 0 and max_nodes >= 1000")
    lo, hi = mesh.bounds[0] - padding, mesh.bounds[1] + padding
    size = hi - lo
    spacing = max(min_spacing, float(np.cbrt(np.prod(size) / max_nodes)))
    shape = np.ceil(size / spacing).astype(int) + 1
    axes = [lo[a] + spacing * np.arange(shape[a]) for a in range(3)]
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)

    samples, faces = _surface_samples(mesh, spacing, seed)

    # Voxelised surface shell; its flood fill gives inside/outside away from the surface
    # and its Euclidean distance transform the (coarse) distance there.
    occupied = np.zeros(shape, dtype=bool)
    cells = np.clip(np.floor((samples - lo) / spacing + 0.5).astype(int), 0, shape - 1)
    occupied[cells[:, 0], cells[:, 1], cells[:, 2]] = True
    inside = ndimage.binary_fill_holes(occupied) & ~occupied
    coarse = ndimage.distance_transform_edt(~occupied) * spacing
    values = np.where(inside, -coarse, coarse).reshape(-1)

    # Narrow band: accurate distances from the nearest surface sample. Nodes farther than
    # the band keep the coarse value (a KD-tree query far from the surface is slow and
    # nothing is decided there).
    # Inside, only the first millimetres matter (penetration beyond the tolerance is
    # illegal however deep), and deep nodes make slow queries: the band is one-sided.
    band = max(band_width, 3.0 * spacing) + 2.0 * spacing
    band_inside = max(inside_band_width, 2.0 * spacing) + 2.0 * spacing
    near_nodes = np.flatnonzero((values <= band) & (values >= -band_inside))
    # The shell above needs dense samples to be closed; finding a nearby triangle for the
    # exact distance needs about a third of them.
    # Every triangle is represented by its centroid too.
    samples = np.vstack([samples[::3], mesh.triangles_center])
    faces = np.concatenate([faces[::3], np.arange(len(mesh.faces))])
    normals = np.asarray(mesh.face_normals)[faces]
    tree = cKDTree(samples)
    dist3, idx3 = tree.query(nodes[near_nodes], k=3, distance_upper_bound=band, workers=-1)
    found = np.isfinite(dist3[:, 0])
    near_nodes, dist3, idx3 = near_nodes[found], dist3[found], idx3[found]
    dist, idx = dist3[:, 0], idx3[:, 0]
    offset = nodes[near_nodes] - samples[idx]
    along = np.einsum("ij,ij->i", offset, normals[idx])
    # Exact distance to the triangles the nearest samples lie on (the closest triangle or
    # its neighbours).
    # The minimum over the triangles of the three nearest samples.
    triangles = np.asarray(mesh.triangles)
    exact = dist.copy()
    for j in range(3):
        ok = np.isfinite(dist3[:, j])
        tri = triangles[faces[np.where(ok, idx3[:, j], 0)]]
        d_j = point_triangle_distance(nodes[near_nodes], tri[:, 0], tri[:, 1], tri[:, 2])
        exact = np.where(ok, np.minimum(exact, d_j), exact)
    sign_plane = np.where(along < 0.0, -1.0, 1.0)
    # Beside a face's edge the nearest sample's plane says nothing (along ~ 0): take the
    # side of the neighbouring sample the node lies most squarely over.
    ambiguous = np.flatnonzero(np.abs(along) < 0.5 * dist)
    if ambiguous.size:
        pts = nodes[near_nodes[ambiguous]]
        d_k, i_k = tree.query(pts, k=16, workers=-1)
        al_k = np.einsum("ikj,ikj->ik", pts[:, None, :] - samples[i_k], normals[i_k])
        best = np.argmax(np.abs(al_k) / np.maximum(d_k, 1e-12), axis=1)
        sign_plane[ambiguous] = np.where(al_k[np.arange(len(best)), best] < 0.0, -1.0, 1.0)
    sign_fill = np.sign(values[near_nodes])
    # Trust the tangent-plane side close to the surface, the fill farther out.
    sign = np.where(dist < 2.0 * spacing, sign_plane, np.where(sign_fill == 0, sign_plane, sign_fill))
    values[near_nodes] = sign * exact
    grid = values.reshape(shape)
    grid.flags.writeable = False
    origin = lo.copy()
    origin.flags.writeable = False
    return SignedDistanceGrid(origin=origin, spacing=spacing, values=grid)


def cached_sdf_grid(mesh: trimesh.Trimesh, key: str, **kwargs) -> SignedDistanceGrid:
    """:func:`build_sdf_grid` memoised by ``key`` (the mesh hash) and the options, in the
    named cache ``"sdf_grid"`` (:mod:`grasp_apso.cache`, bounded in entries and bytes), and
    on disk (:func:`grasp_apso.cache.disk_arrays`, folder ``sdf_grids``, bounded in bytes):
    the file's name is a digest of the key, the mesh's vertices and faces, the options,
    :data:`SDF_GRID_VERSION` and the versions of numpy, scipy and trimesh (which sample the
    surface and find the nearest samples), so a changed mesh, option or library never reads
    a stale grid."""
    cache_key = (key, tuple(sorted(kwargs.items())))
    return cached("sdf_grid", cache_key, lambda: _grid_from_disk(mesh, key, kwargs))


def _grid_from_disk(mesh: trimesh.Trimesh, key: str, kwargs: dict) -> SignedDistanceGrid:
    """The grid of ``mesh`` with ``kwargs`` read from the disk cache, or built and kept there."""
    digest = hashlib.sha256(
        f"v{SDF_GRID_VERSION};{key};{sorted(kwargs.items())!r};numpy {np.__version__};scipy {scipy.__version__};"
        f"trimesh {trimesh.__version__}".encode())
    # The mesh's own arrays too (a millisecond against the build's tenths of a second): a
    # caller's key that is not the mesh's content can never read another mesh's grid.
    digest.update(np.ascontiguousarray(mesh.vertices, dtype="<f8").tobytes())
    digest.update(np.ascontiguousarray(mesh.faces, dtype="<i8").tobytes())

    def build() -> dict[str, np.ndarray]:
        grid = build_sdf_grid(mesh, **kwargs)
        return {"origin": grid.origin, "spacing": np.array([grid.spacing]), "values": grid.values}

    def check(arrays) -> bool:
        values = arrays.get("values")
        return (values is not None and values.ndim == 3 and min(values.shape) >= 2
                and np.shape(arrays.get("origin")) == (3,) and np.shape(arrays.get("spacing")) == (1,)
                and float(arrays["spacing"][0]) > 0 and bool(np.isfinite(values).all()))

    arrays = disk_arrays("sdf_grids", digest.hexdigest(), build, check)
    values = np.ascontiguousarray(arrays["values"], dtype=np.float64)
    origin = np.ascontiguousarray(arrays["origin"], dtype=np.float64)
    values.flags.writeable = False
    origin.flags.writeable = False
    return SignedDistanceGrid(origin=origin, spacing=float(arrays["spacing"][0]), values=values)
