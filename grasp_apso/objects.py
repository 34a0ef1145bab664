"""Objects to grasp: validated meshes, built-in objects, mesh files and poses.

An object is a triangle mesh in its own frame (the *object frame*), in metres. It is
validated once, at the edge, and then held in an immutable :class:`GraspObject`
together with the derived data the planner needs (centre of mass, extents, principal
axes, convex hull, a torque scale and a stable hash for caching).

Constructors (module functions; the same functions are also available as
``GraspObject.from_arrays``, ``GraspObject.from_file`` and ``GraspObject.builtin``):

- :func:`from_arrays` -- vertices and triangles, e.g. from a ``shape_msgs/Mesh``.
- :func:`from_file` -- an STL / OBJ / PLY / OFF file given as a path or ``file://`` URI,
  optionally confined to an allowed directory.
- :func:`builtin` -- the paper's four test objects, :data:`BUILTIN_OBJECTS`.

Every invalid object raises :class:`ObjectError` (a ``ValueError``) whose message starts
with the offending request field (``mesh:``, ``mesh_uri:``, ``object_name:``,
``object_pose:``), for example ``"mesh: triangle 3 index 99 out of range (8 vertices)"``.

Pose utilities (:func:`pose_to_matrix`, :func:`matrix_to_pose`, :func:`transform_points`,
:func:`transform_vectors`) convert between ``geometry_msgs/Pose``-like position +
quaternion (x, y, z, w) and 4x4 homogeneous transforms. The planner works in the object
frame; the object pose (object -> planning frame) is applied to the results only.

Decisions
---------
- Uniform density. When the mesh is a closed, consistently oriented solid
  (``watertight``), the centre of mass is the mesh's volume centroid; otherwise it is the
  centroid of the mesh's convex hull.
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

import functools
import hashlib
import io
import os
import re
import urllib.parse
from dataclasses import dataclass
from typing import Any, Union

import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial.transform import Rotation

__all__ = [
    "BUILTIN_OBJECTS",
    "MESH_FORMATS",
    "MIN_THICKNESS",
    "ObjectError",
    "GraspObject",
    "from_arrays",
    "from_file",
    "builtin",
    "pose_to_matrix",
    "matrix_to_pose",
    "transform_points",
    "transform_vectors",
]

#: Names accepted by :func:`builtin`.
BUILTIN_OBJECTS: tuple[str, ...] = ("sphere", "cube", "barrel", "fish")

#: File extensions accepted by :func:`from_file` (lower case, no dot).
MESH_FORMATS: tuple[str, ...] = ("stl", "obj", "ply", "off")

#: Minimum thickness (m) of an object along its thinnest oriented-bounding-box axis.
MIN_THICKNESS: float = 1e-3

#: Default limits for meshes and mesh files.
DEFAULT_MAX_TRIANGLES: int = 200_000
DEFAULT_MAX_BYTES: int = 50_000_000

#: Triangles with an area at or below this (m^2) count as zero-area.
_ZERO_AREA: float = 1e-14

#: Hull vertices above which the oriented-box orientation is searched on a subset.
_OBB_MAX_POINTS: int = 2000

#: Tolerance on the quaternion norm: |norm - 1| above this is rejected, not normalised.
QUATERNION_NORM_TOLERANCE: float = 1e-3

_URI_SCHEME = re.compile(r"^([A-Za-z][A-Za-z0-9+.\-]*)://")

PathLike = Union[str, "os.PathLike[str]"]


class ObjectError(ValueError):
    """An invalid object: bad mesh, mesh file, object name or object pose.

    The message starts with the request field at fault (``mesh``, ``mesh_uri``,
    ``object_name``, ``object_pose``) and names the problem.
    """


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

    # Classmethod aliases of the module constructors.
    @classmethod
    def from_arrays(cls, *args: Any, **kwargs: Any) -> "GraspObject":
        """Alias of :func:`grasp_apso.objects.from_arrays`."""
        return from_arrays(*args, **kwargs)

    @classmethod
    def from_file(cls, *args: Any, **kwargs: Any) -> "GraspObject":
        """Alias of :func:`grasp_apso.objects.from_file`."""
        return from_file(*args, **kwargs)

    @classmethod
    def builtin(cls, name: str) -> "GraspObject":
        """Alias of :func:`grasp_apso.objects.builtin`."""
        return builtin(name)


# --------------------------------------------------------------------------------------
# Validation of raw arrays
# --------------------------------------------------------------------------------------


def _check_limit(max_triangles: int) -> int:
    """Validate the ``max_triangles`` argument and return it as an int."""
    if isinstance(max_triangles, bool) or not isinstance(max_triangles, (int, np.integer)):
        raise ValueError(f"max_triangles: expected an integer, got {max_triangles!r}")
    if max_triangles < 1:
        raise ValueError(f"max_triangles: must be positive, got {max_triangles}")
    return int(max_triangles)


def _as_vertices(vertices: Any) -> np.ndarray:
    """Convert ``vertices`` to a (V, 3) float64 array or raise ObjectError.

    Parameters
    ----------
    vertices : array_like, (V, 3), m

    Returns
    -------
    (V, 3) float64 np.ndarray, m
    """
    try:
        raw = np.asarray(vertices)
    except (TypeError, ValueError) as exc:
        raise ObjectError(f"mesh: vertices are not a numeric array ({exc})") from None
    if raw.size == 0:
        raise ObjectError("mesh: empty (no vertices)")
    if raw.dtype.kind not in "iuf":
        raise ObjectError(f"mesh: vertices must be real numbers, got dtype {raw.dtype}")
    if raw.ndim != 2 or raw.shape[1] != 3:
        raise ObjectError(f"mesh: vertices must have shape (V, 3), got {raw.shape}")
    verts = raw.astype(np.float64)
    bad = ~np.isfinite(verts).all(axis=1)
    if bad.any():
        index = int(np.flatnonzero(bad)[0])
        what = "NaN" if np.isnan(verts[index]).any() else "infinite"
        raise ObjectError(f"mesh: vertex {index} is {what}")
    return verts


def _to_index_array(triangles: Any) -> np.ndarray:
    """``np.asarray(triangles)`` or ObjectError when it is not a regular array."""
    try:
        return np.asarray(triangles)
    except (TypeError, ValueError) as exc:
        raise ObjectError(f"mesh: triangles are not an integer array ({exc})") from None


def _as_triangles(raw: np.ndarray, n_vertices: int) -> np.ndarray:
    """Check a triangle index array and return it as (T, 3) int64, or raise ObjectError.

    Parameters
    ----------
    raw : np.ndarray, (T, 3), int (floats holding whole numbers accepted)
        Vertex indices of each triangle.
    n_vertices : int
        Number of vertices V; indices must be in [0, V).

    Returns
    -------
    (T, 3) int64 np.ndarray
    """
    if raw.size == 0:
        raise ObjectError("mesh: empty (no triangles)")
    if raw.ndim != 2 or raw.shape[1] != 3:
        raise ObjectError(f"mesh: triangles must have shape (T, 3), got {raw.shape}")
    if raw.dtype.kind == "f":
        not_int = ~np.isfinite(raw) | (raw != np.round(raw))
        if not_int.any():
            tri, col = np.argwhere(not_int)[0]
            raise ObjectError(f"mesh: triangle {tri} index {raw[tri, col]} is not an integer")
    elif raw.dtype.kind not in "iu":
        raise ObjectError(f"mesh: triangles must be integer indices, got dtype {raw.dtype}")
    out_of_range = (raw < 0) | (raw >= n_vertices)
    if out_of_range.any():
        tri, col = np.argwhere(out_of_range)[0]
        index = raw[tri, col]
        index_text = str(int(index)) if raw.dtype.kind in "iu" else f"{index:g}"
        raise ObjectError(
            f"mesh: triangle {tri} index {index_text} out of range ({n_vertices} vertices)"
        )
    return raw.astype(np.int64)


def _triangle_areas(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Areas of the triangles.

    Parameters
    ----------
    vertices : (V, 3) float, m
    triangles : (T, 3) int

    Returns
    -------
    (T,) float, m^2
    """
    corners = vertices[triangles]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    return 0.5 * np.linalg.norm(cross, axis=1)


