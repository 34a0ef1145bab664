"""The python-fcl shapes of any hand's exact collision geometry, and of an object, built once.

:class:`HandShapes` turns every :class:`~grasp_apso.model.hands.geometry.LinkGeometry` of a
:class:`~grasp_apso.model.hands.model.HandModel` (``hand.collision[link]``) into one *part*:
an ``fcl.Box`` / ``fcl.Sphere`` / ``fcl.Cylinder`` / ``fcl.Capsule`` for a primitive, an
``fcl.BVHModel`` of its triangles for a mesh, with the geometry's ``origin`` in its link
frame. The fcl geometries are shared between threads (only geometry); the collision objects
that carry a pose are per thread (:meth:`HandShapes.objects`).

Penetration depths. fcl's distance is exact between separated shapes, but a BVH is a
hollow surface to fcl: against a mesh its signed distance is 0 or -1, and a primitive wholly
inside a mesh is "not colliding". So a part that overlaps a mesh (object, mesh link) is
measured from points: its *samples* (a sphere: its centre, a capsule: points along its axis,
each inflated by the radius; a box, cylinder or mesh: points on its surface at most
:data:`SAMPLE_SPACING` apart) evaluated in the other solid's exact signed distance, and the
object's vertices and points along its edges as far apart
(:attr:`ObjectShape.edge_points`) in the part's exact signed distance (a sharp corner or
edge pressing into a flat face, as a mug's rim into a fingertip); the depth is the larger
of the two. It is the depth of the deepest point of one solid inside the other: for a
sphere or capsule, exact; for the surface samples, short by about ``spacing**2 / (8 r)``
where ``r`` is the distance of the deepest point from the other solid's medial axis (26 um
for a 3 mm deep contact on a 30 mm sphere; up to ``0.71 * spacing`` = 1.8 mm for a
penetration reaching that axis, a grasp that is illegal anyway). Never positive for shapes
in contact.

:class:`ObjectShape`: an object mesh's BVH (shared with :func:`.collision.object_bvh`), its
exact signed distance (:class:`~grasp_apso.model.hands.mesh_distance.MeshDistance`) and
vertices. Both are cached through :mod:`grasp_apso.cache` (named caches ``hand_collision``,
keyed by the hand's ``source_hash`` and a digest of its collision geometry, and
``object_distance``, keyed by the mesh hash).
"""

from __future__ import annotations

import hashlib
import math
from functools import cached_property

import fcl
import numba
import numpy as np
import trimesh

from ..cache import PerThreadCache, cached
from ..errors import InputError
from ..model.hands.geometry import LinkGeometry
from ..model.hands.mesh_distance import MeshDistance
from ..model.hands.model import HandModel
from .collision import BVH_BYTES_PER_TRIANGLE, mesh_bvh, object_bvh

__all__ = ["HandShapes", "ObjectShape", "hand_shapes", "object_shape", "DECIDE_WITHIN", "SAMPLE_SPACING", "MAX_SAMPLES",
           "TOUCH_EPS", "EXACT_WITHIN", "fcl_geometry", "local_samples"]

#: Largest gap (m) between the surface samples of a box, cylinder or mesh part.
SAMPLE_SPACING = 0.0025
#: Most samples per part; larger parts get a coarser spacing (sqrt(area / MAX_SAMPLES)).
MAX_SAMPLES = 3000
#: An fcl distance at most this (m) is a contact (fcl answers 0, -1 or ~1e-300 then).
TOUCH_EPS = 1e-9
#: GJK distances to an object's hull under this (m) are measured again exactly (BVH).
EXACT_WITHIN = 0.01
#: ... or under this (m) where only touching decides (the approach check's ``decide_only``):
#: a hull gap above it is a lower bound that already says "apart".
DECIDE_WITHIN = 1e-6
#: Planes of an object's bounding polytope (:meth:`ObjectShape.hull_gap`), at most.
BOUND_PLANES = 64
_PRIMITIVES = ("box", "sphere", "cylinder", "capsule")


def fcl_geometry(geom: LinkGeometry):
    """The fcl geometry of one LinkGeometry, in its geometry frame (fcl's cylinders and
    capsules lie along z, centred, as LinkGeometry's do)."""
    if geom.kind == "box":
        return fcl.Box(*(2.0 * np.asarray(geom.size)))
    if geom.kind == "sphere":
        return fcl.Sphere(geom.size[0])
    if geom.kind == "cylinder":
        return fcl.Cylinder(geom.size[0], 2.0 * geom.size[1])
    if geom.kind == "capsule":
        return fcl.Capsule(geom.size[0], 2.0 * geom.size[1])
    return mesh_bvh(geom.mesh)


