"""Objects to grasp: validated meshes and the built-in objects.

An object is a triangle mesh in its own frame (the *object frame*), in metres. It is
validated once, at the edge, and then held in an immutable :class:`GraspObject`
together with the derived data the planner needs (centre of mass, extents, principal
axes, convex hull, a torque scale and a stable hash for caching).

Constructors (module functions; the same functions are also available as
``GraspObject.from_arrays``, ``GraspObject.from_file`` and ``GraspObject.builtin``):

- :func:`from_arrays` -- vertices and triangles, e.g. from a ``shape_msgs/Mesh``.
- :func:`from_file` -- an STL / OBJ / PLY / OFF file given as a path or ``file://`` URI,
  optionally confined to an allowed directory (:mod:`grasp_apso.mesh_files`).
- :func:`builtin` -- the paper's four test objects, :data:`BUILTIN_OBJECTS`, whose
  meshes :mod:`grasp_apso.shapes` builds.

Every invalid object raises :class:`ObjectError` (a ``ValueError``) whose message starts
with the offending request field (``mesh:``, ``mesh_uri:``, ``object_name:``,
``object_pose:``), for example ``"mesh: triangle 3 index 99 out of range (8 vertices)"``.

The pose utilities of :mod:`grasp_apso.poses` (:func:`pose_to_matrix`,
:func:`matrix_to_pose`, :func:`transform_points`, :func:`transform_vectors`) and
:func:`from_file` are re-exported here, so ``from grasp_apso.objects import X`` works
for every name in ``__all__``. They are bound on first use (``__getattr__`` below)
because those modules import :class:`ObjectError` and :func:`from_arrays` from this one:
importing them here at load time would make an import cycle.

Decisions
---------
- Uniform density. When the mesh is a closed, consistently oriented solid
  (``watertight``), the centre of mass is the mesh's volume centroid; otherwise it is the
  centroid of the mesh's convex hull.
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

import functools
import hashlib
import importlib
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import trimesh

from . import shapes
from .shapes import (  # noqa: F401  re-exported: the shapes' sizes
    BARREL_BULGE,
    BARREL_DIAMETER,
    BARREL_LENGTH,
    CUBE_EDGE,
    FISH_HEIGHT,
    FISH_LENGTH,
    FISH_WIDTH,
    SPHERE_DIAMETER,
)

if TYPE_CHECKING:  # what __getattr__ binds on first use, for type checkers and IDEs
    from .mesh_files import DEFAULT_MAX_BYTES, PathLike, from_file  # noqa: F401
    from .poses import (  # noqa: F401
        QUATERNION_NORM_TOLERANCE,
        matrix_to_pose,
        pose_to_matrix,
        transform_points,
        transform_vectors,
    )

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

#: Default limit on the number of triangles of a mesh (``DEFAULT_MAX_BYTES``, the one
#: on the size of a mesh file, is in :mod:`grasp_apso.mesh_files`).
DEFAULT_MAX_TRIANGLES: int = 200_000

#: Triangles with an area at or below this (m^2) count as zero-area.
_ZERO_AREA: float = 1e-14

#: Hull vertices above which the oriented-box orientation is searched on a subset of
#: ``_OBB_SUBSET`` of them (trimesh's search costs about 0.16 s for 2,000 points, 0.04 s
#: for 500; the box is then measured on all of them).
_OBB_MAX_POINTS: int = 2000
_OBB_SUBSET: int = 500


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
        from .mesh_files import from_file  # mesh_files imports this module

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
# Orientation (winding) repair
# --------------------------------------------------------------------------------------


def _orient_outward(mesh: trimesh.Trimesh) -> bool:
    """Make a closed mesh's winding consistent with outward normals, in place.

    ``trimesh.repair.fix_normals(mesh, multibody=True)``: faces re-wound consistently
    across shared edges, then each connected piece turned to have positive volume
    (nested shells, i.e. hollow solids, are not supported: their inner shell also ends
    up outward). Cost: for a consistently wound mesh, only the per-piece volume check;
    otherwise trimesh walks the faces in Python, about 0.1 ms per face (some 25 s for
    200,000 triangles).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        A watertight mesh (every edge shared by exactly two faces).

    Returns
    -------
    bool
        True when the mesh is now a consistently oriented solid of positive volume.
        When it cannot be (a non-orientable surface), the faces are left as given.
    """
    faces = mesh.faces.copy()
    trimesh.repair.fix_normals(mesh, multibody=True)
    if not mesh.is_winding_consistent:
        # Non-orientable: trimesh leaves it re-wound part way, depending on where its
        # walk started; keep the faces as they came (and so a stable mesh_hash).
        mesh.faces = faces
        return False
    return bool(mesh.volume > 0.0)


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
# Built-in objects (paper section 5: sphere, cube, barrel, fish)
# --------------------------------------------------------------------------------------

_BUILDERS = {
    "sphere": shapes.sphere,
    "cube": shapes.cube,
    "barrel": shapes.barrel,
    "fish": shapes.fish,
}


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
# Re-exports of grasp_apso.mesh_files and grasp_apso.poses
# --------------------------------------------------------------------------------------

#: Names re-exported from other modules, bound on first access (PEP 562): those modules
#: import from this one, so importing them while this one loads would be a cycle.
_REEXPORTS: dict[str, str] = {
    "from_file": "mesh_files",
    "DEFAULT_MAX_BYTES": "mesh_files",
    "PathLike": "mesh_files",
    "pose_to_matrix": "poses",
    "matrix_to_pose": "poses",
    "transform_points": "poses",
    "transform_vectors": "poses",
    "QUATERNION_NORM_TOLERANCE": "poses",
}


def __getattr__(name: str) -> Any:
    """Bind a re-exported name (``from_file``, ``pose_to_matrix`` ...) on first access."""
    module = _REEXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __package__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    """Module attributes, re-exports included."""
    return sorted(set(globals()) | set(_REEXPORTS))
