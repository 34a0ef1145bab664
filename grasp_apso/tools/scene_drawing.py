"""Artists of a grasp picture on a 3-D matplotlib axis, in millimetres: the object, the
hand (solid at the grasp, faint at the pre-grasp), the contacts, the table, the obstacles
and the approach arrow. Colours come from :mod:`grasp_apso.presentation.palette` (one palette
with the RViz markers). Used by :mod:`grasp_apso.tools.plotting`."""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from ..model.hand import FINGER_NAMES, HandModel
from ..model.scene import BOX, CYLINDER, SPHERE
from ..presentation.palette import (APPROACH_COLOR, COM_COLOR, CONTACT_COLOR, FINGER_COLORS, OBJECT_COLOR, OBSTACLE_COLOR,
                      PALM_COLOR, PRE_GRASP_ALPHA, SCENE_COLOR, rgb)
from .view3d import nice_length, shaded_colors, transform

__all__ = ["MM", "box_corners", "palm_corners", "draw_object", "draw_hand", "draw_contacts", "table_patch", "label_corner",
           "draw_table", "obstacle_surfaces", "draw_obstacles", "draw_approach"]

MM = 1000.0
_NORMAL_ARROW_MM = 14.0
_PALM_EDGE = "#8A6A4A"
_BOX_EDGES = [(a, b) for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]
_BOX_FACES = [(0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5)]


def box_corners(center: np.ndarray, half: np.ndarray) -> np.ndarray:
    """(8, 3) corners; corner k has sign bits (x, y, z) = bits (2, 1, 0) of k."""
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
    return np.asarray(center, float) + signs * np.asarray(half, float)


def palm_corners(hand: HandModel, wrist: np.ndarray) -> np.ndarray:
    """The palm box's corners (mm) at a wrist pose (4, 4, m)."""
    return transform(wrist, box_corners(np.asarray(hand.palm_center), np.asarray(hand.palm_half_extents))) * MM


