"""A picture to check a newly loaded hand: open and closed, with what was derived.

:func:`draw_hand` writes a PNG with four 3-D panels: the hand open and the hand closed
(each closing joint 80 % of the way to its limit), each from two cameras, fingers up: in
front of the palm (its normal points out of the picture) and from the side (the fingers'
curl in profile). Each panel shows

- the spheres (and capsules) that stand for the links in the search, translucent in the colour of the
  finger the link belongs to (tan for the palm and the links no finger moves);
- over them, every link's exact collision geometry as a light grey translucent surface
  (the spheres' outline beyond it is their stray);
- each finger's pad as a dot in its colour (black edge);
- the palm normal as an arrow from the root link's origin;
- a metric scale bar and the root frame's axes.

Links above the root (an arm, a forearm) are left out; the title counts the spheres of
the links drawn.

The title names the hand, its fingers (and which is the thumb) and the number of spheres
with their largest stray. Built without pyplot (Agg canvas), like
:mod:`grasp_apso.tools.plotting`. Uses only the general hand model's public attributes
(:class:`grasp_apso.model.hands.model.HandModel`). Lengths in millimetres.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
import mpl_toolkits.mplot3d  # noqa: F401  (registers the "3d" projection)
import trimesh
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from ..presentation.hand_geometry import EXTRA_FINGER_COLORS, finger_color
from ..presentation.palette import CONTACT_COLOR, PALM_COLOR, rgb
from .view3d import (decimate_for_drawing, framing, nice_length, save, scale_bar_and_triad, screen_axes,
                     shaded_colors, transform, view_angles, zoom_to_content)

__all__ = ["draw_hand", "finger_color", "EXTRA_FINGER_COLORS"]

MM = 1000.0
GEOMETRY_COLOR = "#B4B4B4"
#: Triangles drawn per link's exact geometry at most (decimated beyond).
_LINK_TRIANGLES = 600
#: Icosphere level of a drawn sphere by the number of spheres in the picture.
_SPHERE_LEVEL_UNDER = ((600, 1), (10**9, 0))
_CLOSED_FRACTION = 0.8
_SPHERE_ALPHA = 0.2
_GEOMETRY_ALPHA = 0.2


def _default_posture(hand: Any, fraction: float) -> np.ndarray:
    """Every closing joint ``fraction`` of the way from 0 (clipped into range) to its
    closing limit; pre-shape joints at 0 clipped."""
    lower, upper = np.asarray(hand.lower, float), np.asarray(hand.upper, float)
    q = np.clip(0.0, lower, upper)
    for finger in hand.fingers:
        for joint, sense in zip(finger.joints, finger.closing):
            if sense:
                j = hand.actuated_joints.index(joint)
                q[j] += fraction * ((upper[j] if sense > 0 else lower[j]) - q[j])
    return q


def _link_colors(hand: Any) -> tuple[dict[str, str], list[tuple[str, str]]]:
    """Colour of every link (its finger's, else the palm's) and the legend's (name, colour)."""
    colors: dict[str, str] = {}
    legend = []
    for i, finger in enumerate(hand.fingers):
        color = finger_color(finger.name, i)
        thumb = getattr(finger, "is_thumb", False) and "thumb" not in finger.name.lower()
        legend.append((finger.name + (" (thumb)" if thumb else ""), color))
        for link in hand.finger_links(finger):
            colors.setdefault(link, color)
    return colors, legend


def _unit_sphere(level: int) -> tuple[np.ndarray, np.ndarray]:
    mesh = trimesh.creation.icosphere(subdivisions=level, radius=1.0)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def _in_hand(hand: Any, link: str) -> bool:
    """Whether ``link`` is the root or below it (an arm or forearm above the palm is left
    out of the picture: it would dwarf the fingers)."""
    chain = getattr(hand, "chain", None)
    return chain is None or hand.root_link in chain(link)


