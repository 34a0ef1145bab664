"""The scene around the object: support planes and obstacles the hand must never touch.

A :class:`Scene` is immutable and lives in one frame (the planning frame on the API; the
planner moves it into the object frame with :meth:`Scene.transformed`). Conventions
follow ``shape_msgs`` (DESIGN.md, "Scene"):

- a support plane ``(a, b, c, d)``: the solid side is ``a x + b y + c z + d < 0``, so
  ``(a, b, c)`` points into free space (a table top: normal up). Stored normalised.
- obstacles (``shape_msgs/SolidPrimitive``): ``BOX`` dimensions ``[x, y, z]`` (full sizes),
  ``SPHERE`` ``[radius]``, ``CYLINDER`` ``[height, radius]`` with its axis along the local
  z, each centred at its pose.

:meth:`Scene.signed_distance` is the plain numpy distance (negative inside), for checks
off the hot path; the decoder uses the compiled kernels over :meth:`Scene.packed`. Bad
input raises :class:`~grasp_apso.errors.SceneError` naming the field and index.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Iterable, Sequence

import numpy as np

from ..errors import SceneError

__all__ = ["Scene", "Obstacle", "BOX", "SPHERE", "CYLINDER", "PRIMITIVE_NAMES", "MAX_SINK"]

#: ``shape_msgs/SolidPrimitive`` type constants.
BOX, SPHERE, CYLINDER = 1, 2, 3
PRIMITIVE_NAMES: dict[int, str] = {BOX: "BOX", SPHERE: "SPHERE", CYLINDER: "CYLINDER"}
_DIMENSIONS: dict[int, int] = {BOX: 3, SPHERE: 1, CYLINDER: 2}
#: An object may rest on a support plane but not sink into it by more than this (m).
MAX_SINK = 0.005
#: An object may touch an obstacle but not penetrate it by more than this (m).
MAX_OBSTACLE_PENETRATION = 0.001
#: Largest number of planes / obstacles a scene may hold (bounds every scene loop).
MAX_PLANES = 16
MAX_OBSTACLES = 64


@dataclass(frozen=True)
class Obstacle:
    """One solid primitive: ``kind`` (BOX/SPHERE/CYLINDER), ``dimensions`` as in
    ``shape_msgs/SolidPrimitive`` (m), ``pose`` (4, 4) of its centre."""

    kind: int
    dimensions: tuple[float, ...]
    pose: np.ndarray = field(repr=False)

    @property
    def name(self) -> str:
        return PRIMITIVE_NAMES[self.kind]


def _readonly(a: Any, shape: tuple[int, ...]) -> np.ndarray:
    out = np.array(a, dtype=np.float64).reshape(shape)
    out.flags.writeable = False
    return out


@dataclass(frozen=True, eq=False)
class Scene:
    """Support planes (K, 4), normalised, and obstacles; see the module docstring."""

    planes: np.ndarray = field(default_factory=lambda: _readonly(np.zeros((0, 4)), (0, 4)))
    obstacles: tuple[Obstacle, ...] = ()

    # ------------------------------------------------------------------ building
    @classmethod
    def from_primitives(
        cls,
        planes: Iterable[Sequence[float]] = (),
        obstacles: Iterable[tuple[int, Sequence[float]]] = (),
        obstacle_poses: Iterable[np.ndarray] = (),
    ) -> "Scene":
        """Validate and build a scene.

        Parameters
        ----------
        planes : iterable of (a, b, c, d)
            Field ``support_planes``.
        obstacles : iterable of (type, dimensions)
            Field ``obstacles`` (``shape_msgs/SolidPrimitive`` type and dimensions, m).
        obstacle_poses : iterable of (4, 4) float
            Field ``obstacle_poses``: one rigid transform per obstacle.
        """
        plane_list = list(planes)
        if len(plane_list) > MAX_PLANES:
            raise SceneError(f"support_planes: {len(plane_list)} planes, at most {MAX_PLANES}")
        rows = []
        for i, coeffs in enumerate(plane_list):
            try:
                c = np.asarray(coeffs, dtype=np.float64).reshape(4)
            except (TypeError, ValueError):
                raise SceneError(f"support_planes[{i}]: expected 4 coefficients a, b, c, d") from None
            if not np.all(np.isfinite(c)):
                raise SceneError(f"support_planes[{i}]: coefficients must be finite, got {c.tolist()}")
            norm = float(np.linalg.norm(c[:3]))
            if norm < 1e-9:
                raise SceneError(f"support_planes[{i}]: the normal (a, b, c) is zero")
            rows.append(c / norm)
        obs_list = list(obstacles)
        pose_list = list(obstacle_poses)
        if len(obs_list) != len(pose_list):
            raise SceneError(
                f"obstacles: {len(obs_list)} obstacles but {len(pose_list)} obstacle_poses "
                "(they must have the same length)", "obstacle_poses")
        if len(obs_list) > MAX_OBSTACLES:
            raise SceneError(f"obstacles: {len(obs_list)} obstacles, at most {MAX_OBSTACLES}")
        built = []
        for i, ((kind, dims), pose) in enumerate(zip(obs_list, pose_list)):
            built.append(_obstacle(i, kind, dims, pose))
        return cls(planes=_readonly(np.array(rows).reshape(-1, 4), (len(rows), 4)), obstacles=tuple(built))

    @classmethod
    def table_under(cls, points: np.ndarray, normal: Sequence[float] = (0.0, 0.0, 1.0)) -> "Scene":
        """A support plane with ``normal`` touching the lowest of ``points`` (N, 3)."""
        n = np.asarray(normal, dtype=float)
        n = n / np.linalg.norm(n)
        lowest = float(np.min(np.asarray(points, dtype=float) @ n))
        return cls.from_primitives(planes=[(*n, -lowest)])

    # ------------------------------------------------------------------ queries
    @property
    def is_empty(self) -> bool:
        return len(self.planes) == 0 and not self.obstacles

    def with_obstacles(self, obstacles: Iterable[Obstacle]) -> "Scene":
        """This scene plus more obstacles."""
        return Scene(planes=self.planes, obstacles=self.obstacles + tuple(obstacles))

    def transformed(self, transform: np.ndarray) -> "Scene":
        """The same scene expressed in another frame: ``transform`` (4, 4) maps this
        scene's frame to the new one."""
        t = np.asarray(transform, dtype=float)
        rot, trans = t[:3, :3], t[:3, 3]
        planes = np.empty_like(self.planes)
        if len(self.planes):
            n = self.planes[:, :3] @ rot.T
            # a point p' = R p + t lies on the plane when n.p + d = 0 -> n'.p' + d' = 0
            planes[:, :3] = n
            planes[:, 3] = self.planes[:, 3] - n @ trans
        obstacles = tuple(Obstacle(o.kind, o.dimensions, _readonly(t @ o.pose, (4, 4))) for o in self.obstacles)
        return Scene(planes=_readonly(planes, planes.shape), obstacles=obstacles)

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Least signed distance (m, negative inside) from points (N, 3) to every plane's
        solid half-space and every obstacle; ``inf`` for an empty scene."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        out = np.full(len(p), np.inf)
        if len(self.planes):
            out = np.minimum(out, (p @ self.planes[:, :3].T + self.planes[:, 3]).min(axis=1))
        for o in self.obstacles:
            local = (p - o.pose[:3, 3]) @ o.pose[:3, :3]
            out = np.minimum(out, _primitive_distance(o.kind, o.dimensions, local))
        return out

    def packed(self) -> dict[str, np.ndarray]:
        """Flat arrays for the compiled kernels (all float64, C order).

        planes (K, 4); boxes: box_inv (B, 4, 4) world->box, box_half (B, 3);
        spheres: sphere_center (S, 3), sphere_radius (S,); cylinders: cyl_inv (C, 4, 4),
        cyl_radius (C,), cyl_half_height (C,).
        """
        def inv(m: np.ndarray) -> np.ndarray:
            out = np.eye(4)
            out[:3, :3] = m[:3, :3].T
            out[:3, 3] = -m[:3, :3].T @ m[:3, 3]
            return out

        boxes = [o for o in self.obstacles if o.kind == BOX]
        spheres = [o for o in self.obstacles if o.kind == SPHERE]
        cyls = [o for o in self.obstacles if o.kind == CYLINDER]
        return {
            "planes": np.ascontiguousarray(self.planes, dtype=np.float64).reshape(-1, 4),
            "box_inv": np.array([inv(o.pose) for o in boxes]).reshape(-1, 4, 4),
            "box_half": np.array([np.asarray(o.dimensions) / 2 for o in boxes]).reshape(-1, 3),
            "sphere_center": np.array([o.pose[:3, 3] for o in spheres]).reshape(-1, 3),
            "sphere_radius": np.array([o.dimensions[0] for o in spheres]).reshape(-1),
            "cyl_inv": np.array([inv(o.pose) for o in cyls]).reshape(-1, 4, 4),
            "cyl_radius": np.array([o.dimensions[1] for o in cyls]).reshape(-1),
            "cyl_half_height": np.array([o.dimensions[0] / 2 for o in cyls]).reshape(-1),
        }

    def check_object_placement(self, vertices: np.ndarray, field: str = "object_pose") -> None:
        """Raise :class:`SceneError` when an object (its vertices (N, 3) in this scene's
        frame) sinks more than :data:`MAX_SINK` into a support plane or penetrates an
        obstacle (more than :data:`MAX_OBSTACLE_PENETRATION`)."""
        v = np.asarray(vertices, dtype=float).reshape(-1, 3)
        for i, plane in enumerate(self.planes):
            depth = -float((v @ plane[:3] + plane[3]).min())
            if depth > MAX_SINK:
                raise SceneError(
                    f"{field}: the object sinks {depth * 1000:.1f} mm into support_planes[{i}] "
                    f"(at most {MAX_SINK * 1000:.0f} mm; it may rest on it)", field)
        for i, o in enumerate(self.obstacles):
            local = (v - o.pose[:3, 3]) @ o.pose[:3, :3]
            depth = -float(_primitive_distance(o.kind, o.dimensions, local).min())
            if depth > MAX_OBSTACLE_PENETRATION:
                raise SceneError(
                    f"{field}: the object penetrates obstacles[{i}] ({o.name}) by "
                    f"{depth * 1000:.1f} mm", field)


