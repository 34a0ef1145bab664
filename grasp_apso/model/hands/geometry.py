"""One collision geometry of a hand link: a primitive or a mesh, placed in the link frame.

:class:`LinkGeometry` is what the loaders produce from a URDF ``<collision>`` or an MJCF
``geom`` and what the sphere cover (:mod:`.spheres`) and the pads (:mod:`.pads`) work on.

- ``signed_distance`` is exact: analytic for the primitives; for a mesh, the exact
  distance to its triangles with the sign from the closest feature's pseudo-normal
  (:mod:`.mesh_distance`); a mesh of several closed shells is their union (the least
  signed distance over them), as the shells of CAD exports overlap; a shell wholly inside
  a larger one adds nothing and is left out. A mesh that is not watertight has no inside, so its convex
  hull stands for it (``source`` says so): the hull is what the fingers cannot enter.
- ``to_trimesh`` tessellates the primitives finely (curved surfaces at most 0.12 % of
  the radius inside the true surface, watertight), in the link frame.

Units: metres. Frames: ``origin`` is the pose of the geometry frame in the link frame;
cylinders and capsules lie along the geometry frame's z axis.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import trimesh

from ...errors import HandDescriptionError
from .mesh_distance import MeshDistance

__all__ = ["LinkGeometry", "KINDS", "primitive_sizes"]

#: The kinds of geometry and the number of size values each takes.
KINDS: dict[str, int] = {"box": 3, "sphere": 1, "cylinder": 2, "capsule": 2, "mesh": 0}
#: Tessellation of curved primitives in ``to_trimesh`` (sections around, latitudes per
#: capsule cap, icosphere level): inside the true surface by at most 0.12 % of the radius
#: (a 10 mm radius: 12 um), and watertight.
_SECTIONS = 96
_CAPSULE_LATITUDES = 16
_ICO_LEVEL = 4
#: No collision geometry of a hand (a forearm link included) is this large (m): one that
#: is was drawn in other units than its file says (HOPE-Jr's STL files, scaled 0.1, come
#: out 27 m long per fingertip).
MAX_GEOMETRY_SPAN = 1.0
#: Decimals (m) a mesh's points are rounded to when their convex hull comes out open.
_HULL_DIGITS = (6, 5)
#: Components of a mesh with less volume than this are flat sheets, not solids (m^3).
_FLAT_VOLUME = 1e-12
#: A shell's points within this of a larger shell's surface count as inside it (m).
_CONTAINED = 1e-7
#: Tolerance of the rigid-transform check on ``origin``.
_RIGID_TOL = 1e-6


def primitive_sizes(kind: str) -> int:
    """The number of ``size`` values a kind takes (``HandDescriptionError`` if unknown)."""
    if kind not in KINDS:
        raise HandDescriptionError(f"collision: unknown geometry kind {kind!r} (expected one of {sorted(KINDS)})",
                                   field="collision")
    return KINDS[kind]


@dataclass(frozen=True, eq=False)
class LinkGeometry:
    """One collision geometry of a link, in the link frame (immutable).

    Attributes
    ----------
    kind : str
        ``"box" | "sphere" | "cylinder" | "capsule" | "mesh"``.
    size : tuple of float, m
        box: half extents (3,); sphere: (r,); cylinder, capsule: (radius, half_length)
        along the geometry's z (a capsule's half_length excludes its caps); mesh: ().
    origin : (4, 4) float
        Pose of the geometry frame in the link frame (rigid; stored read-only).
    mesh : trimesh.Trimesh or None
        kind ``"mesh"``: vertices in the geometry frame, scale applied. Replaced by its
        convex hull when it is not watertight.
    source : str
        Where it came from (file, element), for messages.
    """

    kind: str
    size: tuple[float, ...]
    origin: np.ndarray = field(default_factory=lambda: np.eye(4))
    mesh: trimesh.Trimesh | None = None
    source: str = ""

    def __post_init__(self) -> None:
        where = self.where
        count = primitive_sizes(self.kind)
        try:
            size = tuple(float(s) for s in self.size)
        except (TypeError, ValueError):
            raise HandDescriptionError(f"collision: {where}: size {self.size!r} is not numbers",
                                       field="collision") from None
        if len(size) != count or not all(np.isfinite(s) and s > 0 for s in size):
            raise HandDescriptionError(
                f"collision: {where}: {self.kind} size needs {count} positive values, got {self.size!r}",
                field="collision")
        object.__setattr__(self, "size", size)
        origin = np.array(self.origin, dtype=np.float64)
        if origin.shape != (4, 4) or not np.all(np.isfinite(origin)):
            raise HandDescriptionError(f"collision: {where}: origin must be a finite (4, 4) transform",
                                       field="collision")
        rot = origin[:3, :3]
        if (np.abs(rot @ rot.T - np.eye(3)).max() > _RIGID_TOL or abs(np.linalg.det(rot) - 1.0) > _RIGID_TOL
                or np.abs(origin[3] - [0, 0, 0, 1]).max() > _RIGID_TOL):
            raise HandDescriptionError(f"collision: {where}: origin is not a rigid transform (scale belongs "
                                       "to the mesh)", field="collision")
        origin.setflags(write=False)
        object.__setattr__(self, "origin", origin)
        if self.kind == "mesh":
            object.__setattr__(self, "mesh", self._checked_mesh(where))
        elif self.mesh is not None:
            raise HandDescriptionError(f"collision: {where}: a {self.kind} takes no mesh", field="collision")

    def check_hand_part(self) -> None:
        """HandDescriptionError when the geometry is larger than any part of a hand
        (:data:`MAX_GEOMETRY_SPAN`): a file whose units are not what it says. (Scene
        obstacles are LinkGeometry too, and may be any size.)"""
        span = self._span()
        if span > MAX_GEOMETRY_SPAN:
            raise HandDescriptionError(
                f"collision: {self.where}: {span:.3g} m across, more than any part of a hand "
                f"({MAX_GEOMETRY_SPAN:g} m): are its units the file's? (a mesh drawn in mm needs the scale 0.001)",
                field="collision")

    def _span(self) -> float:
        """The largest extent of the geometry (m), without tessellating a primitive."""
        if self.kind == "mesh":
            return float(np.max(self.mesh.extents))
        if self.kind == "box":
            return 2.0 * max(self.size)
        if self.kind == "sphere":
            return 2.0 * self.size[0]
        radius, half = self.size
        return 2.0 * max(radius, half + (radius if self.kind == "capsule" else 0.0))

    def _checked_mesh(self, where: str) -> trimesh.Trimesh:
        mesh = self.mesh
        if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
            raise HandDescriptionError(f"collision: {where}: kind mesh needs a trimesh.Trimesh with faces",
                                       field="collision")
        if not np.all(np.isfinite(mesh.vertices)):
            raise HandDescriptionError(f"collision: {where}: the mesh has non-finite vertices", field="collision")
        mesh = mesh.copy()
        mesh.merge_vertices()
        mesh.update_faces(mesh.nondegenerate_faces())
        if not mesh.is_watertight or not mesh.is_winding_consistent:
            try:
                hull = mesh.convex_hull
                for digits in _HULL_DIGITS:
                    if hull.is_watertight:
                        break
                    # Points a hair off the hull's edges (Tesollo DG-5F's STL files) make qhull
                    # drop a sliver facet and the hull comes out open: rounded to 1 um, then
                    # 10 um, it closes.
                    hull = trimesh.convex.convex_hull(np.round(np.asarray(mesh.vertices), digits))
            except Exception as exc:  # qhull refuses flat or degenerate point sets
                raise HandDescriptionError(f"collision: {where}: the mesh is not watertight and has no convex "
                                           f"hull ({type(exc).__name__})", field="collision") from None
            if hull.volume <= 0 or not hull.is_watertight:
                raise HandDescriptionError(f"collision: {where}: the mesh is flat (no volume)", field="collision")
            object.__setattr__(self, "source", f"{self.source} (not watertight: its convex hull)".strip())
            mesh = hull
        elif mesh.volume < 0:
            mesh = _outward(mesh)
        return mesh

    # ----------------------------------------------------------------------------------
    @property
    def where(self) -> str:
        """``source`` or the kind, for messages."""
        return self.source or f"a {self.kind}"

    @cached_property
    def _local_mesh(self) -> trimesh.Trimesh:
        """The surface in the geometry frame."""
        if self.kind == "mesh":
            return self.mesh
        if self.kind == "box":
            return trimesh.creation.box(extents=2.0 * np.asarray(self.size))
        if self.kind == "sphere":
            return trimesh.creation.icosphere(subdivisions=_ICO_LEVEL, radius=self.size[0])
        if self.kind == "cylinder":
            return trimesh.creation.cylinder(radius=self.size[0], height=2.0 * self.size[1], sections=_SECTIONS)
        return _capsule_mesh(*self.size)

    @cached_property
    def _link_mesh(self) -> trimesh.Trimesh:
        mesh = self._local_mesh.copy()
        mesh.apply_transform(self.origin)
        return mesh

    @cached_property
    def _mesh_distance(self) -> tuple[MeshDistance, ...]:
        """One exact distance per closed component (a collision mesh is often several
        overlapping shells: the solid is their union; flat shells have no inside)."""
        with np.errstate(invalid="ignore", divide="ignore"):  # a flat shell's centre of mass is 0 / 0
            parts = [part for part in self.mesh.split(only_watertight=False) if abs(part.volume) > _FLAT_VOLUME]
        # An inner shell facing inward (a CAD export's cavity: a screw hole, engraved
        # text) is turned outward: its solid lies within the outer shell's. Rebuilt from
        # the reversed faces, not trimesh's ``invert()``: a part of ``split`` keeps its
        # parent's face normals cached, and ``invert()`` left them facing inward (trimesh
        # 5.2), so every point read inside (the XHAND's thumb tip: no pad found).
        parts = [_outward(part) if part.volume < 0 else part for part in parts]
        return _union_parts(parts) or (MeshDistance(self.mesh),)

    def to_trimesh(self) -> trimesh.Trimesh:
        """The surface in the LINK frame (a fresh copy: the caller may change it)."""
        return self._link_mesh.copy()

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) axis-aligned bounds in the link frame, m."""
        return np.asarray(self._link_mesh.bounds)

    def to_local(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) link frame -> (N, 3) geometry frame."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        return (pts - self.origin[:3, 3]) @ self.origin[:3, :3]

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Exact signed distance to the surface, > 0 outside.

        points : (N, 3) float, m, link frame -> (N,) float, m
        """
        p = self.to_local(points)
        if self.kind == "box":
            q = np.abs(p) - np.asarray(self.size)
            outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
            return outside + np.minimum(q.max(axis=1), 0.0)
        if self.kind == "sphere":
            return np.linalg.norm(p, axis=1) - self.size[0]
        if self.kind == "cylinder":
            radius, half = self.size
            q = np.stack([np.hypot(p[:, 0], p[:, 1]) - radius, np.abs(p[:, 2]) - half], axis=1)
            return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)
        if self.kind == "capsule":
            radius, half = self.size
            axial = np.clip(p[:, 2], -half, half)
            return np.linalg.norm(p - np.outer(axial, [0.0, 0.0, 1.0]), axis=1) - radius
        parts = self._mesh_distance
        out = parts[0](p)
        for part in parts[1:]:
            np.minimum(out, part(p), out=out)
        return out


def _union_parts(parts: list[trimesh.Trimesh]) -> tuple[MeshDistance, ...]:
    """The exact distances of the closed shells ``parts`` (wound outward) whose union is the
    solid, less every shell that lies wholly inside a larger one (its vertices and face
    centres inside it): it adds nothing to the union, and a cavity shell that folds
    through itself (the Wuji hand's phalanx STL files) reads points outside the link as
    inside (the pseudo-normal sign is exact only for a shell that does not cross itself),
    which its larger shell's distance would then not outvote (the union takes the least)."""
    kept: list[MeshDistance] = []
    for part in sorted(parts, key=lambda m: -abs(m.volume)):
        probe = np.concatenate([np.asarray(part.vertices), np.asarray(part.triangles_center)])
        if any(np.all(inside(probe) <= _CONTAINED) for inside in kept):
            continue
        kept.append(MeshDistance(part))
    return tuple(kept)


def _outward(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """A closed shell wound inward, as a fresh mesh wound outward (nothing cached)."""
    return trimesh.Trimesh(np.asarray(mesh.vertices), np.ascontiguousarray(np.asarray(mesh.faces)[:, ::-1]),
                           process=False)


def _capsule_mesh(radius: float, half_length: float) -> trimesh.Trimesh:
    """A watertight capsule along z: the convex hull of rings on its two caps (trimesh's
    own capsule loses watertightness at small radii when it merges its pole vertices)."""
    latitude = np.linspace(0.0, 0.5 * np.pi, _CAPSULE_LATITUDES + 1)[:-1]
    around = np.linspace(0.0, 2.0 * np.pi, _SECTIONS, endpoint=False)
    lat, ang = (a.ravel() for a in np.meshgrid(latitude, around, indexing="ij"))
    ring = radius * np.stack([np.cos(lat) * np.cos(ang), np.cos(lat) * np.sin(ang), np.sin(lat)], axis=1)
    poles = [[0.0, 0.0, half_length + radius], [0.0, 0.0, -half_length - radius]]
    points = np.vstack([ring + [0.0, 0.0, half_length], ring * [1.0, 1.0, -1.0] - [0.0, 0.0, half_length], poles])
    return trimesh.convex.convex_hull(points)
