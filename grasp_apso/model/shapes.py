"""The paper's four test objects as procedural triangle meshes (section 5).

Each builder returns raw ``(vertices, triangles)`` arrays in metres, the sphere, cube
and barrel centred on the origin; :func:`grasp_apso.model.builtin.builtin` validates them and
moves the centre of mass to the origin (it shifts the fish along x). The sizes are the
paper's:

- :func:`sphere` -- icosphere, diameter :data:`SPHERE_DIAMETER` (0.05 m);
- :func:`cube` -- box, edge :data:`CUBE_EDGE` (0.07 m);
- :func:`barrel` -- along z, :data:`BARREL_LENGTH` (0.11 m) long, :data:`BARREL_DIAMETER`
  (0.03 m) wide in the middle, 10 % bulge (:data:`BARREL_BULGE`);
- :func:`fish` -- :data:`FISH_LENGTH` x :data:`FISH_WIDTH` x :data:`FISH_HEIGHT`
  (0.29 x 0.06 x 0.07 m), head toward +x, back toward +z.

All four are closed meshes wound with outward normals.
"""

from __future__ import annotations

import numpy as np
import trimesh

__all__ = [
    "SPHERE_DIAMETER",
    "CUBE_EDGE",
    "BARREL_LENGTH",
    "BARREL_DIAMETER",
    "BARREL_BULGE",
    "FISH_LENGTH",
    "FISH_WIDTH",
    "FISH_HEIGHT",
    "sphere",
    "cube",
    "barrel",
    "fish",
]

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


def sphere() -> tuple[np.ndarray, np.ndarray]:
    """Icosphere (subdivisions 3) of diameter 0.05 m centred at the origin.

    Returns
    -------
    vertices : (642, 3) float, m
    triangles : (1280, 3) int
    """
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=SPHERE_DIAMETER / 2.0)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def cube() -> tuple[np.ndarray, np.ndarray]:
    """Cube of edge 0.07 m centred at the origin, faces normal to the object axes.

    Returns
    -------
    vertices : (8, 3) float, m
    triangles : (12, 3) int
    """
    mesh = trimesh.creation.box(extents=(CUBE_EDGE, CUBE_EDGE, CUBE_EDGE))
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def barrel() -> tuple[np.ndarray, np.ndarray]:
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


def fish() -> tuple[np.ndarray, np.ndarray]:
    """A procedural fish: 0.29 m long (x) x 0.06 m wide (y) x 0.07 m high (z).

    A lofted body of elliptical cross-sections, head toward +x, back toward +z: a
    streamlined (NACA 00xx) profile from the blunt nose to a narrow caudal peduncle at
    78 % of the length, then a thin tail fin that flares to about 0.06 m high with a
    forked trailing edge (its top and bottom lobes reach 45 % of the fin length further
    back than its middle). The nose closes with a fan to the tip, the trailing edge with
    a thin strip. The nose tip is at x = 0.29 m, the tail lobe tips at x = 0:
    :func:`grasp_apso.model.builtin.builtin` shifts the vertices along x to put the centre of
    mass at the origin (the shape is symmetric about y = 0 and z = 0).

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