def _sphere(center: np.ndarray, radius: float, n: int = 10) -> tuple[np.ndarray, ...]:
    u = np.linspace(0, 2 * np.pi, n + 1)
    v = np.linspace(0, np.pi, n // 2 + 1)
    return (center[0] + radius * np.outer(np.cos(u), np.sin(v)),
            center[1] + radius * np.outer(np.sin(u), np.sin(v)),
            center[2] + radius * np.outer(np.ones_like(u), np.cos(v)))


def draw_object(ax, tris: np.ndarray, com: np.ndarray, light: np.ndarray) -> None:
    """The object as a translucent shaded mesh (triangles in mm) and its centre of mass (+)."""
    ax.add_collection3d(Poly3DCollection(
        tris, facecolors=shaded_colors(tris, np.array(rgb(OBJECT_COLOR)), light, 0.35),
        edgecolors=(0.35, 0.38, 0.42, 0.12), linewidths=0.3, zorder=1))
    ax.scatter(*com, marker="+", s=60, color=COM_COLOR, zorder=5, depthshade=False)


def draw_hand(ax, joints: np.ndarray, palm: np.ndarray, hand: HandModel, faint: bool = False,
              touching: np.ndarray | None = None) -> list[tuple[Any, float]]:
    """The palm box and the fingers (joints (5, 4, 3) mm, palm corners (8, 3) mm).

    Solid: links as thick lines over their translucent volumes (returned as ``(line,
    diameter mm)`` for :func:`~grasp_apso.tools.view3d.zoom_to_content`), joint dots, pad
    spheres, links ``touching`` the object dashed. Faint (the pre-grasp): thin lines and
    the palm outline at :data:`~grasp_apso.presentation.palette.PRE_GRASP_ALPHA`.
    """
    alpha = PRE_GRASP_ALPHA if faint else 1.0
    for a, b in _BOX_EDGES:
        ax.plot(*np.stack([palm[a], palm[b]]).T, color=_PALM_EDGE, linewidth=0.9 if faint else 1.2,
                alpha=alpha, zorder=2)
    top = palm[[1, 3, 7, 5]]  # +z face (the side toward the object)
    ax.add_collection3d(Poly3DCollection([top], facecolors=[PALM_COLOR], alpha=0.45 * alpha,
                                         edgecolors="none", zorder=2))
    tubes: list[tuple[Any, float]] = []
    radii = np.asarray(hand.link_radii, float) * MM
    pad = hand.pad_radius * MM
    for f, name in enumerate(FINGER_NAMES):
        color = FINGER_COLORS[name]
        chain = joints[f]
        if faint:
            ax.plot(*chain.T, color=color, linewidth=2.0, alpha=alpha, solid_capstyle="round", zorder=2)
            ax.scatter(*chain[3], s=18, color=color, alpha=alpha, zorder=2, depthshade=False)
            continue
        for piece, radius in ((chain[:3], max(radii[0], radii[1])), (chain[2:], radii[2])):
            tube, = ax.plot(*piece.T, color=color, alpha=0.16, linewidth=1.0, solid_capstyle="round",
                            solid_joinstyle="round", zorder=2)
            tubes.append((tube, 2.0 * radius))
        ax.plot(*chain.T, color=color, linewidth=4.0, solid_capstyle="round", zorder=3)
        if touching is not None:
            for k in np.flatnonzero(touching[f]):
                ax.plot(*chain[k:k + 2].T, color="black", linewidth=1.3, linestyle=(0, (2, 1.5)), zorder=4)
        ax.scatter(*chain[:3].T, s=14, color="white", edgecolors=color, zorder=4, depthshade=False)
        ax.plot_surface(*_sphere(chain[3], pad), color=color, alpha=0.55, linewidth=0, shade=True, zorder=3)
    return tubes


def draw_contacts(ax, contacts: Sequence[Any], finger_colors: dict[str, str] | None = None) -> None:
    """Contacts (planning frame, m) as rings in the finger's colour with outward normals
    (``finger_colors``: finger name -> colour; default the paper hand's palette)."""
    colors = FINGER_COLORS if finger_colors is None else finger_colors
    for c in contacts:
        p = np.asarray(c.position, float) * MM
        n = np.asarray(c.normal, float)
        ax.scatter(*p, s=55, marker="o", color=colors.get(c.finger, "k"), edgecolors=CONTACT_COLOR,
                   linewidths=1.5, zorder=6, depthshade=False)
        ax.quiver(*p, *(n * _NORMAL_ARROW_MM), color=CONTACT_COLOR, linewidth=1.4, arrow_length_ratio=0.35,
                  zorder=6)


def _tangents(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.eye(3)[int(np.argmin(np.abs(n)))]
    u = np.cross(n, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


def table_patch(plane: np.ndarray, content: np.ndarray) -> np.ndarray:
    """(4, 3) corners (mm) of a square of the plane (a, b, c, d; m, normalised) under the
    content points (mm): centred below their middle, 1.3 times their spread along the plane."""
    n = np.asarray(plane[:3], float)
    d = float(plane[3]) * MM
    mid = 0.5 * (content.min(axis=0) + content.max(axis=0))
    centre = mid - (n @ mid + d) * n
    u, v = _tangents(n)
    half = 0.65 * max(float(np.ptp(content @ u)), float(np.ptp(content @ v)), 40.0)
    return np.array([centre + su * half * u + sv * half * v for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1))])


def label_corner(corners: np.ndarray, content: np.ndarray, direction: np.ndarray) -> int:
    """Index of the table corner (corners (4, 3), mm) whose label place the camera looking
    along ``direction`` (3,) sees farthest from everything drawn (content (k, 3) mm, the
    object's and the hand's points): the label covers neither the object nor the hand (a
    hand's forearm reaches out over one side of the table)."""
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    gaps = _label_places(np.asarray(corners, float))[:, None, :] - np.asarray(content, float)[None]   # (4, k, 3)
    gaps -= (gaps @ d)[..., None] * d                             # as the picture shows them
    return int(np.argmax(np.linalg.norm(gaps, axis=2).min(axis=1)))


def _label_places(corners: np.ndarray) -> np.ndarray:
    """(4, 3) mm: where the table's label may go, just inside each corner (corners (4, 3))."""
    return corners + 0.12 * (corners.mean(axis=0) - corners)


def draw_table(ax, corners: np.ndarray, label_at: int = 0) -> None:
    """A translucent wooden plane patch with a grid (so its tilt reads at a glance) and a
    darker rim, labelled near corner ``label_at``."""
    ax.add_collection3d(Poly3DCollection([corners], facecolors=[(*rgb(SCENE_COLOR), 0.22)],
                                         edgecolors=[(*rgb(SCENE_COLOR), 0.9)], linewidths=1.6, zorder=0))
    side = float(np.linalg.norm(corners[1] - corners[0]))
    step = nice_length(side)
    u = (corners[1] - corners[0]) / side
    v = (corners[3] - corners[0]) / side
    for t in np.arange(step, side - 1e-6, step):
        for a, b in ((corners[0] + t * u, corners[3] + t * u), (corners[0] + t * v, corners[1] + t * v)):
            ax.plot(*np.stack([a, b]).T, color=SCENE_COLOR, linewidth=0.5, alpha=0.45, zorder=0)
    ax.text(*_label_places(corners)[label_at], "table", color=SCENE_COLOR, fontsize=9, fontweight="bold", zorder=7)


def obstacle_surfaces(obstacle, roi_lo: np.ndarray, roi_hi: np.ndarray) -> list[np.ndarray]:
    """Surface points (mm) of an obstacle: box -> its 8 corners (an axis-aligned box is clipped
    to the region of interest, so a wall does not swamp the picture); sphere / cylinder -> grids."""
    pose = np.asarray(obstacle.pose, float)
    dims = np.asarray(obstacle.dimensions, float) * MM
    centre = pose[:3, 3] * MM
    if obstacle.kind == BOX:
        if np.allclose(np.abs(pose[:3, :3]), np.eye(3), atol=1e-9):
            lo = np.maximum(centre - dims / 2, roi_lo)
            hi = np.minimum(centre + dims / 2, roi_hi)
            if np.any(hi <= lo):
                return []
            return [box_corners((lo + hi) / 2, (hi - lo) / 2)]
        return [centre + box_corners(np.zeros(3), dims / 2) @ pose[:3, :3].T]
    if obstacle.kind == SPHERE:
        x, y, z = _sphere(centre, dims[0], 16)
        return [np.stack([x, y, z], axis=-1)]
    if obstacle.kind == CYLINDER:
        h, r = dims
        t = np.linspace(0, 2 * np.pi, 25)
        zs = np.array([-h / 2, h / 2])
        local = np.stack([np.outer(np.ones(2), r * np.cos(t)), np.outer(np.ones(2), r * np.sin(t)),
                          np.outer(zs, np.ones_like(t))], axis=-1)
        return [local @ pose[:3, :3].T + centre]
    return []


def draw_obstacles(ax, scene, roi_lo: np.ndarray, roi_hi: np.ndarray) -> np.ndarray:
    """Draw every obstacle translucent grey; return their drawn points (N, 3) mm."""
    pts = [np.zeros((0, 3))]
    for o in scene.obstacles:
        for surface in obstacle_surfaces(o, roi_lo, roi_hi):
            if o.kind == BOX:
                faces = [surface[list(f)] for f in _BOX_FACES]
                ax.add_collection3d(Poly3DCollection(faces, facecolors=[(*rgb(OBSTACLE_COLOR), 0.25)],
                                                     edgecolors=[(*rgb(OBSTACLE_COLOR), 0.9)], linewidths=1.0,
                                                     zorder=1))
                pts.append(surface)
            else:
                ax.plot_surface(surface[..., 0], surface[..., 1], surface[..., 2], color=OBSTACLE_COLOR,
                                alpha=0.3, linewidth=0, shade=True, zorder=1)
                if o.kind == CYLINDER:
                    for rim in surface:
                        ax.plot(*rim.T, color=OBSTACLE_COLOR, linewidth=1.0, zorder=1)
                pts.append(surface.reshape(-1, 3))
    return np.vstack(pts)


def draw_approach(ax, start: np.ndarray, end: np.ndarray, label: str | None = None) -> None:
    """The approach: a thick arrow (mm) from the pre-grasp palm centre to the grasp's."""
    ax.quiver(*start, *(end - start), color=APPROACH_COLOR, linewidth=3.0, arrow_length_ratio=0.22, zorder=6)
    if label:
        ax.text(*(start - 0.25 * (end - start)), label, color=APPROACH_COLOR, fontsize=9, ha="center",
                va="center", fontweight="bold", zorder=7)