def _pca_thickness(points: np.ndarray) -> float:
    """Size (m) of ``points`` (N, 3) along their direction of least variance."""
    centred = points - points.mean(axis=0)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    thinnest = vt[-1]
    return float(np.ptp(centred @ thinnest))


def _flat_error(thickness: float) -> ObjectError:
    """The error for a mesh thinner than :data:`MIN_THICKNESS`."""
    return ObjectError(
        f"mesh: flat (thickness {round(thickness, 6)} m along its thinnest axis, "
        f"minimum {MIN_THICKNESS} m)"
    )


def _check_raw_mesh(
    vertices: Any, triangles: Any, max_triangles: int
) -> tuple[np.ndarray, np.ndarray]:
    """Validate raw mesh arrays: emptiness, shapes, finiteness, indices, size, area, flatness.

    Parameters
    ----------
    vertices : array_like, (V, 3), m
    triangles : array_like, (T, 3), int
    max_triangles : int
        Largest accepted T; V may be at most ``3 * max_triangles``.

    Returns
    -------
    vertices : (V, 3) float64, m
    triangles : (T', 3) int64
        The triangles with non-zero area.
    """
    verts = _as_vertices(vertices)
    raw_tris = _to_index_array(triangles)
    n_tri = raw_tris.shape[0] if raw_tris.ndim >= 1 else 0
    if n_tri > max_triangles:
        raise ObjectError(f"mesh: {n_tri} triangles exceeds the limit of {max_triangles}")
    if len(verts) > 3 * max_triangles:
        raise ObjectError(
            f"mesh: {len(verts)} vertices exceeds the limit of {3 * max_triangles}"
        )
    tris = _as_triangles(raw_tris, len(verts))
    areas = _triangle_areas(verts, tris)
    keep = areas > _ZERO_AREA
    if not keep.any():
        raise ObjectError("mesh: degenerate (all triangles have zero area)")
    tris = tris[keep]
    thickness = _pca_thickness(verts[np.unique(tris)])
    if thickness <= MIN_THICKNESS:
        raise _flat_error(thickness)
    return verts, tris