class _Scene:
    """The triangles to draw for one posture, root frame, mm."""

    def __init__(self, hand: Any, q: np.ndarray, link_colors: dict[str, str], sphere_level: int):
        poses = hand.link_transforms(np.asarray(q, float))
        light = np.array([0.3, -0.5, 1.0])
        geometry, spheres_by_color = [], {}
        unit_v, unit_f = _unit_sphere(sphere_level)
        for link, geoms in hand.collision.items():
            if not _in_hand(hand, link):
                continue
            pose = poses[link]
            for geom in geoms:
                mesh = geom.to_trimesh()
                v, f = decimate_for_drawing(np.asarray(mesh.vertices), np.asarray(mesh.faces), _LINK_TRIANGLES)
                geometry.append(transform(pose, v)[f] * MM)
            cover = hand.spheres.get(link)
            if cover is None or len(cover.radii) == 0:
                continue
            a = transform(pose, np.asarray(cover.centers)) * MM
            b = transform(pose, np.asarray(getattr(cover, "ends", cover.centers))) * MM
            radii = np.asarray(cover.radii) * MM
            # A capsule is the unit sphere's two halves moved to its two ends (a sphere
            # where they coincide); the triangles across the cut make its side.
            upper = (unit_v @ (b - a).T).T > 0  # (k, V)
            vertices = np.where(upper[:, :, None], b[:, None, :], a[:, None, :]) + radii[:, None, None] * unit_v
            tris = vertices[:, unit_f].reshape(-1, 3, 3)
            spheres_by_color.setdefault(link_colors.get(link, PALM_COLOR), []).append(tris)
        self.geometry = np.concatenate(geometry) if geometry else np.zeros((0, 3, 3))
        self.geometry_colors = shaded_colors(self.geometry, np.array(rgb(GEOMETRY_COLOR)), light, _GEOMETRY_ALPHA)
        self.spheres = {c: np.concatenate(t) for c, t in spheres_by_color.items()}
        self.light = light
        self.pads = []
        for i, finger in enumerate(hand.fingers):
            center = transform(poses[finger.pad_link], np.asarray(finger.pad_center, float)[None])[0] * MM
            self.pads.append((center, link_colors.get(finger.pad_link, finger_color(finger.name, i))))
        self.tips = np.array([poses[f.tip_link][:3, 3] * MM for f in hand.fingers])

    def points(self) -> np.ndarray:
        parts = [self.geometry.reshape(-1, 3)] + [t.reshape(-1, 3) for t in self.spheres.values()]
        return np.vstack([p for p in parts if len(p)] or [np.zeros((1, 3))])


def _cameras(hand: Any, tips: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """View name -> (direction toward the camera, picture-up), fingers up in both: in front
    of the palm (slightly turned), and from the side (the fingers' curl in profile)."""
    normal = np.array(hand.palm_normal, dtype=float)
    normal /= np.linalg.norm(normal)
    along = tips.mean(axis=0) if len(tips) else np.array([0.0, 0.0, 1.0])
    along = along - (along @ normal) * normal
    if np.linalg.norm(along) < 1e-9:
        along = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    along /= np.linalg.norm(along)
    across = np.cross(normal, along)
    return {"palm side": (normal + 0.35 * across + 0.2 * along, along),
            "side": (across + 0.25 * normal + 0.15 * along, along)}


def _draw_panel(ax, scene: _Scene, hand: Any, direction: np.ndarray, up: np.ndarray, title: str) -> tuple:
    elev, azim, roll = view_angles(direction, up)
    ax.view_init(elev=elev, azim=azim, roll=roll)
    ax.set_proj_type("ortho")
    # Layers in a fixed order (matplotlib has no per-pixel depth): the spheres, the exact
    # geometry over them (faint: the spheres' colour shows through, their outline beyond
    # it is the stray), then the palm normal and the pads on top, always visible.
    ax.computed_zorder = False
    for color, tris in scene.spheres.items():
        colors = shaded_colors(tris, np.array(rgb(color)), scene.light, _SPHERE_ALPHA)
        ax.add_collection3d(Poly3DCollection(tris, facecolors=colors, edgecolors="none", zorder=1))
    if len(scene.geometry):
        ax.add_collection3d(Poly3DCollection(scene.geometry, facecolors=scene.geometry_colors, edgecolors="none",
                                             zorder=2))
    pts = scene.points()
    span = float(np.ptp(pts, axis=0).max())
    normal = np.asarray(hand.palm_normal, float) / np.linalg.norm(hand.palm_normal)
    arrow = normal * 0.45 * span
    ax.quiver(0.0, 0.0, 0.0, *arrow, color=CONTACT_COLOR, linewidth=2.0, arrow_length_ratio=0.15, zorder=8)
    ax.text(*(arrow * 1.12), "palm normal", fontsize=8, ha="center", va="center", zorder=8)
    for center, color in scene.pads:
        ax.scatter(*center, s=46, color=color, edgecolors="black", linewidths=1.0, depthshade=False, zorder=9)
    right_s, up_s = screen_axes(direction, up)
    pts = np.vstack([pts, np.zeros((1, 3)), arrow[None] * 1.15])
    extra = scale_bar_and_triad(ax, pts, direction, right_s, up_s, nice_length(span))
    pts = np.vstack([pts, extra])
    center, half = framing(pts, direction, right_s, up_s)
    for setter, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), center):
        setter(c - half, c + half)
    ax.set_axis_off()
    ax.set_title(title, fontsize=11)
    # Zoomed to fill the panel with these points: 12 % more than the content leaves a
    # margin under the panel's title.
    middle = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    return ax, middle + 1.12 * (pts - middle), right_s, []