def _obstacle(i: int, kind: Any, dims: Any, pose: Any) -> Obstacle:
    if isinstance(kind, bool) or not isinstance(kind, (int, np.integer)) or int(kind) not in _DIMENSIONS:
        raise SceneError(
            f"obstacles[{i}]: unknown primitive type {kind!r} (expected BOX=1, SPHERE=2 or CYLINDER=3)")
    kind = int(kind)
    try:
        d = np.asarray(dims, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise SceneError(f"obstacles[{i}]: dimensions must be numbers") from None
    want = _DIMENSIONS[kind]
    if d.size != want:
        raise SceneError(f"obstacles[{i}]: a {PRIMITIVE_NAMES[kind]} needs {want} dimension(s), got {d.size}")
    if not np.all(np.isfinite(d)) or np.any(d <= 0):
        raise SceneError(f"obstacles[{i}]: dimensions must be positive and finite, got {d.tolist()}")
    m = np.asarray(pose, dtype=np.float64)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise SceneError(f"obstacle_poses[{i}]: expected a finite (4, 4) transform", "obstacle_poses")
    if not np.allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3), atol=1e-6) or np.linalg.det(m[:3, :3]) < 0:
        raise SceneError(f"obstacle_poses[{i}]: the rotation is not a rotation", "obstacle_poses")
    return Obstacle(kind, tuple(float(x) for x in d), _readonly(m, (4, 4)))


def _primitive_distance(kind: int, dims: tuple[float, ...], local: np.ndarray) -> np.ndarray:
    """Signed distance (N,) of points in the primitive's frame (negative inside)."""
    if kind == SPHERE:
        return np.linalg.norm(local, axis=1) - dims[0]
    if kind == BOX:
        q = np.abs(local) - np.asarray(dims) / 2
        outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
        inside = np.minimum(q.max(axis=1), 0.0)
        return outside + inside
    height, radius = dims
    radial = np.linalg.norm(local[:, :2], axis=1) - radius
    axial = np.abs(local[:, 2]) - height / 2
    q = np.stack([radial, axial], axis=1)
    return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)