# --------------------------------------------------------------------------------------
# Orientation (winding) repair, without networkx
# --------------------------------------------------------------------------------------


def _consistent_flips(
    faces: np.ndarray, adjacency: np.ndarray, shared_edges: np.ndarray
) -> np.ndarray | None:
    """Which faces to flip so that all adjacent faces have consistent winding.

    Two faces sharing an edge are consistent when they traverse it in opposite
    directions. Each face gets two states (kept, flipped); a graph on the 2F states links
    compatible states, and its connected components give the flips. The first face of
    each connected piece keeps its winding.

    Parameters
    ----------
    faces : (F, 3) int
    adjacency : (A, 2) int
        Pairs of faces sharing an edge (``mesh.face_adjacency``).
    shared_edges : (A, 2) int
        The shared edge (vertex pair) of each pair (``mesh.face_adjacency_edges``).

    Returns
    -------
    (F,) bool or None
        Faces to flip, or None when the surface is not orientable.
    """
    n_faces = len(faces)
    if len(adjacency) == 0:
        return np.zeros(n_faces, dtype=bool)
    u, v = shared_edges[:, 0], shared_edges[:, 1]

    def has_forward_edge(face_ids: np.ndarray) -> np.ndarray:
        f = faces[face_ids]
        nxt = np.roll(f, -1, axis=1)
        return ((f == u[:, None]) & (nxt == v[:, None])).any(axis=1)

    a, b = adjacency[:, 0], adjacency[:, 1]
    inconsistent = has_forward_edge(a) == has_forward_edge(b)
    b_state = b + n_faces * inconsistent
    b_other = b + n_faces * ~inconsistent
    rows = np.concatenate([a, a + n_faces])
    cols = np.concatenate([b_state, b_other])
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(2 * n_faces, 2 * n_faces))
    _, labels = connected_components(graph, directed=False)
    if np.any(labels[:n_faces] == labels[n_faces:]):
        return None
    plain = coo_matrix((np.ones(len(a)), (a, b)), shape=(n_faces, n_faces))
    _, pieces = connected_components(plain, directed=False)
    first_face = np.full(pieces.max() + 1, n_faces, dtype=np.int64)
    np.minimum.at(first_face, pieces, np.arange(n_faces))
    return labels[:n_faces] != labels[first_face[pieces]]


def _signed_volumes(vertices: np.ndarray, faces: np.ndarray, pieces: np.ndarray) -> np.ndarray:
    """Signed volume (m^3) of each connected piece of a closed mesh.

    Parameters
    ----------
    vertices : (V, 3) float, m
    faces : (F, 3) int
    pieces : (F,) int
        Piece label of each face, 0..P-1.

    Returns
    -------
    (P,) float, m^3
    """
    c = vertices[faces]
    per_face = np.einsum("ij,ij->i", c[:, 0], np.cross(c[:, 1], c[:, 2])) / 6.0
    return np.bincount(pieces, weights=per_face)


def _orient_outward(mesh: trimesh.Trimesh) -> bool:
    """Make a closed mesh's winding consistent with outward normals, in place.

    Each connected piece is oriented to have positive volume (nested shells, i.e.
    hollow solids, are not supported: their inner shell also ends up outward).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        A watertight mesh (every edge shared by exactly two faces).

    Returns
    -------
    bool
        True when the mesh is now a consistently oriented solid of positive volume.
    """
    faces = np.array(mesh.faces, dtype=np.int64)
    flips = _consistent_flips(faces, mesh.face_adjacency, mesh.face_adjacency_edges)
    if flips is None:
        return False
    faces[flips] = faces[flips][:, ::-1]
    plain = coo_matrix(
        (np.ones(len(mesh.face_adjacency)), tuple(mesh.face_adjacency.T)),
        shape=(len(faces), len(faces)),
    )
    _, pieces = connected_components(plain, directed=False)
    inverted = _signed_volumes(np.asarray(mesh.vertices), faces, pieces) < 0.0
    flip_piece = inverted[pieces]
    faces[flip_piece] = faces[flip_piece][:, ::-1]
    if flips.any() or flip_piece.any():
        mesh.faces = faces
    return bool(mesh.is_winding_consistent and mesh.volume > 0.0)


# --------------------------------------------------------------------------------------
# Building a GraspObject
# --------------------------------------------------------------------------------------


def _process_mesh(vertices: np.ndarray, triangles: np.ndarray) -> tuple[trimesh.Trimesh, bool]:
    """Build the processed trimesh and orient it when closed.

    Parameters
    ----------
    vertices : (V, 3) float, m
    triangles : (T, 3) int

    Returns
    -------
    mesh : trimesh.Trimesh
    watertight : bool
        Closed, consistently oriented and of positive volume.
    """
    mesh = trimesh.Trimesh(vertices=vertices, faces=triangles, process=True, validate=False)
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.update_faces(mesh.unique_faces())
    mesh.remove_unreferenced_vertices()
    if len(mesh.faces) == 0:
        raise ObjectError("mesh: degenerate (all triangles have zero area)")
    watertight = bool(mesh.is_watertight) and _orient_outward(mesh)
    return mesh, watertight