def local_samples(geom: LinkGeometry) -> tuple[np.ndarray, float]:
    """(points (S, 3) in the GEOMETRY frame, inflation m): the solid is the set of points
    within ``inflation`` of the samples' hull / surface (see the module docstring)."""
    if geom.kind == "sphere":
        core, inflate = np.zeros((1, 3)), geom.size[0]
    elif geom.kind == "capsule":
        radius, half = geom.size
        count = int(math.ceil(2.0 * half / SAMPLE_SPACING)) + 1
        core, inflate = np.column_stack([np.zeros((count, 2)), np.linspace(-half, half, count)]), radius
    else:
        mesh = geom.to_trimesh()
        mesh.apply_transform(np.linalg.inv(geom.origin))  # back to the geometry frame
        spacing = max(SAMPLE_SPACING, math.sqrt(float(mesh.area) / MAX_SAMPLES))
        vertices, _ = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, max_edge=spacing, max_iter=20)
        core, inflate = np.unique(np.round(vertices, 12), axis=0), 0.0
        if len(core) > MAX_SAMPLES:  # deterministic thinning, the original vertices first
            core = np.vstack([mesh.vertices, core[:: int(math.ceil(len(core) / MAX_SAMPLES))]])
    return np.ascontiguousarray(core, dtype=float), float(inflate)


def _bounding_sphere(geom: LinkGeometry) -> tuple[np.ndarray, float]:
    """(centre (3,) geometry frame, radius m) of a sphere holding the whole geometry."""
    if geom.kind == "mesh":
        v = np.asarray(geom.mesh.vertices)
        centre = 0.5 * (v.min(axis=0) + v.max(axis=0))
        radius = float(np.linalg.norm(v - centre, axis=1).max())
    else:
        s = geom.size
        if geom.kind == "box":
            radius = float(np.linalg.norm(s))
        elif geom.kind == "sphere":
            radius = s[0]
        elif geom.kind == "cylinder":
            radius = math.hypot(s[0], s[1])
        else:  # capsule
            radius = s[0] + s[1]
        centre = np.zeros(3)
    return centre, radius


def _digest(hand: HandModel) -> str:
    """sha1 of the collision geometry (kinds, sizes, origins, mesh arrays) and link order."""
    h = hashlib.sha1("\0".join(hand.links).encode())
    for link in hand.links:
        for g in hand.collision.get(link, ()):
            h.update(f"{link}|{g.kind}|{g.size}".encode())
            h.update(np.ascontiguousarray(g.origin).tobytes())
            if g.mesh is not None:
                h.update(np.ascontiguousarray(g.mesh.vertices, dtype=np.float64).tobytes())
                h.update(np.ascontiguousarray(g.mesh.faces, dtype=np.int64).tobytes())
    return h.hexdigest()


