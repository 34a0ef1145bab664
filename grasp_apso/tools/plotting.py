"""Pictures of planned grasps: the hand and object in 3-D, and convergence curves.

Pure functions that take planner results (:class:`grasp_apso.search.planner.GraspResult`) and
write a PNG, returning its path; used by the command line (:mod:`grasp_apso.tools.cli`) and
reusable by experiment reports. No display is needed: figures are built with
:class:`matplotlib.figure.Figure` and rendered by the Agg canvas, without pyplot, so the
functions neither change nor depend on matplotlib's global backend and can run in worker
threads.

Drawings are in millimetres in the planning frame of the result (the frame of
``result.wrist_pose``). The 3-D views are chosen from the hand, not from the planning
frame, so every grasp is seen the same way whatever its orientation:

- *side view*: the camera looks across the palm from the little-finger side (along the
  palm frame's +y), the palm normal points up the picture and the fingers to the right:
  the curl of the fingers and the gap between palm and object are visible;
- *fingertip view*: the camera looks from beyond the fingertips back toward the wrist,
  from above the palm: the spread of the fingers around the object and the thumb's
  opposition are visible.

Because the camera follows the hand, the 3-D axis box is hidden; each panel instead shows
a metric scale bar (mm) and the planning frame's x, y, z axes as a small triad, and the
contact positions are printed by the command line. Lengths are drawn to scale (equal
axis ranges, ``set_box_aspect((1, 1, 1))``, orthographic projection). Fingers behind the
translucent object are still drawn on top of it (matplotlib has no per-pixel depth).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import mpl_toolkits.mplot3d  # noqa: F401  (registers the "3d" projection)
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from ..model.hand import FINGER_NAMES, HandModel, load_hand

__all__ = [
    "FINGER_COLORS",
    "MAX_DRAWN_TRIANGLES",
    "decimate_for_drawing",
    "grasp_title",
    "plot_convergence",
    "plot_grasp",
    "view_angles",
]

#: One colour per finger (little, ring, middle, index, thumb); colour-blind friendly
#: (Okabe-Ito), distinct from the grey object and the tan palm.
FINGER_COLORS: dict[str, str] = {
    "little": "#CC79A7",  # reddish purple
    "ring": "#0072B2",  # blue
    "middle": "#009E73",  # bluish green
    "index": "#E69F00",  # orange
    "thumb": "#D55E00",  # vermillion
}
_OBJECT_COLOR = np.array([0.62, 0.66, 0.72])
_PALM_COLOR = "#C8A27A"
_CONTACT_COLOR = "black"
_COM_COLOR = "#444444"
_RUN_COLORS = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000")

#: Meshes with more triangles are simplified (vertex clustering) before drawing.
MAX_DRAWN_TRIANGLES = 3000
_MM = 1000.0
_NORMAL_ARROW_MM = 14.0


# ----------------------------------------------------------------------------- helpers
def _save(fig: Figure, path: str | os.PathLike, dpi: int) -> str:
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=dpi)
    return path


def decimate_for_drawing(
    vertices: np.ndarray, faces: np.ndarray, max_triangles: int = MAX_DRAWN_TRIANGLES
) -> tuple[np.ndarray, np.ndarray]:
    """Simplify a triangle mesh for drawing by vertex clustering.

    Vertices are snapped to a grid whose cell grows until at most ``max_triangles``
    non-degenerate triangles remain; each cell's vertices merge into their mean. Only for
    pictures: the result need not be closed or manifold.

    Parameters
    ----------
    vertices : (V, 3) float
    faces : (T, 3) int
    max_triangles : int

    Returns
    -------
    vertices : (V', 3) float
    faces : (T', 3) int, T' <= max_triangles (unless the coarsest grid still has more)
    """
    vertices = np.asarray(vertices, dtype=float)
    faces = np.asarray(faces, dtype=np.int64)
    if len(faces) <= max_triangles:
        return vertices, faces
    lo = vertices.min(axis=0)
    size = float(np.ptp(vertices, axis=0).max()) or 1.0
    cells = int(math.sqrt(max_triangles / 2.0)) * 2
    best = (vertices, faces)
    while cells >= 4:
        key = np.floor((vertices - lo) / (size / cells)).astype(np.int64)
        _, cluster, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        cluster = cluster.reshape(-1)
        merged = np.zeros((len(counts), 3))
        np.add.at(merged, cluster, vertices)
        merged /= counts[:, None]
        new_faces = cluster[faces]
        keep = (
            (new_faces[:, 0] != new_faces[:, 1])
            & (new_faces[:, 1] != new_faces[:, 2])
            & (new_faces[:, 0] != new_faces[:, 2])
        )
        new_faces = new_faces[keep]
        first = np.unique(np.sort(new_faces, axis=1), axis=0, return_index=True)[1]
        new_faces = new_faces[np.sort(first)]  # drop duplicates, keep the winding
        best = (merged, new_faces)
        if len(new_faces) <= max_triangles:
            break
        cells = int(cells * 0.8)
    return best


def view_angles(direction: np.ndarray, up: np.ndarray) -> tuple[float, float, float]:
    """Matplotlib ``(elev, azim, roll)`` in degrees for a camera looking from ``direction``.

    Parameters
    ----------
    direction : (3,) float
        From the scene centre toward the camera (any length).
    up : (3,) float
        Direction that should point up in the picture (its part across the view).
    """
    c = np.asarray(direction, dtype=float)
    c = c / np.linalg.norm(c)
    elev = math.asin(float(np.clip(c[2], -1.0, 1.0)))
    azim = math.atan2(c[1], c[0])
    # Screen axes at roll 0: right and up.
    right = np.array([-math.sin(azim), math.cos(azim), 0.0])
    up0 = np.array([-math.sin(elev) * math.cos(azim), -math.sin(elev) * math.sin(azim), math.cos(elev)])
    u = np.asarray(up, dtype=float)
    sx, sy = float(u @ right), float(u @ up0)
    # A positive roll turns the picture counter-clockwise; bring u to the top.
    roll = -math.atan2(-sx, sy) if (sx or sy) else 0.0
    return math.degrees(elev), math.degrees(azim), math.degrees(roll)


def _screen_axes(direction: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors (world) pointing right and up in the picture for a camera at ``direction``."""
    c = np.asarray(direction, float) / np.linalg.norm(direction)
    u = np.asarray(up, float) - (np.asarray(up, float) @ c) * c
    u /= np.linalg.norm(u)
    return np.cross(-c, u), u


def _framing(pts: np.ndarray, direction: np.ndarray, right_s: np.ndarray, up_s: np.ndarray):
    """Centre and half size of an axis-aligned cube holding ``pts`` whose centre projects
    onto the middle of the points' projection (so zooming keeps them centred)."""
    c = np.asarray(direction, float) / np.linalg.norm(direction)
    mid = lambda v: 0.5 * (float((pts @ v).min()) + float((pts @ v).max()))  # noqa: E731
    c3 = right_s * mid(right_s) + up_s * mid(up_s) + c * mid(c)
    half = float(np.abs(pts - c3).max()) * 1.02
    return c3, half


def _nice_length(span: float) -> float:
    """A round length (mm) of about a fifth of ``span``: 5, 10, 20, 25, 50, 100 ..."""
    target = span / 5.0
    for step in (1, 2, 2.5, 5, 10, 20, 25, 50, 100, 200, 250, 500, 1000):
        if step >= target:
            return float(step)
    return float(10 ** math.ceil(math.log10(target)))


def _scale_bar_and_triad(ax, pts: np.ndarray, direction: np.ndarray, right_s: np.ndarray,
                         up_s: np.ndarray, length: float) -> np.ndarray:
    """Draw a metric scale bar (bottom left) and the planning-frame axes (bottom right)
    below the content; return the points they occupy (for framing)."""
    c = np.asarray(direction, float) / np.linalg.norm(direction)
    pr, pu, pc = pts @ right_s, pts @ up_s, pts @ c
    span = float(max(np.ptp(pr), np.ptp(pu)))
    depth = c * 0.5 * (pc.min() + pc.max())
    arrow = 0.3 * length
    gap = 0.05 * span + arrow * 1.3  # the triad's arrows stay below the content
    start = depth + right_s * (pr.min()) + up_s * (pu.min() - gap)
    end = start + right_s * length
    ax.plot(*np.stack([start, end]).T, color="black", linewidth=2.5, solid_capstyle="butt", zorder=7)
    for tick in (start, end):
        seg = np.stack([tick - up_s * 0.012 * span, tick + up_s * 0.012 * span])
        ax.plot(*seg.T, color="black", linewidth=1.2, zorder=7)
    label = start + right_s * (length / 2) - up_s * 0.045 * span
    ax.text(*label, f"{length:g} mm", ha="center", va="top", fontsize=9, zorder=7)
    # Planning-frame triad.
    # Right of the content, and clear of the scale bar and its label.
    origin_r = max(float(pr.max()) - arrow * 1.3, float(pr.min()) + length + arrow * 2.2)
    origin = depth + right_s * origin_r + up_s * (pu.min() - gap)
    for k, (name, color) in enumerate((("x", "#D62728"), ("y", "#2CA02C"), ("z", "#1F77B4"))):
        axis = np.eye(3)[k] * arrow
        ax.quiver(*origin, *axis, color=color, linewidth=1.5, arrow_length_ratio=0.25, zorder=7)
        ax.text(*(origin + axis * 1.25), name, color=color, fontsize=9, ha="center", va="center", zorder=7)
    lowest = min(0.0, float((np.eye(3) @ up_s).min()) * arrow * 1.25)
    ax.text(*(origin + up_s * (lowest - 0.03 * span)), "planning frame", ha="center", va="top", fontsize=8,
            color="0.3", zorder=7)
    below = up_s * (lowest - 0.09 * span)
    return np.vstack([start + below, end + below, origin + below, origin + np.eye(3) * arrow * 1.4])


def _zoom_to_content(fig: Figure, panels: list) -> None:
    """Zoom each 3-D panel so its content fills about 90 % of the panel."""
    from mpl_toolkits.mplot3d import proj3d

    FigureCanvasAgg(fig)
    fig.canvas.draw()
    for ax, pts, right_s, tubes in panels:
        bbox = ax.get_window_extent()
        probe = np.vstack([pts, pts[:1] + right_s * 10.0])  # last two points: 10 mm apart
        x2, y2, _ = proj3d.proj_transform(*probe.T, ax.get_proj())
        disp = ax.transData.transform(np.column_stack([x2, y2]))
        px_per_mm = float(np.linalg.norm(disp[-1] - disp[0])) / 10.0
        disp = disp[:-1]
        cx, cy = (bbox.x0 + bbox.x1) / 2, (bbox.y0 + bbox.y1) / 2
        need_x = float(np.abs(disp[:, 0] - cx).max()) / (bbox.width / 2)
        need_y = float(np.abs(disp[:, 1] - cy).max()) / (bbox.height / 2)
        zoom = float(np.clip(0.9 / max(need_x, need_y, 1e-6), 0.5, 4.0))
        ax.set_box_aspect((1, 1, 1), zoom=zoom)
        # Finger volumes to scale: line width (points) of the link diameter after zooming.
        for line, diameter_mm in tubes:
            line.set_linewidth(diameter_mm * px_per_mm * zoom * 72.0 / fig.dpi)


def _shaded_colors(tris: np.ndarray, base: np.ndarray, light: np.ndarray, alpha: float) -> np.ndarray:
    normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    norm = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = normals / np.where(norm > 0, norm, 1.0)
    light = light / np.linalg.norm(light)
    shade = 0.55 + 0.45 * np.abs(normals @ light)
    colors = np.empty((len(tris), 4))
    colors[:, :3] = np.clip(base[None, :] * shade[:, None], 0, 1)
    colors[:, 3] = alpha
    return colors


def _sphere(center: np.ndarray, radius: float, n: int = 10) -> tuple[np.ndarray, ...]:
    u = np.linspace(0, 2 * np.pi, n + 1)
    v = np.linspace(0, np.pi, n // 2 + 1)
    x = center[0] + radius * np.outer(np.cos(u), np.sin(v))
    y = center[1] + radius * np.outer(np.sin(u), np.sin(v))
    z = center[2] + radius * np.outer(np.ones_like(u), np.cos(v))
    return x, y, z


def _box_corners(center: np.ndarray, half: np.ndarray) -> np.ndarray:
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
    return center + signs * half


_BOX_EDGES = [(a, b) for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]


def _transform(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ matrix[:3, :3].T + matrix[:3, 3]


def _yes(flag: bool) -> str:
    return "yes" if flag else "no"


def _touching_links(result: Any, tolerance: float = 1e-4) -> np.ndarray:
    """(5, 3) bool: links resting on the object (python-fcl distance 0), except the distal
    link of a finger whose fingertip is a contact."""
    fcl = getattr(result, "fcl", None)
    distance = getattr(fcl, "link_distance", None)
    if distance is None:
        return np.zeros((5, 3), bool)
    touching = np.asarray(distance, float) <= tolerance
    for c in result.contacts:
        if c.finger in FINGER_NAMES:
            touching[FINGER_NAMES.index(c.finger), 2] = False
    return touching


def grasp_title(result: Any, object_name: str | None = None) -> str:
    """Two-line title: object and algorithm, then fitness, epsilon, closure, contacts."""
    fingers = ", ".join(c.finger for c in result.contacts) or "none"
    head = f"{object_name or 'object'}: {str(result.algorithm).upper()} grasp"
    if getattr(result, "cancelled", False):
        head += " (cancelled)"
    if not getattr(result, "valid", True):
        head += " (NOT VALID)"
    return (
        f"{head}\n"
        f"fitness {result.fitness:.3f}   epsilon {result.epsilon:.3f}   "
        f"force closure: {_yes(result.force_closure)}   "
        f"{len(result.contacts)} contacts: {fingers}"
    )


# ----------------------------------------------------------------------------- grasp
def plot_grasp(
    result: Any,
    obj: Any,
    pose: np.ndarray | None = None,
    path: str | os.PathLike = "grasp.png",
    title: str | None = None,
    hand: HandModel | None = None,
    views: Sequence[str] = ("side", "fingertips"),
    dpi: int = 110,
) -> str:
    """Draw the hand and the object in 3-D with the contacts; write a PNG.

    Parameters
    ----------
    result : GraspResult
        A planned grasp (``joints``, ``wrist_pose``, ``contacts`` in the planning frame).
    obj : GraspObject
        The object that was planned on (its mesh is in the object frame).
    pose : (4, 4) float, optional
        Object frame -> planning frame, as given to ``plan``. None recovers it from the
        result (``wrist_pose @ inv(wrist_in_object)``).
    path : path-like
        Output PNG; missing folders are created.
    title : str, optional
        Figure title; default :func:`grasp_title`.
    hand : HandModel, optional
        The hand planned with (for the palm box and pad radius); the shipped hand when None.
    views : sequence of "side" | "fingertips" | "palm"
        One panel per view, side by side (see the module docstring; "palm" looks at the
        palm face through the object).
    dpi : int

    Returns
    -------
    str
        ``path``.
    """
    hand = hand or load_hand()
    if pose is None:
        pose = np.asarray(result.wrist_pose, float) @ np.linalg.inv(np.asarray(result.wrist_in_object, float))
    pose = np.asarray(pose, dtype=float)
    wrist = np.asarray(result.wrist_pose, dtype=float)
    joints = np.asarray(result.joints, dtype=float) * _MM  # (5, 4, 3) base, pip, dip, tip

    verts, faces = decimate_for_drawing(np.asarray(obj.mesh.vertices), np.asarray(obj.mesh.faces))
    verts = _transform(pose, verts) * _MM
    tris = verts[faces]
    com = _transform(pose, np.asarray(obj.center_of_mass, float)[None])[0] * _MM

    palm = _transform(wrist, _box_corners(np.asarray(hand.palm_center), np.asarray(hand.palm_half_extents))) * _MM
    axes_palm = wrist[:3, :3]  # columns: fingers (x), thumb side (y), palm normal (z)
    pad_mm = hand.pad_radius * _MM
    radii_mm = np.asarray(hand.link_radii, float) * _MM

    # Scene bounds: object, palm, fingers; equal ranges on every axis.
    pts = np.vstack([verts, palm, joints.reshape(-1, 3)])
    lo, hi = pts.min(axis=0) - pad_mm, pts.max(axis=0) + pad_mm
    bar_mm = _nice_length(float((hi - lo).max()))

    camera = {
        "side": (-axes_palm[:, 1] * 1.0 - axes_palm[:, 0] * 0.12 + axes_palm[:, 2] * 0.05, axes_palm[:, 2],
                 "side view (from the little-finger side)"),
        "fingertips": (axes_palm[:, 0] * 1.0 + axes_palm[:, 2] * 0.5 - axes_palm[:, 1] * 0.2, axes_palm[:, 2],
                       "fingertip view (from beyond the fingertips)"),
        "palm": (axes_palm[:, 2] * 1.0 + axes_palm[:, 0] * 0.15 + axes_palm[:, 1] * 0.1, axes_palm[:, 0],
                 "palm view (through the object)"),
    }
    unknown = [v for v in views if v not in camera]
    if unknown or not views:
        raise ValueError(f"views: expected some of {sorted(camera)}, got {list(views)!r}")

    fig = Figure(figsize=(5.9 * len(views), 6.6))
    fig.suptitle(title if title is not None else grasp_title(result, getattr(obj, "name", None)), fontsize=12)
    light = axes_palm @ np.array([0.3, 0.5, 1.0])
    contact_by_finger = {c.finger: c for c in result.contacts}
    touching = _touching_links(result)
    panels = []

    for k, view in enumerate(views):
        ax = fig.add_subplot(1, len(views), k + 1, projection="3d", computed_zorder=False)
        direction, up, label = camera[view]
        elev, azim, roll = view_angles(direction, up)
        ax.view_init(elev=elev, azim=azim, roll=roll)
        ax.set_proj_type("ortho")
        tubes = []

        # Object: translucent shaded mesh.
        mesh = Poly3DCollection(
            tris, facecolors=_shaded_colors(tris, _OBJECT_COLOR, light, 0.35),
            edgecolors=(0.35, 0.38, 0.42, 0.12), linewidths=0.3, zorder=1,
        )
        ax.add_collection3d(mesh)
        ax.scatter(*com, marker="+", s=60, color=_COM_COLOR, zorder=5, depthshade=False)

        # Palm: box outline, its face toward the object filled.
        for a, b in _BOX_EDGES:
            ax.plot(*np.stack([palm[a], palm[b]]).T, color="#8A6A4A", linewidth=1.2, zorder=2)
        top = palm[[1, 3, 7, 5]]  # +z face (sz = +1): corners (-,-,+), (-,+,+), (+,+,+), (+,-,+)
        ax.add_collection3d(Poly3DCollection([top], facecolors=[_PALM_COLOR], alpha=0.45,
                                             edgecolors="none", zorder=2))

        # Fingers: links as thick lines, joints as dots, pads as spheres.
        for f, name in enumerate(FINGER_NAMES):
            color = FINGER_COLORS[name]
            chain = joints[f]
            # Link volumes to scale: proximal + middle as one polyline, then the distal link.
            for piece, radius in ((chain[:3], max(radii_mm[0], radii_mm[1])), (chain[2:], radii_mm[2])):
                tube, = ax.plot(*piece.T, color=color, alpha=0.16, linewidth=1.0,
                                solid_capstyle="round", solid_joinstyle="round", zorder=2)
                tubes.append((tube, 2.0 * radius))
            ax.plot(*chain.T, color=color, linewidth=4.0, solid_capstyle="round", zorder=3)
            for k in np.flatnonzero(touching[f]):
                ax.plot(*chain[k:k + 2].T, color="black", linewidth=1.3, linestyle=(0, (2, 1.5)), zorder=4)
            ax.scatter(*chain[:3].T, s=14, color="white", edgecolors=color, zorder=4, depthshade=False)
            sx, sy, sz = _sphere(chain[3], pad_mm)
            ax.plot_surface(sx, sy, sz, color=color, alpha=0.55, linewidth=0, shade=True, zorder=3)

        # Contacts: markers and short outward normals.
        for finger, contact in contact_by_finger.items():
            p = np.asarray(contact.position, float) * _MM  # already in the planning frame
            n = np.asarray(contact.normal, float)
            ax.scatter(*p, s=55, marker="o", color=FINGER_COLORS.get(finger, "k"),
                       edgecolors=_CONTACT_COLOR, linewidths=1.5, zorder=6, depthshade=False)
            ax.quiver(*p, *(n * _NORMAL_ARROW_MM), color=_CONTACT_COLOR, linewidth=1.4,
                      arrow_length_ratio=0.35, zorder=6)

        right_s, up_s = _screen_axes(direction, up)
        deco = _scale_bar_and_triad(ax, pts, direction, right_s, up_s, bar_mm)
        view_pts = np.vstack([pts, deco])
        c3, half = _framing(view_pts, direction, right_s, up_s)
        ax.set_xlim(c3[0] - half, c3[0] + half)
        ax.set_ylim(c3[1] - half, c3[1] + half)
        ax.set_zlim(c3[2] - half, c3[2] + half)
        ax.set_box_aspect((1, 1, 1))
        ax.set_axis_off()
        panels.append((ax, view_pts, right_s, tubes))
        ax.set_title(label, fontsize=10)

    handles = [Line2D([], [], color=FINGER_COLORS[n], linewidth=5, label=n) for n in FINGER_NAMES]
    handles += [
        Line2D([], [], marker="o", linestyle="-", color=_CONTACT_COLOR, markerfacecolor="white",
               markeredgewidth=1.5, label="contact + surface normal"),
        Line2D([], [], marker="+", linestyle="none", color=_COM_COLOR, markersize=9, label="centre of mass"),
        Patch(facecolor=_OBJECT_COLOR, alpha=0.5, label="object"),
        Patch(facecolor=_PALM_COLOR, edgecolor="#8A6A4A", alpha=0.6, label="palm (face toward object)"),
    ]
    handles.append(Line2D([], [], color="0.5", alpha=0.3, linewidth=9, solid_capstyle="round",
                          label="finger volume (to scale)"))
    if touching.any():
        handles.append(Line2D([], [], color="black", linewidth=1.3, linestyle=(0, (2, 1.5)),
                              label="link touching the object (not a contact)"))
    fig.legend(handles=handles, loc="lower center", ncol=6, fontsize=9, frameon=False, columnspacing=1.2,
               handlelength=2.2)
    fig.subplots_adjust(left=0.0, right=1.0, bottom=0.08, top=0.88, wspace=0.0)
    _zoom_to_content(fig, panels)
    return _save(fig, path, dpi)


# ----------------------------------------------------------------------------- convergence
def _history_arrays(run: Any) -> dict[str, np.ndarray]:
    """Per-iteration arrays (iteration, best, mean, active) of a GraspResult, a sequence of
    IterationStats, or a mapping with ``best`` (and optionally ``mean``, ``iteration``,
    ``active``) arrays."""
    history = getattr(run, "history", run)
    if isinstance(history, Mapping):
        best = np.asarray(history["best"], float)
        nan = np.full(len(best), np.nan)
        return {
            "iteration": np.asarray(history.get("iteration", np.arange(1, len(best) + 1)), float),
            "best": best,
            "mean": np.asarray(history.get("mean", nan), float),
            "active": np.asarray(history.get("active", nan), float),
        }
    history = list(history)
    return {
        "iteration": np.array([h.iteration for h in history], float),
        "best": np.array([h.best_fitness for h in history], float),
        "mean": np.array([h.mean_fitness for h in history], float),
        "active": np.array([h.active_particles for h in history], float),
    }


def plot_convergence(
    results: Any,
    path: str | os.PathLike = "convergence.png",
    title: str | None = None,
    dpi: int = 110,
) -> str:
    """Best and mean fitness per iteration for one or several runs, on the same axes.

    A lower panel shows the number of active particles (legal, at least 2 contacts), the
    particles the mean is taken over.

    Parameters
    ----------
    results : GraspResult, sequence of IterationStats, or mapping label -> either
        One run, or several (e.g. ``{"APSO": r1, "PSO": r2}``). A run may also be a
        mapping with ``best`` (and optionally ``mean``, ``iteration``, ``active``) arrays.
    path : path-like
        Output PNG; missing folders are created.
    title : str, optional
    dpi : int

    Returns
    -------
    str
        ``path``.
    """
    if not isinstance(results, Mapping) or "best" in results:
        label = str(getattr(results, "algorithm", "run")).upper()
        results = {label: results}
    runs = {label: _history_arrays(run) for label, run in results.items()}
    runs = {label: h for label, h in runs.items() if len(h["iteration"])}
    if not runs:
        raise ValueError("results: nothing to plot (no iteration history)")

    fig = Figure(figsize=(8.0, 6.0))
    grid = fig.add_gridspec(2, 1, height_ratios=(3.2, 1.0), hspace=0.08)
    ax = fig.add_subplot(grid[0])
    ax_active = fig.add_subplot(grid[1], sharex=ax)
    lowest = 0.0
    most = 1.0
    for k, (label, h) in enumerate(runs.items()):
        its, best, mean = h["iteration"], h["best"], h["mean"]
        color = _RUN_COLORS[k % len(_RUN_COLORS)]
        marker = "o" if len(its) <= 12 else None
        ax.plot(its, best, color=color, linewidth=2.2, marker=marker, markersize=4,
                label=f"{label}: best (final {best[-1]:.3f})")
        ax.plot(its, mean, color=color, linewidth=1.4, linestyle="--", alpha=0.85,
                label=f"{label}: mean of active particles")
        ax_active.plot(its, h["active"], color=color, linewidth=1.4, marker=marker, markersize=3, label=label)
        finite = np.concatenate([best[np.isfinite(best)], mean[np.isfinite(mean)]])
        if finite.size:
            lowest = min(lowest, float(finite.min()))
        if np.isfinite(h["active"]).any():
            most = max(most, float(np.nanmax(h["active"])))
    ax.axhline(0.0, color="0.6", linewidth=0.8)
    ax.set_ylim(min(-0.05, lowest - 0.05), 1.02)
    ax.set_ylabel("fitness (maximised;\nvalid grasps in [0, 1])")
    ax.grid(True, alpha=0.3)
    ax.tick_params(labelbottom=False)
    if lowest < 0:
        ax.text(0.99, 0.02, "below 0: no valid grasp yet\n(fewer than 2 contacts or a collision)",
                transform=ax.transAxes, ha="right", va="bottom", fontsize=8, color="0.35")
    ax.legend(loc="lower right" if lowest >= 0 else "center right", fontsize=9)
    ax.set_title(title or "Convergence: best and mean fitness of the swarm per iteration", fontsize=11)
    ax_active.set_ylim(0, most * 1.1)
    ax_active.set_ylabel("active\nparticles")
    ax_active.set_xlabel("iteration")
    ax_active.grid(True, alpha=0.3)
    ax_active.xaxis.get_major_locator().set_params(integer=True)
    fig.subplots_adjust(left=0.11, right=0.98, top=0.93, bottom=0.09)
    return _save(fig, path, dpi)
