"""A general hand (:class:`grasp_apso.model.hands.HandModel`) in the grasp pictures of
:mod:`grasp_apso.tools.plotting`: its own collision geometry at the grasp (solid, each link in
its finger's colour) and at the pre-grasp (faint), in millimetres in the planning frame.

The paper's hand keeps its own drawing (:func:`grasp_apso.tools.scene_drawing.draw_hand`:
palm box, finger lines, pads).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.lines import Line2D
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from ..presentation.hand_geometry import finger_color, hand_triangles, link_colors
from ..presentation.palette import PRE_GRASP_ALPHA, rgb
from .view3d import shaded_colors

__all__ = ["hand_mesh_mm", "hand_axes", "draw_any_hand", "finger_legend", "pad_radius_mm"]

MM = 1000.0
_LIGHT = np.array([0.3, -0.5, 1.0])


def hand_mesh_mm(hand: Any, q: np.ndarray, root_pose: np.ndarray) -> dict[str, np.ndarray]:
    """link -> (T, 3, 3) triangles, mm, planning frame (the hand at ``q``, root at ``root_pose``)."""
    return {link: tris * MM for link, tris in hand_triangles(hand, q, root_pose).items()}


def hand_axes(hand: Any, root_pose: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(3, 3) columns x, y, z for the cameras, like the paper's palm frame: z the palm normal,
    x from the root toward the fingertips (perpendicular to z), y = z cross x."""
    root = np.asarray(root_pose, float)
    z = root[:3, :3] @ np.asarray(hand.palm_normal, float)
    z /= np.linalg.norm(z)
    poses = hand.link_transforms(np.asarray(q, float))
    tips = np.array([poses[f.tip_link][:3, 3] for f in hand.fingers])
    x = root[:3, :3] @ tips.mean(axis=0)
    x -= (x @ z) * z
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def pad_radius_mm(hand: Any) -> float:
    """The largest fingertip pad radius, mm (the picture's margin)."""
    return MM * max(float(f.pad_radius) for f in hand.fingers)


def draw_any_hand(ax, hand: Any, tris_by_link: dict[str, np.ndarray], faint: bool = False) -> None:
    """The hand's links as shaded translucent surfaces in their fingers' colours (faint:
    the pre-grasp, at :data:`~grasp_apso.presentation.palette.PRE_GRASP_ALPHA`)."""
    colors = link_colors(hand)
    alpha = PRE_GRASP_ALPHA if faint else 0.75
    by_color: dict[str, list[np.ndarray]] = {}
    for link, tris in tris_by_link.items():
        by_color.setdefault(colors.get(link, "#B3B3B3"), []).append(tris)
    for color, parts in by_color.items():
        tris = np.concatenate(parts)
        ax.add_collection3d(Poly3DCollection(
            tris, facecolors=shaded_colors(tris, np.array(rgb(color)), _LIGHT, alpha),
            edgecolors="none", zorder=2 if faint else 3))


def finger_legend(hand: Any) -> list[Line2D]:
    """Legend entries: one per finger of the hand, in its colour."""
    return [Line2D([], [], color=finger_color(f.name, i), linewidth=5, label=f.name)
            for i, f in enumerate(hand.fingers)]
