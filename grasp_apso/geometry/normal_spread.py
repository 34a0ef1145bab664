"""How well defined the surface normal is around each point of the surface: a grid, built
once per mesh, read by trilinear interpolation on the optimiser's hot path.

A fingertip on an edge, a corner or a rim rests on an ill-defined normal: the force it
can exert may point anywhere in the fan of the adjacent faces' normals, and such grasps
slip in simulation (issue 13, part 6). :func:`grasp_apso.quality.robustness.normal_uncertainty`
measures this exactly for a few final contacts; the swarm needs it for every contact
of every particle, so this module samples the same quantity, the *normal spread*, on
the nodes of the object's signed-distance grid near the surface:

1. area-weighted surface samples (seeded) with their face normals, in a KD-tree;
2. for every grid node within :data:`BAND_CELLS` cells of the surface, its closest
   surface point ``q = node - d * grad d`` (from the signed-distance grid);
3. the samples within ``radius`` of ``q`` (at most :data:`NEIGHBOURS`, the nearest),
   left out when their normal is more than 120 degrees from ``grad d`` (the far side of
   a thin wall); the samples are area-weighted, so with ``m`` their normalised mean
   normal the spread is the RMS angle to ``m`` over the ``J`` samples::

       u = sqrt( sum_j angle(n_j, m)^2 / J )      (rad)

   as :func:`~grasp_apso.quality.robustness.normal_uncertainty` (0 on a flat face, up
   to 45 degrees on a box edge and 55 degrees at a box corner, at most 8 degrees on the
   built-in sphere's 1,280-face tessellation; on the project's meshes about 0.8 times
   ``normal_uncertainty``, whose whole-triangle weights reach a little farther);
4. nodes farther from the surface hold 0 (a contact point lies on the surface, and its
   eight interpolation nodes are within sqrt(3) cells of it).

The grid has the signed-distance grid's lattice (same origin, spacing and shape), so a
contact's spread is one more trilinear look-up (:func:`grasp_apso.geometry.kernels.grid_values`).
Cached by mesh hash with the distance grid's options. Frames and units: object frame, m;
spreads in rad.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from ..cache import cached
from . import kernels
from .sdf import SignedDistanceGrid

__all__ = ["NormalSpreadGrid", "build_normal_spread_grid", "cached_normal_spread_grid",
           "DEFAULT_RADIUS", "NEIGHBOURS", "BAND_CELLS", "SAMPLE_DENSITY"]

#: Neighbourhood radius (m), as :data:`grasp_apso.quality.robustness.DEFAULT_RADIUS`.
DEFAULT_RADIUS = 0.004
#: At most this many surface samples (the nearest) per neighbourhood.
NEIGHBOURS = 16
#: Nodes within this many cells of the surface get a spread (the rest 0).
BAND_CELLS = 1.8
#: Surface samples per m^2 (about 16 in a 4 mm disc), clipped to [4,000, 120,000].
SAMPLE_DENSITY = 3.2e5
#: Samples whose normal is more than 120 degrees from the node's gradient are the far
#: side of a thin wall (as ``robustness.BACK_FACE_COS``).
BACK_FACE_COS = -0.5


@dataclass(frozen=True)
class NormalSpreadGrid:
    """Normal spread (rad) on the nodes of a signed-distance grid's lattice (immutable).

    Attributes
    ----------
    origin : (3,) float, m
        Position of node (0, 0, 0) in the object frame.
    spacing : float, m
        Node spacing.
    values : (nx, ny, nz) float, rad
        Spread of the surface normals around each node's closest surface point (0 far
        from the surface).
    """

    origin: np.ndarray
    spacing: float
    values: np.ndarray

    @cached_property
    def _values64(self) -> np.ndarray:
        return np.ascontiguousarray(self.values, dtype=np.float64)

    @cached_property
    def _origin64(self) -> np.ndarray:
        return np.ascontiguousarray(self.origin, dtype=np.float64)

    def spread(self, points: np.ndarray) -> np.ndarray:
        """Normal spread at surface points (trilinear; clamped to the grid box).

        points : (..., 3) float, m, object frame -> (...,) float, rad
        """
        points = np.asarray(points, dtype=np.float64)
        if points.shape[-1:] != (3,):
            raise ValueError(f"points: expected (..., 3), got {points.shape}")
        flat = np.ascontiguousarray(points).reshape(-1, 3)
        out = np.empty(len(flat))
        kernels.grid_values(self._values64, self._origin64, float(self.spacing), flat, out)
        return out.reshape(points.shape[:-1])


def build_normal_spread_grid(mesh: trimesh.Trimesh, sdf: SignedDistanceGrid, radius: float = DEFAULT_RADIUS,
                             seed: int = 0) -> NormalSpreadGrid:
    """Sample the normal spread of ``mesh`` on the lattice of ``sdf`` (see the module).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Object surface, object frame, m (outward normals).
    sdf : SignedDistanceGrid
        Its signed-distance grid (gives the lattice and the closest surface points).
    radius : float, m
        Neighbourhood radius, > 0.
    seed : int
        Seed of the surface sampling (the grid is deterministic).

    Returns
    -------
    NormalSpreadGrid
    """
    if not radius > 0.0:
        raise ValueError(f"radius: expected a positive length in m, got {radius!r}")
    values = np.zeros(sdf.values.shape)
    near = np.flatnonzero(np.abs(sdf.values.reshape(-1)) <= BAND_CELLS * sdf.spacing)
    if near.size:
        idx = np.stack(np.unravel_index(near, sdf.values.shape), axis=1)
        nodes = sdf.origin + sdf.spacing * idx
        dist, grad = sdf.distance_and_gradient(nodes)
        surface = nodes - dist[:, None] * grad
        count = int(np.clip(SAMPLE_DENSITY * mesh.area, 4_000, 120_000))
        samples, faces = trimesh.sample.sample_surface(mesh, count, seed=seed)
        normals = np.ascontiguousarray(np.asarray(mesh.face_normals)[faces], dtype=np.float64)
        tree = cKDTree(samples)
        d_k, i_k = tree.query(surface, k=NEIGHBOURS, distance_upper_bound=radius, workers=-1)
        spread = np.empty(len(near))
        kernels.normal_spreads(np.ascontiguousarray(d_k), np.ascontiguousarray(i_k, dtype=np.int64), normals,
                               np.ascontiguousarray(grad), float(radius), BACK_FACE_COS, spread)
        values.reshape(-1)[near] = spread
    values.flags.writeable = False
    origin = np.array(sdf.origin, dtype=np.float64)
    origin.flags.writeable = False
    return NormalSpreadGrid(origin=origin, spacing=float(sdf.spacing), values=values)


def cached_normal_spread_grid(mesh: trimesh.Trimesh, sdf: SignedDistanceGrid, key: str,
                              radius: float = DEFAULT_RADIUS, **sdf_kwargs) -> NormalSpreadGrid:
    """:func:`build_normal_spread_grid` memoised by ``key`` (the mesh hash), the options
    ``sdf_kwargs`` ``sdf`` was built with, and ``radius``, in the named cache
    ``"normal_spread"`` (:mod:`grasp_apso.cache`)."""
    cache_key = (key, tuple(sorted(sdf_kwargs.items())), float(radius))
    return cached("normal_spread", cache_key, lambda: build_normal_spread_grid(mesh, sdf, radius))