class HandShapes:
    """The parts of one hand (shared, read-only after construction; built by :func:`hand_shapes`).

    Attributes
    ----------
    links : tuple of str
        The links with collision geometry (``hand.links`` order): the rows of every report.
    link_rows : (Lg,) int
        Their indices into ``hand.links``.
    part_link : (K,) int
        Per part, its row in ``links``.
    geoms : tuple of LinkGeometry, (K,)
    origins : (K, 4, 4) float
        Geometry frame in the link frame.
    primitive : (K,) bool
    finger : (Lg,) int
        Per link, the index of its finger in ``hand.fingers`` (-1: palm, forearm ...).
    bound_centre : (K, 3) float, m, geometry frame; bound_radius : (K,) float, m
        A sphere holding each part.
    """

    def __init__(self, hand: HandModel):
        self.hand = hand
        self.links = tuple(name for name in hand.links if hand.collision.get(name))
        self.link_rows = np.array([hand.links.index(name) for name in self.links], dtype=np.int64)
        row_of = {name: i for i, name in enumerate(self.links)}
        part_link, geoms = [], []
        for name in self.links:
            for g in hand.collision[name]:
                part_link.append(row_of[name])
                geoms.append(g)
        self.part_link = np.array(part_link, dtype=np.int64)
        self.geoms = tuple(geoms)
        self.origins = np.array([g.origin for g in geoms]).reshape(-1, 4, 4)
        self.primitive = np.array([g.kind in _PRIMITIVES for g in geoms], dtype=bool)
        #: spheres and capsules: a segment along z (half length ``sup_axial``) with a radius
        self.rounded = np.array([g.kind in ("sphere", "capsule") for g in geoms], dtype=bool)
        self.fcl_geometries = tuple(fcl_geometry(g) for g in geoms)
        bounds = [_bounding_sphere(g) for g in geoms]
        self.bound_centre = np.array([b[0] for b in bounds]).reshape(-1, 3)
        self.bound_radius = np.array([b[1] for b in bounds])
        finger = np.full(len(self.links), -1, dtype=np.int64)
        for f, fing in enumerate(hand.fingers):
            for name in hand.finger_links(fing):
                if name in row_of:
                    finger[row_of[name]] = f
        self.finger = finger
        self.collision_parent = self._collision_parents(hand, row_of)
        self._support_arrays()
        self.nbytes = sum(BVH_BYTES_PER_TRIANGLE * len(g.mesh.faces) for g in geoms if g.mesh is not None) + 4096

    @staticmethod
    def _collision_parents(hand: HandModel, row_of: dict[str, int]) -> np.ndarray:
        """Per link row: the row of its nearest ancestor with geometry (-1 if none)."""
        out = np.full(len(row_of), -1, dtype=np.int64)
        for name, row in row_of.items():
            i = hand.link_parents[hand.links.index(name)]
            while i >= 0 and hand.links[i] not in row_of:
                i = hand.link_parents[i]
            out[row] = row_of[hand.links[i]] if i >= 0 else -1
        return out

    def _support_arrays(self) -> None:
        """Per part, the terms of its support function h(u) = max over the part of u . (p - c)
        for a unit u in the geometry frame: |u| . half + radius + axial |u_z| + disc sqrt(1 - u_z^2)."""
        k = len(self.geoms)
        self.sup_half = np.zeros((k, 3))
        self.sup_radius = np.zeros(k)
        self.sup_axial = np.zeros(k)
        self.sup_disc = np.zeros(k)
        self.hull_vertices: dict[int, np.ndarray] = {}  # mesh parts: hull vertices, geometry frame
        for i, g in enumerate(self.geoms):
            if g.kind == "box":
                self.sup_half[i] = g.size
            elif g.kind == "sphere":
                self.sup_radius[i] = g.size[0]
            elif g.kind == "capsule":
                self.sup_radius[i], self.sup_axial[i] = g.size
            elif g.kind == "cylinder":
                self.sup_disc[i], self.sup_axial[i] = g.size
            else:
                self.hull_vertices[i] = np.asarray(g.mesh.convex_hull.vertices, dtype=float)

    @cached_property
    def samples(self) -> tuple[tuple[np.ndarray, float], ...]:
        """Per part: (points (S, 3) link frame, inflation m), see the module docstring."""
        return tuple(local_samples(g) for g in self.geoms)

    @cached_property
    def pair_candidates(self) -> tuple[np.ndarray, np.ndarray]:
        """(a, b) part indices of the self-collision pairs: parts of links of different
        fingers, of one finger's links that are not adjacent (a link and its nearest
        ancestor with geometry), and of a finger link and a palm link (a link no finger
        carries: the root, the links fixed to it, the held ones above it) that are not
        adjacent (a thumb link swung into the palm)."""
        la, lb = self.part_link[:, None], self.part_link[None, :]
        fa, fb = self.finger[la], self.finger[lb]
        adjacent = (self.collision_parent[la] == lb) | (self.collision_parent[lb] == la)
        fingers = (fa >= 0) & (fb >= 0) & ((fa != fb) | ~adjacent)
        palm = ((fa < 0) != (fb < 0)) & ~adjacent
        a, b = np.nonzero((la < lb) & (fingers | palm))
        return a.astype(np.int64), b.astype(np.int64)

    @cached_property
    def palm_pair(self) -> np.ndarray:
        """(len(a),) bool over :attr:`pair_candidates` (a, b): the pair has a palm part."""
        a, b = self.pair_candidates
        return (self.finger[self.part_link[a]] < 0) | (self.finger[self.part_link[b]] < 0)

    def objects(self) -> list:
        """This thread's fcl collision objects of the parts (moved with setTransform)."""
        return _PART_OBJECTS.get(self, lambda s: [fcl.CollisionObject(g, fcl.Transform())
                                                  for g in s.fcl_geometries])

    @cached_property
    def hull_geometries(self) -> tuple:
        """Per part, a solid that holds it for a quick lower bound: a mesh part's convex
        hull as an ``fcl.Convex`` (GJK: microseconds where the BVH of a 20,000-triangle CAD
        link takes milliseconds), a primitive itself."""
        out = []
        for i, geometry in enumerate(self.fcl_geometries):
            if i in self.hull_vertices:
                hull = self.geoms[i].mesh.convex_hull
                faces = np.column_stack([np.full(len(hull.faces), 3), hull.faces]).ravel().astype(np.int32)
                geometry = fcl.Convex(np.asarray(hull.vertices, dtype=float), len(hull.faces), faces)
            out.append(geometry)
        return tuple(out)

    def hull_objects(self) -> list:
        """This thread's fcl collision objects of :attr:`hull_geometries` (moved with setTransform)."""
        return _HULL_OBJECTS.get(self, lambda s: [fcl.CollisionObject(g, fcl.Transform())
                                                  for g in s.hull_geometries])