def _title(hand: Any) -> str:
    covers = [c for link, c in hand.spheres.items() if _in_hand(hand, link)]
    count = sum(len(c.radii) for c in covers)
    stray = max((c.max_stray for c in covers), default=0.0)
    uncovered = max((c.uncovered for c in covers), default=0.0)
    thumb = next((f.name for f in hand.fingers if getattr(f, "is_thumb", False)), None)
    line1 = f"{hand.name}: {len(hand.fingers)} fingers" + (f" (thumb: {thumb})" if thumb else " (no thumb)")
    capsules = sum(int(np.any(np.asarray(getattr(c, "ends", c.centers)) != np.asarray(c.centers), axis=1).sum())
                   for c in covers)
    kinds = f"spheres and capsules ({capsules} capsules)" if capsules else "spheres"
    line2 = f"{count} collision {kinds} over the {len(covers)} links below the root, largest stray {stray * MM:.2f} mm"
    if uncovered > 0:
        line2 += f", up to {uncovered:.1%} of a link's surface uncovered"
    return line1 + "\n" + line2


def draw_hand(hand: Any, path: str | os.PathLike, q_open: np.ndarray | None = None,
              q_closed: np.ndarray | None = None, dpi: int = 110) -> str:
    """Write the picture of ``hand`` open and closed to ``path`` (PNG); returns the path.

    hand : the general hand model (``grasp_apso.model.hands``).
    q_open, q_closed : (n,) actuated positions, rad or m; default: every joint at 0
        (clipped into its range), and every closing joint 80 % of the way to its limit.
    """
    n = len(hand.actuated_joints)
    postures = []
    for name, q, fraction in (("q_open", q_open, 0.0), ("q_closed", q_closed, _CLOSED_FRACTION)):
        q = _default_posture(hand, fraction) if q is None else np.asarray(q, dtype=float)
        if q.shape != (n,) or not np.all(np.isfinite(q)):
            from ..errors import InputError

            raise InputError(f"{name}: expected {n} finite joint positions, got shape {q.shape}", field=name)
        postures.append(q)
    link_colors, legend = _link_colors(hand)
    total = sum(len(c.radii) for c in hand.spheres.values())
    level = next(level for limit, level in _SPHERE_LEVEL_UNDER if total <= limit)
    scenes = [_Scene(hand, q, link_colors, level) for q in postures]

    fig = Figure(figsize=(11.0, 11.0))
    panels = []
    closed = f"closed ({_CLOSED_FRACTION:.0%} of the way)" if q_closed is None else "closed"
    for row, (view, (direction, up)) in enumerate(_cameras(hand, scenes[0].tips).items()):
        for col, (scene, label) in enumerate(zip(scenes, ("open", closed))):
            ax = fig.add_subplot(2, 2, 2 * row + col + 1, projection="3d")
            panels.append(_draw_panel(ax, scene, hand, direction, up, f"{label}, {view} view"))
    handles = [Patch(facecolor=c, alpha=0.5, label=name) for name, c in legend]
    handles += [Patch(facecolor=PALM_COLOR, alpha=0.5, label="palm and other links"),
                Patch(facecolor=GEOMETRY_COLOR, alpha=0.4, label="exact collision geometry"),
                Line2D([], [], marker="o", linestyle="", markerfacecolor="white", markeredgecolor="black",
                       label="pads (finger colour)")]
    fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 5), fontsize=9, frameon=False)
    fig.suptitle(_title(hand), fontsize=12)
    fig.subplots_adjust(left=0.01, right=0.99, top=0.92, bottom=0.06, wspace=0.02, hspace=0.06)
    zoom_to_content(fig, panels)
    return save(fig, path, dpi)
