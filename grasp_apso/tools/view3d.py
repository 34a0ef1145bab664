"""3-D view helpers for the grasp pictures: camera angles that follow the hand, framing,
a metric scale bar with the planning-frame triad, zooming to the content, shading and
mesh decimation (used by :mod:`grasp_apso.tools.plotting`; no pyplot)."""

from __future__ import annotations

import math
import os

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..presentation.hand_geometry import MAX_DRAWN_TRIANGLES, decimate_for_drawing

__all__ = ["MAX_DRAWN_TRIANGLES", "save", "decimate_for_drawing", "view_angles", "screen_axes", "framing",
           "nice_length", "scale_bar_and_triad", "zoom_to_content", "shaded_colors", "transform"]

def save(fig: Figure, path: str | os.PathLike, dpi: int) -> str:
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=dpi)
    return path




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


def screen_axes(direction: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors (world) pointing right and up in the picture for a camera at ``direction``."""
    c = np.asarray(direction, float) / np.linalg.norm(direction)
    u = np.asarray(up, float) - (np.asarray(up, float) @ c) * c
    u /= np.linalg.norm(u)
    return np.cross(-c, u), u


def framing(pts: np.ndarray, direction: np.ndarray, right_s: np.ndarray, up_s: np.ndarray):
    """Centre and half size of an axis-aligned cube holding ``pts`` whose centre projects
    onto the middle of the points' projection (so zooming keeps them centred)."""
    c = np.asarray(direction, float) / np.linalg.norm(direction)
    mid = lambda v: 0.5 * (float((pts @ v).min()) + float((pts @ v).max()))  # noqa: E731
    c3 = right_s * mid(right_s) + up_s * mid(up_s) + c * mid(c)
    half = float(np.abs(pts - c3).max()) * 1.02
    return c3, half


def nice_length(span: float) -> float:
    """A round length (mm) of about a fifth of ``span``: 5, 10, 20, 25, 50, 100 ..."""
    target = span / 5.0
    for step in (1, 2, 2.5, 5, 10, 20, 25, 50, 100, 200, 250, 500, 1000):
        if step >= target:
            return float(step)
    return float(10 ** math.ceil(math.log10(target)))


def scale_bar_and_triad(ax, pts: np.ndarray, direction: np.ndarray, right_s: np.ndarray,
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


def zoom_to_content(fig: Figure, panels: list) -> None:
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


def shaded_colors(tris: np.ndarray, base: np.ndarray, light: np.ndarray, alpha: float) -> np.ndarray:
    normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    norm = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = normals / np.where(norm > 0, norm, 1.0)
    light = light / np.linalg.norm(light)
    shade = 0.55 + 0.45 * np.abs(normals @ light)
    colors = np.empty((len(tris), 4))
    colors[:, :3] = np.clip(base[None, :] * shade[:, None], 0, 1)
    colors[:, 3] = alpha
    return colors


def transform(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ matrix[:3, :3].T + matrix[:3, 3]