_PART_OBJECTS: "PerThreadCache[list]" = PerThreadCache(max_entries=8)
_HULL_OBJECTS: "PerThreadCache[list]" = PerThreadCache(max_entries=8)


def hand_shapes(hand: HandModel) -> HandShapes:
    """The shapes of ``hand``, built once per hand content (named cache ``hand_collision``)."""
    if not isinstance(hand, HandModel):
        raise InputError(f"hand: expected a grasp_apso.model.hands HandModel, got {type(hand).__name__}", "hand")
    return cached("hand_collision", (hand.source_hash, _digest(hand)), lambda: HandShapes(hand),
                  nbytes=lambda s: s.nbytes)


@numba.njit(cache=True, nogil=True)
def _may_reach(points, normals, offsets, within, out):
    for i in range(points.shape[0]):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        out[i] = True
        for k in range(normals.shape[0]):
            if normals[k, 0] * x + normals[k, 1] * y + normals[k, 2] * z - offsets[k] >= within:
                out[i] = False
                break


def _bounding_directions(normals: np.ndarray) -> np.ndarray:
    """(H, 3) unit directions: the 26 of a cube's faces, edges and corners, then up to
    :data:`BOUND_PLANES` - 26 of ``normals`` (M, 3), each the farthest from those chosen."""
    grid = np.array([(x, y, z) for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1) if (x, y, z) != (0, 0, 0)],
                    dtype=float)
    chosen = list(grid / np.linalg.norm(grid, axis=1, keepdims=True))
    gap = np.full(len(normals), np.inf)
    for d in chosen:
        gap = np.minimum(gap, np.linalg.norm(normals - d, axis=1))
    while len(chosen) < BOUND_PLANES and len(normals) and gap.max() > 1e-6:
        k = int(np.argmax(gap))
        chosen.append(normals[k])
        gap = np.minimum(gap, np.linalg.norm(normals - normals[k], axis=1))
    return np.ascontiguousarray(chosen, dtype=float)


def _edge_points(mesh: trimesh.Trimesh, spacing: float) -> np.ndarray:
    """(N, 3): the mesh's vertices and points along each unique edge at most ``spacing``
    apart (the edge's interior points only)."""
    v = np.asarray(mesh.vertices, dtype=float)
    edges = np.asarray(mesh.edges_unique, dtype=np.int64)
    a, b = v[edges[:, 0]], v[edges[:, 1]]
    cuts = np.ceil(np.linalg.norm(b - a, axis=1) / spacing).astype(np.int64)  # pieces per edge
    n = np.maximum(cuts - 1, 0)  # interior points per edge
    inner = np.repeat(np.arange(len(edges)), n)
    if len(inner) == 0:
        return v
    step = np.arange(len(inner)) - np.repeat(np.cumsum(n) - n, n) + 1  # 1 .. n along each edge
    t = (step / cuts[inner])[:, None]
    return np.vstack([v, a[inner] + t * (b[inner] - a[inner])])


