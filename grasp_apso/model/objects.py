"""Objects to grasp: a validated mesh and what the planner derives from it.

An object is a triangle mesh in its own frame (the *object frame*), in metres. It is
validated once, at the edge, and then held in an immutable :class:`GraspObject`
together with the derived data the planner needs (centre of mass, extents, principal
axes, convex hull, a torque scale and a stable hash for caching).

Where objects come from (one module each, no re-exports):

- :func:`from_arrays` (here) -- vertices and triangles, e.g. from a ``shape_msgs/Mesh``;
  the raw arrays are checked by :mod:`grasp_apso.model.mesh_checks`.
- :func:`grasp_apso.model.mesh_files.from_file` -- an STL / OBJ / PLY / OFF file given as
  a path or ``file://`` URI, optionally confined to an allowed directory.
- :func:`grasp_apso.model.builtin.builtin` -- the paper's four test objects.

Every invalid object raises :class:`~grasp_apso.errors.ObjectError` (a ``ValueError``)
whose message starts with the offending request field (``mesh:``, ``mesh_uri:``,
``object_name:``, ``object_pose:``), e.g. ``"mesh: triangle 3 index 99 out of range (8 vertices)"``.

Decisions
---------
- Uniform density. When the mesh is a closed, consistently oriented solid
  (``watertight``), the centre of mass is the mesh's volume centroid; otherwise it is the
  centroid of the mesh's convex hull.
- Holes (scans): a mesh that is not closed has its holes closed when the caps add at
  most :data:`~grasp_apso.model.mesh_checks.MAX_HOLE_AREA` (45 %) of its area
  (``trimesh.repair.fill_holes`` for triangles and quads, a fan around the rim's centroid
  for larger simple rims), so that the signed-distance grid knows inside from outside
  and every contact carries the outward normal; ``mesh_hash`` is that of the closed
  mesh. A mesh with larger holes (a half shell) is refused, saying why; one whose holes'
  rims touch themselves (non-manifold edges) stays open, wound consistently and outward
  (the side where the mesh closed by its caps has a positive volume).
- Winding repair of closed meshes is trimesh's (``trimesh.repair.fix_normals`` with
  ``multibody=True``, which needs networkx): each closed piece is made consistently
  wound with positive volume (nested shells, i.e. hollow solids, are not supported:
  their inner shell also ends up outward).
- ``principal_extents`` / ``principal_axes`` come from the smallest of three bounding
  boxes: axis-aligned, trimesh's oriented box (``trimesh.bounds.oriented_bounds``, a
  heuristic) and the principal-component box. Note that in trimesh 5.2
  ``mesh.bounding_box_oriented.extents`` is the axis-aligned size of the *rotated* box
  mesh; the box sizes are ``mesh.bounding_box_oriented.primitive.extents``.
- A mesh is *flat* when its oriented bounding box is 1 mm thick or less
  (:data:`MIN_THICKNESS`): nothing a fingertip can pinch.
- The ``mesh`` attribute's vertex and face arrays are made read-only. trimesh methods
  that replace the arrays (``apply_transform`` ...) would still change it: do not call
  them on ``GraspObject.mesh``; use ``obj.mesh.copy()`` to get a mesh to modify.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Any

import numpy as np
import trimesh

from ..errors import ObjectError
from .mesh_checks import (
    DEFAULT_MAX_TRIANGLES,
    MIN_THICKNESS,
    check_encloses_volume,
    check_holes,
    check_limit,
    check_one_body,
    check_raw_mesh,
    convex_hull,
    flat_error,
    process_mesh,
)

__all__ = ["GraspObject", "from_arrays", "MESH_FORMATS"]

#: File extensions accepted by :func:`from_file` (lower case, no dot).
MESH_FORMATS: tuple[str, ...] = ("stl", "obj", "ply", "off")

#: Hull vertices above which the oriented-box orientation is searched on a subset of
#: ``_OBB_SUBSET`` of them (trimesh's search costs about 0.16 s for 2,000 points, 0.04 s
#: for 500; the box is then measured on all of them).
_OBB_MAX_POINTS: int = 2000
_OBB_SUBSET: int = 500




# --------------------------------------------------------------------------------------
# GraspObject
# --------------------------------------------------------------------------------------


def _readonly(array: Any, shape: tuple[int | None, ...], field: str) -> np.ndarray:
    """Return a read-only float64 copy of ``array``, checking its shape.

    Parameters
    ----------
    array : array_like
        Values to copy.
    shape : tuple of int or None
        Expected shape; ``None`` matches any size along that axis.
    field : str
        Field name for the error message.

    Returns
    -------
    np.ndarray
        Read-only float64 copy.
    """
    out = np.array(array, dtype=np.float64, copy=True)
    ok = out.ndim == len(shape) and all(
        want is None or want == got for want, got in zip(shape, out.shape)
    )
    if not ok:
        raise ObjectError(f"{field}: expected shape {shape}, got {out.shape}")
    out.flags.writeable = False
    return out


@dataclass(frozen=True, eq=False, repr=False)
class GraspObject:
    """A validated object to grasp, in its own frame (metres).

    Build it with :func:`from_arrays`, :func:`from_file` or :func:`builtin` (also
    available as classmethods of the same names); the constructors validate the mesh and
    compute the derived fields. Instances are immutable, hashable and compare equal
    when their name and mesh hash are equal.

    Attributes
    ----------
    name : str
        Object name (built-in name, file stem, or the caller's name).
    mesh : trimesh.Trimesh
        The processed mesh in the object frame, metres: merged vertices, no degenerate or
        duplicate faces, consistent outward winding when ``watertight``. Its vertex and
        face arrays are read-only; do not modify it (use ``mesh.copy()``).
    center_of_mass : (3,) float, m
        Centre of mass for uniform density: from the mesh volume when ``watertight``,
        else from its convex hull.
    watertight : bool
        True when the mesh is closed, consistently oriented and has positive volume.
    extents : (3,) float, m
        Size of the axis-aligned bounding box along the object x, y, z axes.
    principal_extents : (3,) float, m
        Sizes of the (near) minimum-volume oriented bounding box, sorted descending.
    principal_axes : (3, 3) float
        Rows are the unit axes (object frame) of the oriented bounding box, matching
        ``principal_extents``; a right-handed rotation (determinant +1).
    hull_vertices : (H, 3) float, m
        Vertices of the convex hull of the mesh (for support-function queries).
    characteristic_radius : float, m
        Largest distance from ``center_of_mass`` to a hull vertex; the torque scale of
        the wrench quality.
    mesh_hash : str
        SHA-256 hex digest of the processed vertices and faces; stable across runs, used
        as a key to cache derived data (signed distance grids ...).
    """

    name: str
    mesh: trimesh.Trimesh
    center_of_mass: np.ndarray
    watertight: bool
    extents: np.ndarray
    principal_extents: np.ndarray
    principal_axes: np.ndarray
    hull_vertices: np.ndarray
    characteristic_radius: float
    mesh_hash: str

    def __post_init__(self) -> None:
        """Copy the array fields to read-only float64 arrays and check their shapes."""
        if not isinstance(self.name, str):
            raise ObjectError(f"name: expected a string, got {type(self.name).__name__}")
        if not isinstance(self.mesh, trimesh.Trimesh):
            raise ObjectError(f"mesh: expected a trimesh.Trimesh, got {type(self.mesh).__name__}")
        shapes: dict[str, tuple[int | None, ...]] = {
            "center_of_mass": (3,),
            "extents": (3,),
            "principal_extents": (3,),
            "principal_axes": (3, 3),
            "hull_vertices": (None, 3),
        }
        for field, shape in shapes.items():
            object.__setattr__(self, field, _readonly(getattr(self, field), shape, field))
        object.__setattr__(self, "watertight", bool(self.watertight))
        object.__setattr__(self, "characteristic_radius", float(self.characteristic_radius))

    # Equality and hashing by content, not by the (unhashable) arrays.
    def __eq__(self, other: object) -> bool:
        if not isinstance(other, GraspObject):
            return NotImplemented
        return self.name == other.name and self.mesh_hash == other.mesh_hash

    def __hash__(self) -> int:
        return hash((self.name, self.mesh_hash))

    def __repr__(self) -> str:
        ext = ", ".join(f"{e:.4f}" for e in self.extents)
        return (
            f"GraspObject(name={self.name!r}, vertices={len(self.mesh.vertices)}, "
            f"triangles={len(self.mesh.faces)}, extents=({ext}) m, "
            f"watertight={self.watertight}, mesh_hash={self.mesh_hash[:12]}...)"
        )

    @property
    def volume(self) -> float:
        """Volume (m^3) of the mesh when ``watertight``, else of its convex hull."""
        if self.watertight:
            return float(self.mesh.volume)
        return float(self.mesh.convex_hull.volume)



# --------------------------------------------------------------------------------------
# Validation of raw arrays
def _box_along(points: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """Sizes (m) of ``points`` (N, 3) along the unit row vectors of ``axes`` (3, 3)."""
    return np.ptp(points @ axes.T, axis=0)


def _oriented_box_axes(mesh: trimesh.Trimesh, hull_points: np.ndarray) -> np.ndarray | None:
    """Axes of trimesh's oriented bounding box (``trimesh.bounds.oriented_bounds``).

    Its cost grows with the hull size (about 5 s for a 100,000-vertex hull), so for
    hulls of more than :data:`_OBB_MAX_POINTS` vertices the orientation is searched on
    an evenly strided subset of :data:`_OBB_SUBSET` of them; the caller measures the box
    on all of them.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The object mesh, m (its cached convex hull is reused).
    hull_points : (H, 3) float, m
        Vertices of its convex hull.

    Returns
    -------
    (3, 3) float or None
        Rows are unit box axes; None when trimesh cannot compute the box.
    """
    try:
        if len(hull_points) <= _OBB_MAX_POINTS:
            to_origin, _ = trimesh.bounds.oriented_bounds(mesh)
        else:
            subset = np.linspace(0, len(hull_points) - 1, _OBB_SUBSET).astype(np.int64)
            to_origin, _ = trimesh.bounds.oriented_bounds(hull_points[subset])
    except Exception:  # qhull / coplanar-subset failures: fall back to other candidates
        return None
    return np.asarray(to_origin, dtype=np.float64)[:3, :3]


def _principal_box(mesh: trimesh.Trimesh, hull: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    """Smallest-volume bounding box among candidate orientations.

    Candidates: the object axes (axis-aligned box), trimesh's oriented bounding box
    (see :func:`_oriented_box_axes`) and the principal component axes of the hull
    vertices. The sizes along each candidate are measured on all hull vertices; the
    smallest box wins, the earlier candidate on ties within 1e-9 relative.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The object mesh, m (its cached convex hull is reused).
    hull : trimesh.Trimesh
        Its convex hull, m.

    Returns
    -------
    extents : (3,) float, m
        Box sizes, sorted descending.
    axes : (3, 3) float
        Rows are the unit box axes in the object frame, matching ``extents``;
        right-handed.
    """
    points = np.asarray(hull.vertices, dtype=np.float64)
    centred = points - points.mean(axis=0)
    candidates = [np.eye(3), np.linalg.svd(centred, full_matrices=False)[2]]
    obb_axes = _oriented_box_axes(mesh, points)
    if obb_axes is not None:
        candidates.insert(1, obb_axes)
    sizes = [_box_along(points, axes) for axes in candidates]
    volumes = np.array([np.prod(size) for size in sizes])
    best = int(np.flatnonzero(volumes <= volumes.min() * (1.0 + 1e-9))[0])
    order = np.argsort(-sizes[best], kind="stable")
    axes = candidates[best][order].copy()
    if np.linalg.det(axes) < 0.0:
        axes[2] *= -1.0
    return sizes[best][order], axes


def _mesh_hash(mesh: trimesh.Trimesh) -> str:
    """SHA-256 hex digest of a mesh's vertices (float64) and faces (int64), little-endian."""
    verts = np.ascontiguousarray(mesh.vertices, dtype="<f8")
    faces = np.ascontiguousarray(mesh.faces, dtype="<i8")
    digest = hashlib.sha256(b"grasp_apso.mesh.v1")
    digest.update(np.array(verts.shape + faces.shape, dtype="<i8").tobytes())
    digest.update(verts.tobytes())
    digest.update(faces.tobytes())
    return digest.hexdigest()


def _freeze_mesh(mesh: trimesh.Trimesh) -> None:
    """Make the mesh's vertex and face arrays read-only (in place)."""
    mesh.vertices.flags.writeable = False
    mesh.faces.flags.writeable = False


def from_arrays(
    vertices: Any,
    triangles: Any,
    name: str = "mesh",
    max_triangles: int = DEFAULT_MAX_TRIANGLES,
) -> GraspObject:
    """Validate a triangle mesh and build a :class:`GraspObject`.

    Parameters
    ----------
    vertices : array_like, (V, 3) float, m
        Vertex positions in the object frame.
    triangles : array_like, (T, 3) int
        Vertex indices of each triangle (floats holding whole numbers are accepted).
    name : str
        Object name.
    max_triangles : int
        Largest accepted T (V may be at most ``3 * max_triangles``).

    Returns
    -------
    GraspObject

    Raises
    ------
    ObjectError
        Empty mesh, wrong shapes, NaN/inf vertices, indices not integer or out of range,
        too many triangles, all triangles of zero area, or a mesh 1 mm thick or less.

    Notes
    -----
    The mesh is built with ``trimesh.Trimesh(process=True)`` (duplicate vertices merged),
    zero-area and duplicate triangles and unreferenced vertices are removed, small holes
    are closed, and when the mesh is closed its faces are re-wound consistently with
    outward normals.
    """
    if not isinstance(name, str):
        raise ObjectError(f"name: expected a string, got {type(name).__name__}")
    limit = check_limit(max_triangles)
    verts, tris = check_raw_mesh(vertices, triangles, limit)
    mesh, watertight = process_mesh(verts, tris)
    hull = convex_hull(mesh)
    check_encloses_volume(mesh, hull, watertight)
    check_holes(mesh, watertight)
    check_one_body(mesh)
    principal_extents, principal_axes = _principal_box(mesh, hull)
    if principal_extents[-1] <= MIN_THICKNESS:
        raise flat_error(float(principal_extents[-1]))
    com = mesh.center_mass if watertight else hull.center_mass
    hull_vertices = np.asarray(hull.vertices, dtype=np.float64)
    radius = float(np.max(np.linalg.norm(hull_vertices - com, axis=1)))
    _freeze_mesh(mesh)
    return GraspObject(
        name=name,
        mesh=mesh,
        center_of_mass=com,
        watertight=watertight,
        extents=mesh.extents,
        principal_extents=principal_extents,
        principal_axes=principal_axes,
        hull_vertices=hull_vertices,
        characteristic_radius=radius,
        mesh_hash=_mesh_hash(mesh),
    )