def _convex_hull(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Convex hull of ``mesh`` as a closed trimesh, or ObjectError when it has no volume."""
    try:
        hull = mesh.convex_hull
    except Exception as exc:  # qhull raises its own error types
        raise ObjectError(f"mesh: cannot compute its convex hull ({exc})") from None
    if len(hull.faces) == 0 or not hull.volume > 0.0:
        raise _flat_error(0.0)
    return hull


def _box_along(points: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """Sizes (m) of ``points`` (N, 3) along the unit row vectors of ``axes`` (3, 3)."""
    return np.ptp(points @ axes.T, axis=0)


def _oriented_box_axes(mesh: trimesh.Trimesh, hull_points: np.ndarray) -> np.ndarray | None:
    """Axes of trimesh's oriented bounding box (``trimesh.bounds.oriented_bounds``).

    Its cost grows with the hull size (about 5 s for a 100,000-vertex hull), so for
    hulls of more than :data:`_OBB_MAX_POINTS` vertices the orientation is searched on
    an evenly strided subset of them; the caller measures the box on all of them.

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
            subset = np.linspace(0, len(hull_points) - 1, _OBB_MAX_POINTS).astype(np.int64)
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
    zero-area and duplicate triangles and unreferenced vertices are removed, and when
    the mesh is closed its faces are re-wound consistently with outward normals.
    """
    if not isinstance(name, str):
        raise ObjectError(f"name: expected a string, got {type(name).__name__}")
    limit = _check_limit(max_triangles)
    verts, tris = _check_raw_mesh(vertices, triangles, limit)
    mesh, watertight = _process_mesh(verts, tris)
    hull = _convex_hull(mesh)
    principal_extents, principal_axes = _principal_box(mesh, hull)
    if principal_extents[-1] <= MIN_THICKNESS:
        raise _flat_error(float(principal_extents[-1]))
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


# --------------------------------------------------------------------------------------
# Mesh files
# --------------------------------------------------------------------------------------


def _uri_to_path(path: PathLike) -> str:
    """Turn a path or ``file://`` URI into a filesystem path string.

    Raises
    ------
    ObjectError
        Empty path, NUL bytes, or a URI scheme other than ``file``.
    """
    if isinstance(path, os.PathLike):
        path = os.fspath(path)
    if not isinstance(path, str):
        raise ObjectError(f"mesh_uri: expected a path or file:// URI, got {type(path).__name__}")
    if not path.strip():
        raise ObjectError("mesh_uri: empty")
    match = _URI_SCHEME.match(path)
    if match:
        scheme = match.group(1).lower()
        if scheme != "file":
            raise ObjectError(
                f"mesh_uri: unsupported URI scheme '{scheme}://' (expected a file path or "
                f"a file:// URI): {path}"
            )
        parsed = urllib.parse.urlparse(path)
        if parsed.netloc not in ("", "localhost"):
            raise ObjectError(
                f"mesh_uri: remote file:// host '{parsed.netloc}' not supported: {path}"
            )
        path = urllib.parse.unquote(parsed.path)
        if not path:
            raise ObjectError("mesh_uri: empty")
    if "\x00" in path:
        raise ObjectError("mesh_uri: path contains a NUL character")
    return path


def _resolve_inside(path: str, allowed_dir: PathLike | None) -> str:
    """Resolve symlinks and ``..``; refuse a result outside ``allowed_dir``.

    Parameters
    ----------
    path : str
        Requested path (relative paths are taken from the current directory).
    allowed_dir : path or None
        Directory the resolved file must lie in; None allows any path.

    Returns
    -------
    str
        The resolved absolute path.
    """
    real = os.path.realpath(path)
    if allowed_dir is None:
        return real
    allowed = os.path.realpath(os.fspath(allowed_dir))
    if not os.path.isdir(allowed):
        raise ObjectError(f"mesh_uri: the allowed mesh directory does not exist: {allowed}")
    if os.path.commonpath([real, allowed]) != allowed:
        raise ObjectError(f"mesh_uri: outside the allowed mesh directory {allowed}: {path}")
    return real


def _file_format(path: str) -> str:
    """Lower-case extension of ``path`` (no dot) if it is in :data:`MESH_FORMATS`."""
    ext = os.path.splitext(path)[1].lower()
    if ext.lstrip(".") not in MESH_FORMATS:
        shown = ext if ext else "(none)"
        raise ObjectError(
            f"mesh_uri: unknown format '{shown}' (expected {', '.join(MESH_FORMATS)}): {path}"
        )
    return ext.lstrip(".")


def _read_bytes(real: str, shown: str, max_bytes: int) -> bytes:
    """Read a whole file of at most ``max_bytes`` bytes.

    Parameters
    ----------
    real : str
        Resolved path to open.
    shown : str
        Path to name in error messages (the one the caller gave).
    max_bytes : int
        Largest accepted file size, bytes.
    """
    if not os.path.exists(real):
        raise ObjectError(f"mesh_uri: file not found: {shown}")
    if not os.path.isfile(real):
        raise ObjectError(f"mesh_uri: not a regular file: {shown}")
    try:
        with open(real, "rb") as handle:
            size = os.fstat(handle.fileno()).st_size
            if size > max_bytes:
                raise ObjectError(
                    f"mesh_uri: file is {size} bytes, exceeds the limit of {max_bytes}: {shown}"
                )
            data = handle.read(max_bytes + 1)
    except OSError as exc:
        raise ObjectError(f"mesh_uri: cannot read file ({exc.strerror or exc}): {shown}") from None
    if len(data) > max_bytes:
        raise ObjectError(f"mesh_uri: file exceeds the limit of {max_bytes} bytes: {shown}")
    if not data:
        raise ObjectError(f"mesh_uri: file is empty: {shown}")
    return data


def _parse_mesh(data: bytes, file_type: str, shown: str) -> trimesh.Trimesh:
    """Parse mesh file bytes with trimesh; concatenate a Scene's meshes.

    Returns
    -------
    trimesh.Trimesh
        Unprocessed mesh with at least one triangle.
    """
    try:
        loaded = trimesh.load(io.BytesIO(data), file_type=file_type, process=False)
    except Exception as exc:  # trimesh parsers raise many exception types
        # An ImportError means trimesh wanted an optional decoder for unrecognised bytes.
        if isinstance(exc, ImportError):
            detail = "unrecognised content"
        else:
            detail = f"{type(exc).__name__}: {exc}"
        raise ObjectError(
            f"mesh_uri: cannot parse as {file_type.upper()} ({detail}): {shown}"
        ) from None
    if isinstance(loaded, trimesh.Scene):
        parts = [g for g in loaded.dump() if isinstance(g, trimesh.Trimesh) and len(g.faces)]
        loaded = trimesh.util.concatenate(parts) if parts else None
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise ObjectError(f"mesh_uri: file contains no triangles: {shown}")
    return loaded


def from_file(
    path: PathLike,
    allowed_dir: PathLike | None = None,
    max_triangles: int = DEFAULT_MAX_TRIANGLES,
    max_bytes: int = DEFAULT_MAX_BYTES,
    name: str | None = None,
) -> GraspObject:
    """Load, validate and build a :class:`GraspObject` from an STL/OBJ/PLY/OFF file.

    Parameters
    ----------
    path : str or os.PathLike
        File path or ``file://`` URI (percent-encoding decoded; host empty or
        ``localhost``). Other schemes (``package://``, ``http://`` ...) are refused.
        The vertices are read as metres in the object frame.
    allowed_dir : str or os.PathLike or None
        When given, the file, after resolving symlinks and ``..`` (``os.path.realpath``),
        must lie inside this directory.
    max_triangles : int
        Largest accepted number of triangles.
    max_bytes : int
        Largest accepted file size, bytes.
    name : str or None
        Object name; default the file name without extension.

    Returns
    -------
    GraspObject

    Raises
    ------
    ObjectError
        ``mesh_uri: ...`` for a bad URI, a file outside ``allowed_dir``, an unknown
        extension, a missing, unreadable, empty or too large file, a file trimesh cannot
        parse or without triangles; ``mesh: ... (mesh_uri: <path>)`` when the mesh itself
        is invalid (see :func:`from_arrays`).

    Notes
    -----
    The format comes from the extension of the path as given (case-insensitive). The
    containment check resolves symlinks at call time. A multi-geometry file (a trimesh
    Scene) is flattened with its transforms and concatenated.
    """
    limit = _check_limit(max_triangles)
    if isinstance(max_bytes, bool) or not isinstance(max_bytes, (int, np.integer)) or max_bytes < 1:
        raise ValueError(f"max_bytes: expected a positive integer, got {max_bytes!r}")
    requested = _uri_to_path(path)
    real = _resolve_inside(requested, allowed_dir)
    file_type = _file_format(requested)
    data = _read_bytes(real, requested, int(max_bytes))
    loaded = _parse_mesh(data, file_type, requested)
    stem = os.path.splitext(os.path.basename(requested))[0] or "mesh"
    try:
        return from_arrays(loaded.vertices, loaded.faces, name=name or stem, max_triangles=limit)
    except ObjectError as exc:
        raise ObjectError(f"{exc} (mesh_uri: {requested})") from None


# --------------------------------------------------------------------------------------
# Built-in objects (paper section 5: sphere, cube, barrel, fish)
# --------------------------------------------------------------------------------------

SPHERE_DIAMETER = 0.05  #: m
CUBE_EDGE = 0.07  #: m
BARREL_LENGTH = 0.11  #: m, along the object z axis
BARREL_DIAMETER = 0.03  #: m, at the middle (largest)
BARREL_BULGE = 0.10  #: middle diameter is 10 % larger than the end diameter
FISH_LENGTH = 0.29  #: m, along x (head toward +x)
FISH_WIDTH = 0.06  #: m, along y
FISH_HEIGHT = 0.07  #: m, along z
_SECTIONS = 48  #: vertices around a lofted cross-section (a multiple of 4)


def _loft_faces(n_rings: int, n_around: int) -> np.ndarray:
    """Side triangles joining consecutive rings of a lofted tube.

    Vertex ``j * n_around + k`` is point k of ring j.

    Returns
    -------
    (2 * (n_rings - 1) * n_around, 3) int
    """
    j, k = np.meshgrid(np.arange(n_rings - 1), np.arange(n_around), indexing="ij")
    j, k = j.ravel(), k.ravel()
    k1 = (k + 1) % n_around
    p00, p01 = j * n_around + k, j * n_around + k1
    p10, p11 = p00 + n_around, p01 + n_around
    return np.concatenate([np.stack([p00, p10, p11], 1), np.stack([p00, p11, p01], 1)])


def _fan(center: int, ring: np.ndarray, reverse: bool) -> np.ndarray:
    """Triangles closing a ring with a fan around vertex ``center``.

    Parameters
    ----------
    center : int
        Index of the fan's centre vertex.
    ring : (N,) int
        Ring vertex indices in order.
    reverse : bool
        Reverse the winding of the fan.

    Returns
    -------
    (N, 3) int
    """
    tris = np.stack([np.full(len(ring), center), np.roll(ring, -1), ring], axis=1)
    return tris[:, ::-1] if reverse else tris


def _barrel() -> tuple[np.ndarray, np.ndarray]:
    """Barrel along z: length 0.11 m, diameter 0.03 m in the middle, 10 % bulge.

    The radius follows a parabola from ``r_end = r_mid / 1.1`` at z = +-L/2 to
    ``r_mid = 0.015 m`` at z = 0; flat end caps. Centred at the origin.

    Returns
    -------
    vertices : (V, 3) float, m
    triangles : (T, 3) int
    """
    r_mid = BARREL_DIAMETER / 2.0
    r_end = r_mid / (1.0 + BARREL_BULGE)
    z = np.linspace(-BARREL_LENGTH / 2.0, BARREL_LENGTH / 2.0, 23)
    radius = r_end + (r_mid - r_end) * (1.0 - (2.0 * z / BARREL_LENGTH) ** 2)
    theta = 2.0 * np.pi * np.arange(_SECTIONS) / _SECTIONS
    rings = np.stack(
        [
            radius[:, None] * np.cos(theta)[None, :],
            radius[:, None] * np.sin(theta)[None, :],
            np.broadcast_to(z[:, None], (len(z), _SECTIONS)),
        ],
        axis=-1,
    ).reshape(-1, 3)
    n = len(rings)
    vertices = np.vstack([rings, [[0.0, 0.0, z[0]], [0.0, 0.0, z[-1]]]])
    first = np.arange(_SECTIONS)
    last = first + n - _SECTIONS
    faces = np.vstack(
        [
            _loft_faces(len(z), _SECTIONS),
            _fan(n, first, reverse=False),
            _fan(n + 1, last, reverse=True),
        ]
    )
    return vertices, faces


def _streamline(u: np.ndarray) -> np.ndarray:
    """Closed NACA 00xx thickness profile scaled to a maximum of about 1.

    Parameters
    ----------
    u : (N,) float in [0, 1]
        Position along the body (0 nose, 1 tail end).

    Returns
    -------
    (N,) float
        0 at u = 0 and u = 1, maximum about 1 near u = 0.3.
    """
    t = 0.2969 * np.sqrt(u) - 0.1260 * u - 0.3516 * u**2 + 0.2843 * u**3 - 0.1036 * u**4
    return t / 0.1


def _fish_profiles(s: np.ndarray, s_tail: float) -> tuple[np.ndarray, np.ndarray]:
    """Relative half-width (y) and half-height (z) of the fish cross-sections.

    The body (s <= s_tail) is a streamlined profile plus a term that keeps the caudal
    peduncle 0.10 (width) and 0.22 (height) of the body maximum; the tail fin
    (s > s_tail) thins to 0.05 and flares to 0.86 in height.

    Parameters
    ----------
    s : (M,) float in (0, 1]
        Position from the nose (0) to the tail lobe tips (1), fraction of the length.
    s_tail : float
        Position of the caudal peduncle, where the tail fin starts.

    Returns
    -------
    half_width, half_height : (M,) float
        Relative sizes; the body maximum is about 1.
    """
    peduncle_w, peduncle_h, fin_end_w, fin_end_h = 0.10, 0.22, 0.05, 0.86
    u = np.clip(s / s_tail, 0.0, 1.0)
    body_w = _streamline(u) + peduncle_w * u**2
    body_h = _streamline(u) + peduncle_h * u**2
    v = np.clip((s - s_tail) / (1.0 - s_tail), 0.0, 1.0)
    fin_w = peduncle_w + (fin_end_w - peduncle_w) * v
    fin_h = peduncle_h + (fin_end_h - peduncle_h) * np.sin(0.5 * np.pi * v) ** 1.3
    in_fin = s > s_tail
    return np.where(in_fin, fin_w, body_w), np.where(in_fin, fin_h, body_h)


def _tail_strip(base: int, n_around: int) -> np.ndarray:
    """Triangles closing the fish's last ring, a thin vertical loop, as a strip.

    Ring point k (angle theta_k = -pi/2 + 2 pi k / N) faces its mirror image across
    y = 0, point (N - k) mod N; consecutive mirror pairs are joined by two triangles.

    Parameters
    ----------
    base : int
        Index of the ring's first vertex.
    n_around : int
        Points on the ring N (even).

    Returns
    -------
    (N - 2, 3) int
    """
    k = np.arange(n_around // 2)
    k1 = k + 1
    mk, mk1 = (n_around - k) % n_around, (n_around - k1) % n_around
    tris = np.concatenate([np.stack([k, mk1, k1], 1), np.stack([k, mk, mk1], 1)])
    distinct = (tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 0] != tris[:, 2])
    return base + tris[distinct]


def _fish() -> tuple[np.ndarray, np.ndarray]:
    """A procedural fish: 0.29 m long (x) x 0.06 m wide (y) x 0.07 m high (z).

    A lofted body of elliptical cross-sections, head toward +x, back toward +z: a
    streamlined (NACA 00xx) profile from the blunt nose to a narrow caudal peduncle at
    78 % of the length, then a thin tail fin that flares to about 0.06 m high with a
    forked trailing edge (its top and bottom lobes reach 45 % of the fin length further
    back than its middle). The nose closes with a fan to the tip, the trailing edge with
    a thin strip. Vertices are shifted along x so that the centre of mass is at the
    origin (the shape is symmetric about y = 0 and z = 0).

    Returns
    -------
    vertices : (V, 3) float, m
    triangles : (T, 3) int
    """
    s_tail, fork, n_body, n_fin = 0.78, 0.45, 44, 18
    s_body = s_tail * (1.0 - np.cos(0.5 * np.pi * np.linspace(0.0, 1.0, n_body + 1)[1:]))
    s = np.concatenate([s_body, np.linspace(s_tail, 1.0, n_fin + 1)[1:]])
    half_w, half_h = _fish_profiles(s, s_tail)
    in_body = s <= s_tail
    half_w = half_w / half_w[in_body].max() * (FISH_WIDTH / 2.0)
    half_h = half_h / half_h[in_body].max() * (FISH_HEIGHT / 2.0)
    theta = -0.5 * np.pi + 2.0 * np.pi * np.arange(_SECTIONS) / _SECTIONS
    fin_length = (1.0 - s_tail) * FISH_LENGTH
    v = np.clip((s - s_tail) / (1.0 - s_tail), 0.0, 1.0)
    lobe = (1.0 - fork) + fork * np.abs(np.sin(theta)) ** 1.5
    x = FISH_LENGTH * (1.0 - np.minimum(s, s_tail))[:, None] - fin_length * v[:, None] * lobe
    y = half_w[:, None] * np.cos(theta)[None, :]
    z = half_h[:, None] * np.sin(theta)[None, :]
    rings = np.stack([x, y, z], axis=-1).reshape(-1, 3)
    nose = len(rings)
    vertices = np.vstack([rings, [[FISH_LENGTH, 0.0, 0.0]]])
    faces = np.vstack(
        [
            _fan(nose, np.arange(_SECTIONS), reverse=True),
            _loft_faces(len(s), _SECTIONS),
            _tail_strip(nose - _SECTIONS, _SECTIONS),
        ]
    )
    return vertices, faces


def _sphere() -> tuple[np.ndarray, np.ndarray]:
    """Icosphere (subdivisions 3) of diameter 0.05 m centred at the origin."""
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=SPHERE_DIAMETER / 2.0)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def _cube() -> tuple[np.ndarray, np.ndarray]:
    """Cube of edge 0.07 m centred at the origin, faces normal to the object axes."""
    mesh = trimesh.creation.box(extents=(CUBE_EDGE, CUBE_EDGE, CUBE_EDGE))
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


_BUILDERS = {"sphere": _sphere, "cube": _cube, "barrel": _barrel, "fish": _fish}


@functools.lru_cache(maxsize=None)
def _builtin_cached(name: str) -> GraspObject:
    """Build (once) the built-in object ``name``, centre of mass moved to the origin."""
    vertices, faces = _BUILDERS[name]()
    first = from_arrays(vertices, faces, name=name)
    if np.allclose(first.center_of_mass, 0.0, atol=1e-9):
        return first
    return from_arrays(vertices - first.center_of_mass, faces, name=name)


def builtin(name: str) -> GraspObject:
    """One of the paper's test objects, with the paper's sizes (metres).

    ========  ===================================================================
    name      shape
    ========  ===================================================================
    sphere    icosphere (subdivisions 3), diameter 0.05
    cube      box, edge 0.07, faces normal to the object axes
    barrel    along z: length 0.11, diameter 0.03 in the middle and 0.03 / 1.1 at
              the flat ends (a 10 % parabolic bulge), 48 sections
    fish      0.29 (x, head at +x) x 0.06 (y) x 0.07 (z, back up): lofted
              streamlined body, narrow tail stalk, forked tail fin
    ========  ===================================================================

    All are closed, outward-oriented meshes whose centre of mass is at the origin
    (the fish is shifted along x to put it there). Built once and cached; the returned
    objects are shared and immutable.

    Parameters
    ----------
    name : str
        One of :data:`BUILTIN_OBJECTS` (exact, lower case).

    Returns
    -------
    GraspObject

    Raises
    ------
    ObjectError
        ``object_name: unknown built-in object ...`` naming the valid ones.
    """
    if not isinstance(name, str) or name not in _BUILDERS:
        raise ObjectError(
            f"object_name: unknown built-in object {name!r} "
            f"(expected one of: {', '.join(BUILTIN_OBJECTS)})"
        )
    return _builtin_cached(name)


# --------------------------------------------------------------------------------------
# Poses
# --------------------------------------------------------------------------------------


def _as_vector(values: Any, size: int, what: str) -> np.ndarray:
    """A finite float vector of length ``size`` or ObjectError naming ``what``."""
    try:
        vec = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise ObjectError(f"{what} must be {size} numbers") from None
    if vec.shape != (size,):
        raise ObjectError(f"{what} must have shape ({size},), got {vec.shape}")
    if not np.isfinite(vec).all():
        raise ObjectError(f"{what} is not finite: {vec.tolist()}")
    return vec


def pose_to_matrix(position: Any, quaternion: Any, field: str = "object_pose") -> np.ndarray:
    """Homogeneous transform of a pose.

    Parameters
    ----------
    position : array_like, (3,) float, m
    quaternion : array_like, (4,) float
        Orientation as (x, y, z, w) (ROS order). Its norm must be 1 within
        :data:`QUATERNION_NORM_TOLERANCE` (1e-3); such a quaternion is normalised, any
        other is rejected, not silently normalised.
    field : str
        Request field named in error messages.

    Returns
    -------
    (4, 4) float
        ``T`` with ``T[:3, :3]`` the rotation and ``T[:3, 3]`` the position.

    Raises
    ------
    ObjectError
        ``object_pose: ...`` for wrong shapes, non-finite values, a zero quaternion or a
        quaternion that is not unit.
    """
    pos = _as_vector(position, 3, f"{field}: position")
    quat = _as_vector(quaternion, 4, f"{field}: quaternion")
    norm = float(np.linalg.norm(quat))
    if norm < 1e-12:
        raise ObjectError(f"{field}: zero quaternion")
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        raise ObjectError(f"{field}: quaternion is not unit (norm {norm:.4g})")
    transform = np.eye(4)
    transform[:3, :3] = Rotation.from_quat(quat / norm).as_matrix()
    transform[:3, 3] = pos
    return transform


def _check_transform(transform: Any) -> np.ndarray:
    """A (4, 4) finite float array, or ValueError naming ``T``."""
    mat = np.asarray(transform, dtype=np.float64)
    if mat.shape != (4, 4):
        raise ValueError(f"T: expected shape (4, 4), got {mat.shape}")
    if not np.isfinite(mat).all():
        raise ValueError("T: not finite")
    return mat


def matrix_to_pose(transform: Any) -> tuple[np.ndarray, np.ndarray]:
    """Position and quaternion of a rigid homogeneous transform.

    Parameters
    ----------
    transform : array_like, (4, 4) float
        Rigid transform: rotation block orthonormal with determinant +1 (within 1e-6),
        last row (0, 0, 0, 1).

    Returns
    -------
    position : (3,) float, m
    quaternion : (4,) float
        Unit (x, y, z, w) with w >= 0.

    Raises
    ------
    ValueError
        ``T: ...`` when the matrix is not a finite rigid transform.
    """
    mat = _check_transform(transform)
    if not np.allclose(mat[3], (0.0, 0.0, 0.0, 1.0), atol=1e-9):
        raise ValueError(f"T: last row must be (0, 0, 0, 1), got {mat[3].tolist()}")
    rot = mat[:3, :3]
    if not np.allclose(rot @ rot.T, np.eye(3), atol=1e-6) or np.linalg.det(rot) <= 0.0:
        raise ValueError("T: rotation block is not a proper rotation")
    quat = Rotation.from_matrix(rot).as_quat()
    if quat[3] < 0.0:
        quat = -quat
    return mat[:3, 3].copy(), quat


def transform_points(transform: Any, points: Any) -> np.ndarray:
    """Apply a homogeneous transform to points.

    Parameters
    ----------
    transform : array_like, (4, 4) float
    points : array_like, (..., 3) float, m

    Returns
    -------
    (..., 3) float, m
        ``R @ p + t`` for every point.
    """
    mat = _check_transform(transform)
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim == 0 or pts.shape[-1] != 3:
        raise ValueError(f"points: expected shape (..., 3), got {pts.shape}")
    return pts @ mat[:3, :3].T + mat[:3, 3]


def transform_vectors(transform: Any, vectors: Any) -> np.ndarray:
    """Rotate vectors (directions, normals, forces) by a transform's rotation only.

    Parameters
    ----------
    transform : array_like, (4, 4) float
    vectors : array_like, (..., 3) float

    Returns
    -------
    (..., 3) float
        ``R @ v`` for every vector.
    """
    mat = _check_transform(transform)
    vecs = np.asarray(vectors, dtype=np.float64)
    if vecs.ndim == 0 or vecs.shape[-1] != 3:
        raise ValueError(f"vectors: expected shape (..., 3), got {vecs.shape}")
    return vecs @ mat[:3, :3].T