class ObjectShape:
    """An object mesh for the exact checks: ``bvh`` (object frame), ``distance`` (its exact
    signed distance, :class:`MeshDistance`, negative inside), ``vertices`` (V, 3),
    ``edge_points`` (N, 3): the vertices and points along its edges.

    ``hull``: the convex hull as an ``fcl.Convex`` (a solid; GJK, some 20 times quicker
    than the BVH, off by up to ~0.4 mm); parts it finds within :data:`EXACT_WITHIN` are
    measured again exactly. ``convex``: the mesh is its own hull."""

    def __init__(self, mesh: trimesh.Trimesh, bvh: fcl.BVHModel | None = None):
        self.mesh = mesh
        self.vertices = np.asarray(mesh.vertices, dtype=float)
        self.convex = bool(mesh.is_watertight and mesh.is_convex)
        hull = mesh if self.convex else mesh.convex_hull
        faces = np.column_stack([np.full(len(hull.faces), 3), hull.faces]).ravel().astype(np.int32)
        self.hull = fcl.Convex(np.asarray(hull.vertices, dtype=float), len(hull.faces), faces)
        #: planes supporting the hull, n . x = o (unit normals (H, 3), offsets (H,)): a
        #: point's largest n . x - o is at most its distance outside the hull (so outside
        #: the object). The 26 box, edge and corner directions and up to BOUND_PLANES - 26
        #: of the hull's face normals, spread by farthest-point sampling: a few dozen planes
        #: cost microseconds per thousand points where the hull's thousands cost milliseconds.
        self.hull_normals = _bounding_directions(np.asarray(hull.face_normals, dtype=float))
        self.hull_offsets = (np.asarray(hull.vertices, dtype=float) @ self.hull_normals.T).max(axis=0)
        self.bvh = mesh_bvh(mesh) if bvh is None else bvh
        self.distance = MeshDistance(mesh)
        self.bounds = np.asarray(mesh.bounds, dtype=float)
        #: the vertices and points along every edge at most SAMPLE_SPACING apart (object
        #: frame): read in a touching part's signed distance, they catch an edge of the
        #: object (a mug's rim) pressing into a link's face between two vertices, which the
        #: vertices alone read short (LEAP's thumb on the mug: 1.31 mm deep, 0.07 mm at them)
        self.edge_points = _edge_points(mesh, SAMPLE_SPACING)
        #: a sphere holding the object (object frame): only samples inside it can be inside
        self.centre = 0.5 * (self.bounds[0] + self.bounds[1])
        self.radius = float(np.linalg.norm(self.vertices - self.centre, axis=1).max())
        self.nbytes = (BVH_BYTES_PER_TRIANGLE + 400) * len(mesh.faces) + 48 * len(mesh.vertices) \
            + 24 * len(self.edge_points)

    def hull_gap(self, points: np.ndarray) -> np.ndarray:
        """(N,) m: a lower bound of how far the points (N, 3), object frame, lie outside the
        object (<= 0 inside its convex hull)."""
        return (points @ self.hull_normals.T - self.hull_offsets).max(axis=1)

    def may_reach(self, points: np.ndarray, within: float) -> np.ndarray:
        """(N,) bool: the points (N, 3), object frame, that :meth:`hull_gap` does not show
        ``within`` (m) or farther outside (compiled, a point leaves at its first such plane)."""
        out = np.empty(len(points), dtype=np.bool_)
        _may_reach(np.ascontiguousarray(points, dtype=np.float64), self.hull_normals, self.hull_offsets,
                   float(within), out)
        return out

    def collision_objects(self) -> tuple[fcl.CollisionObject, fcl.CollisionObject]:
        """This thread's fcl objects of the BVH and of the hull, moved with setTransform."""
        return _OBJECT_OBJECTS.get(self, lambda s: (fcl.CollisionObject(s.bvh, fcl.Transform()),
                                                    fcl.CollisionObject(s.hull, fcl.Transform())))


_OBJECT_OBJECTS: "PerThreadCache[tuple]" = PerThreadCache(max_entries=8)


def object_shape(obj, field: str = "obj") -> ObjectShape:
    """An :class:`ObjectShape` of ``obj``: a GraspObject (cached by its mesh hash, its BVH
    shared with :func:`.collision.object_bvh`), a closed ``trimesh.Trimesh`` (cached by the
    sha256 of its arrays) or an ObjectShape (returned).

    A bare ``fcl.BVHModel`` is refused: fcl cannot tell how deep a link is inside it."""
    if isinstance(obj, ObjectShape):
        return obj
    if isinstance(obj, trimesh.Trimesh):
        if len(obj.faces) == 0:
            raise InputError(f"{field}: the mesh has no faces", field)
        key = hashlib.sha256(np.ascontiguousarray(obj.vertices, dtype=np.float64).tobytes()
                             + np.ascontiguousarray(obj.faces, dtype=np.int64).tobytes()).hexdigest()
        return cached("object_distance", ("trimesh", key), lambda: ObjectShape(obj), nbytes=lambda s: s.nbytes)
    if hasattr(obj, "mesh") and hasattr(obj, "mesh_hash"):
        return cached("object_distance", obj.mesh_hash, lambda: ObjectShape(obj.mesh, object_bvh(obj)),
                      nbytes=lambda s: s.nbytes)
    raise InputError(f"{field}: expected a GraspObject, a trimesh.Trimesh or an ObjectShape (a bare fcl.BVHModel "
                     f"cannot tell penetration depths), got {type(obj).__name__}", field)
