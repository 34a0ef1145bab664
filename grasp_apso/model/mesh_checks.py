"""Validation and processing of raw triangle meshes (the edge of every object source).

:func:`check_raw_mesh` checks the arrays a caller sent (emptiness, shapes, finiteness,
indices, size limits, zero-area triangles, flatness) and :func:`process_mesh` builds the
trimesh (duplicates merged, degenerate faces dropped, small holes closed, closed meshes
wound outward, open ones wound consistently and outward as far as their holes allow).
Every failure raises :class:`~grasp_apso.errors.ObjectError` naming the field (``mesh:``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import trimesh

from ..errors import InputError, ObjectError

#: Minimum thickness (m) of an object along its thinnest oriented-bounding-box axis.
MIN_THICKNESS: float = 1e-3

#: Default limit on the number of triangles of a mesh (``DEFAULT_MAX_BYTES``, the one
#: on the size of a mesh file, is in :mod:`grasp_apso.model.mesh_files`).
DEFAULT_MAX_TRIANGLES: int = 200_000

#: Triangles with an area at or below this (m^2) count as zero-area.
_ZERO_AREA: float = 1e-14

def check_limit(max_triangles: int) -> int:
    """Validate the ``max_triangles`` argument and return it as an int."""
    if isinstance(max_triangles, bool) or not isinstance(max_triangles, (int, np.integer)):
        raise InputError(f"max_triangles: expected an integer, got {max_triangles!r}")
    if max_triangles < 1:
        raise InputError(f"max_triangles: must be positive, got {max_triangles}")
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


def flat_error(thickness: float) -> ObjectError:
    """The error for a mesh thinner than :data:`MIN_THICKNESS`."""
    return ObjectError(
        f"mesh: flat (thickness {round(thickness, 6)} m along its thinnest axis, "
        f"minimum {MIN_THICKNESS} m)"
    )


def check_raw_mesh(
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
        raise flat_error(thickness)
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


def process_mesh(vertices: np.ndarray, triangles: np.ndarray) -> tuple[trimesh.Trimesh, bool]:
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
    if not mesh.is_watertight:
        close_holes(mesh)
    watertight = bool(mesh.is_watertight) and _orient_outward(mesh)
    if not watertight and not mesh.is_watertight:
        _orient_open(mesh)
    return mesh, watertight


# --------------------------------------------------------------------------------------
# Holes (scans): closed when small, so that inside and outside, and the normals, are known
# --------------------------------------------------------------------------------------

#: Holes are closed when the caps that close them add at most this share of the mesh's
#: area: a scan's holes, its unseen bottom, a box missing a face (20 % for a cube, 43 % for
#: a cereal box missing a large side). A mesh with larger holes (a half shell without
#: thickness: 50 %) is refused (:func:`check_holes`): its inside is unknown.
MAX_HOLE_AREA: float = 0.45


def _boundary_loops(mesh: trimesh.Trimesh) -> list[np.ndarray] | None:
    """The holes' rims as closed loops of vertex indices, each in the direction its
    faces run along it; None when the rims touch themselves (not simple loops)."""
    edges = np.asarray(mesh.edges)
    single = trimesh.grouping.group_rows(np.asarray(mesh.edges_sorted), require_count=1)
    if len(single) == 0:
        return []
    directed = edges[np.asarray(single).reshape(-1)]
    starts, counts = np.unique(directed[:, 0], return_counts=True)
    if np.any(counts > 1) or set(starts.tolist()) != set(directed[:, 1].tolist()):
        return None
    # every rim vertex starts one edge and ends one: the edges form disjoint cycles
    following = dict(zip(directed[:, 0].tolist(), directed[:, 1].tolist()))
    loops = []
    while following:
        start, current = following.popitem()
        loop = [start]
        while current != start:  # each step removes an edge: bounded
            loop.append(current)
            current = following.pop(current)
        loops.append(np.array(loop, dtype=np.int64))
    return loops


def _fan_caps(mesh: trimesh.Trimesh) -> None:
    """Close every simple boundary loop with a fan of triangles around a new vertex at its
    centroid, wound against the rim's faces (the winding stays consistent); in place.
    Nothing when the rims are not simple loops."""
    loops = _boundary_loops(mesh)
    if not loops:
        return
    vertices = np.asarray(mesh.vertices)
    centres = np.array([vertices[loop].mean(axis=0) for loop in loops])
    faces = [np.stack([np.roll(loop, -1), loop, np.full(len(loop), len(vertices) + k)], axis=1)
             for k, loop in enumerate(loops)]
    mesh.vertices = np.vstack([vertices, centres])
    mesh.faces = np.vstack([np.asarray(mesh.faces)] + faces)


def hole_area_share(mesh: trimesh.Trimesh) -> float | None:
    """The area that fans over the holes' rims would add, as a share of the mesh's area;
    0 for a closed mesh, None when the rims are not simple loops."""
    loops = _boundary_loops(mesh)
    if loops is None:
        return None
    vertices = np.asarray(mesh.vertices)
    added = 0.0
    for loop in loops:
        centre = vertices[loop].mean(axis=0)
        spokes = np.cross(vertices[loop] - centre, vertices[np.roll(loop, -1)] - centre)
        added += 0.5 * float(np.linalg.norm(spokes, axis=1).sum())
    return added / max(float(mesh.area), 1e-30)


def check_holes(mesh: trimesh.Trimesh, watertight: bool) -> None:
    """Refuse a mesh whose holes are too large to close (ObjectError naming ``mesh``):
    contacts need the outward side of the surface, and with such holes the inside of the
    object is unknown. Holes whose rims touch themselves (non-manifold edges) are left as
    they are, open."""
    if watertight:
        return
    share = hole_area_share(mesh)
    if share is not None and share > MAX_HOLE_AREA:
        raise ObjectError(
            f"mesh: not closed, and its holes are too large to close (closing them would add {share:.0%} to its "
            f"area, at most {MAX_HOLE_AREA:.0%}): which side is outside is unknown, so contact normals would be "
            "guesses; send a closed mesh (fill the holes of the scan)")


def close_holes(mesh: trimesh.Trimesh, max_area: float = MAX_HOLE_AREA) -> bool:
    """Close the holes of an open mesh, in place, when they are small.

    Triangular and quadrilateral holes are filled by ``trimesh.repair.fill_holes``; any
    other hole whose rim is a simple loop gets a fan of triangles around its centroid
    (:func:`_fan_caps`). Nothing changes unless the mesh comes out closed and the new
    triangles add at most ``max_area`` of the mesh's area.

    Returns True when the holes were closed.
    """
    area = float(mesh.area)
    trial = mesh.copy()
    trimesh.repair.fill_holes(trial)
    if not trial.is_watertight:
        _fan_caps(trial)
    if not trial.is_watertight or float(trial.area) - area > max_area * area:
        return False
    mesh.vertices = np.asarray(trial.vertices)
    mesh.faces = np.asarray(trial.faces)
    return True


def _orient_open(mesh: trimesh.Trimesh) -> None:
    """Wind an open mesh consistently and outward, in place: outward is where the signed
    volume of the mesh (closed by its holes' caps when they can be) comes out positive."""
    trimesh.repair.fix_winding(mesh)
    if not mesh.is_winding_consistent:
        return
    capped = mesh.copy()
    close_holes(capped, max_area=np.inf)
    if float(capped.volume) < 0.0:
        # The faces reversed (which drops every cached normal), not ``invert()``: trimesh
        # 5.2 left the face normals it had cached facing inward.
        mesh.faces = np.ascontiguousarray(np.asarray(mesh.faces)[:, ::-1])


def convex_hull(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Convex hull of ``mesh`` as a closed trimesh, or ObjectError when it has no volume."""
    try:
        hull = mesh.convex_hull
    except Exception as exc:  # qhull raises its own error types
        raise ObjectError(f"mesh: cannot compute its convex hull ({exc})") from None
    if len(hull.faces) == 0 or not hull.volume > 0.0:
        raise flat_error(0.0)
    return hull


# --------------------------------------------------------------------------------------
# What cannot be an object
# --------------------------------------------------------------------------------------

#: A mesh that is not closed must cover at least this share of its convex hull's surface:
#: an open surface without volume (two triangles forming a hinge cover 42 %) is not an
#: object, a bowl-like half shell (65 %) is (small holes, as in a scan or a box missing a
#: face, are closed before: :func:`close_holes`).
MIN_OPEN_COVERAGE: float = 0.5
#: Connected parts whose bounding boxes lie farther apart than this (m) are separate
#: bodies; a request plans one object, so such a mesh is refused. Parts that touch or
#: overlap (a mug's handle through its wall) or lie closer stay one object.
MAX_BODY_GAP: float = 0.05
#: Above this many connected parts the body check is skipped (a triangle soup).
_MAX_PARTS: int = 2000


def check_encloses_volume(mesh: trimesh.Trimesh, hull: trimesh.Trimesh, watertight: bool) -> None:
    """Refuse an open surface without volume (ObjectError naming ``mesh``).

    A closed mesh passes; an open one must cover at least :data:`MIN_OPEN_COVERAGE` of
    the surface area of its convex hull.
    """
    if watertight:
        return
    hull_area = float(hull.area)
    coverage = float(mesh.area) / hull_area if hull_area > 0 else 0.0
    if coverage < MIN_OPEN_COVERAGE:
        raise ObjectError(
            f"mesh: an open surface without volume (not closed, and it covers only {coverage:.0%} of "
            f"its convex hull's surface, at least {MIN_OPEN_COVERAGE:.0%}); send a closed mesh of the object")


def check_one_body(mesh: trimesh.Trimesh) -> None:
    """Refuse a mesh of separate bodies more than :data:`MAX_BODY_GAP` apart (ObjectError
    naming ``mesh``)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n_faces = len(mesh.faces)
    adjacency = np.asarray(mesh.face_adjacency, dtype=np.int64).reshape(-1, 2)
    graph = coo_matrix((np.ones(len(adjacency)), (adjacency[:, 0], adjacency[:, 1])), shape=(n_faces, n_faces))
    n_parts, labels = connected_components(graph, directed=False)
    if n_parts <= 1 or n_parts > _MAX_PARTS:
        return
    corners = np.asarray(mesh.vertices)[np.asarray(mesh.faces)]
    lo = np.full((n_parts, 3), np.inf)
    hi = np.full((n_parts, 3), -np.inf)
    np.minimum.at(lo, labels, corners.min(axis=1))
    np.maximum.at(hi, labels, corners.max(axis=1))
    # Gap between two boxes: the largest separation along any axis (0 when they overlap).
    gap = np.maximum(lo[:, None, :] - hi[None, :, :], lo[None, :, :] - hi[:, None, :]).max(axis=2)
    n_bodies, body = connected_components(coo_matrix(gap <= MAX_BODY_GAP), directed=False)
    if n_bodies > 1:
        between = gap[body[:, None] != body[None, :]]
        raise ObjectError(
            f"mesh: {n_bodies} separate bodies, the closest {float(between.min()) * 1000:.0f} mm apart "
            f"(parts farther apart than {MAX_BODY_GAP * 1000:.0f} mm are separate objects); a request plans "
            "one object: send each body in a request of its own")
