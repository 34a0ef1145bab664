"""Pictures of planned grasps: the hand, the object and the scene in 3-D, the ranked
candidates as small multiples, and convergence curves.

Pure functions that take planner results (:class:`grasp_apso.search.result.GraspResult`)
and write a PNG, returning its path; used by the command line (:mod:`grasp_apso.tools.cli`)
and the experiment report. No display is needed: figures are built with
:class:`matplotlib.figure.Figure` and rendered by the Agg canvas, without pyplot, so the
functions neither change nor depend on matplotlib's global backend and can run in worker
threads.

Drawings are in millimetres in the planning frame of the result (the frame of
``result.wrist_pose``). What a grasp picture shows: the translucent object and its centre
of mass (+); the palm box and each finger in its colour over its volume to scale; the
contacts with their outward normals; when a scene is given, the table as a translucent
wooden patch with a grid and the obstacles in translucent grey; the approach as a sky-blue
arrow from the pre-grasp palm to the grasp palm, and the pre-grasp hand drawn faintly at
the start of that arrow. Colours: :mod:`grasp_apso.presentation.palette`.

The views follow the hand, so every grasp is seen the same way whatever its orientation:

- *side view*: the camera looks across the palm from the little-finger side (along the
  palm frame's +y; "across the palm" for any other hand), the palm normal points up the
  picture and the fingers to the right;
- *fingertip view*: the camera looks from beyond the fingertips back toward the wrist.

With a table, both views keep the table horizontal instead (its normal up the picture,
the camera slightly above it), so "from above" reads as from above. The 3-D axis box is
hidden; each panel shows a metric scale bar (mm) and the planning frame's x, y, z axes as a
small triad. Lengths are to scale (equal axis ranges, orthographic projection). Fingers
behind the translucent object are still drawn on top of it (matplotlib has no per-pixel
depth).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import mpl_toolkits.mplot3d  # noqa: F401  (registers the "3d" projection)
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from ..model.hand import FINGER_NAMES, HandModel, load_hand
from ..model.planning_hand import is_general_hand
from ..presentation.hand_geometry import finger_color
from ..presentation.palette import (APPROACH_COLOR, COM_COLOR, CONTACT_COLOR, FINGER_COLORS, OBJECT_COLOR, OBSTACLE_COLOR,
                      PALM_COLOR, PRE_GRASP_ALPHA, SCENE_COLOR)
from .any_hand_drawing import draw_any_hand, finger_legend, hand_axes, hand_mesh_mm, pad_radius_mm
from .scene_drawing import (MM, draw_approach, draw_contacts, draw_hand, draw_object, draw_obstacles, draw_table,
                            label_corner, palm_corners, table_patch)
from .view3d import (MAX_DRAWN_TRIANGLES, decimate_for_drawing, framing, nice_length, save, scale_bar_and_triad,
                     screen_axes, transform, view_angles, zoom_to_content)

__all__ = [
    "FINGER_COLORS",
    "MAX_DRAWN_TRIANGLES",
    "decimate_for_drawing",
    "grasp_title",
    "candidate_title",
    "camera_directions",
    "plot_candidates",
    "plot_convergence",
    "plot_grasp",
    "view_angles",
]

_RUN_COLORS = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000")
_VIEW_LABELS = {"side": "side view (from the little-finger side)",
                "fingertips": "fingertip view (from beyond the fingertips)",
                "palm": "palm view (through the object)"}
#: Any other hand has no little finger: its side view looks across the palm (its palm
#: frame's y axis, x toward the fingers, z the palm normal).
_GENERAL_SIDE = "side view (across the palm)"


def _view_label(view: str, hand: Any) -> str:
    """The caption of ``view`` in words that hold for ``hand``."""
    return _GENERAL_SIDE if view == "side" and is_general_hand(hand) else _VIEW_LABELS[view]


def _yes(flag: bool) -> str:
    return "yes" if flag else "no"


def grasp_title(result: Any, object_name: str | None = None) -> str:
    """Two-line title: object and algorithm, then fitness, epsilon, closure, contacts."""
    fingers = ", ".join(c.finger for c in result.contacts) or "none"
    head = f"{object_name or 'object'}: {str(result.algorithm).upper()} grasp"
    if getattr(result, "cancelled", False):
        head += " (cancelled)"
    if not getattr(result, "valid", True):
        head += " (NOT VALID)"
    return (f"{head}\n"
            f"fitness {result.fitness:.3f}   epsilon {result.epsilon:.3f}   "
            f"force closure: {_yes(result.force_closure)}   {len(result.contacts)} contacts: {fingers}")


def candidate_title(candidate: Any) -> str:
    """Two-line panel title of a ranked candidate: rank, quality, epsilon, closure, contacts
    and the simulation verdict when it ran."""
    sim = {1: ", held", 0: ", DROPPED"}.get(int(getattr(candidate, "sim_result", -1)), "")
    return (f"#{candidate.rank + 1}: quality {candidate.grasp_quality:.2f}{sim}\n"
            f"epsilon {candidate.epsilon:.3f}, FC {_yes(candidate.force_closure)}, {candidate.n_contacts} contacts"
            + ("" if candidate.valid else " (NOT VALID)"))


def camera_directions(palm_axes: np.ndarray, up: np.ndarray | None = None) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """``view -> (camera direction, picture up)`` for the views of the module docstring;
    ``up`` (a table normal) keeps that direction up the picture in the side and fingertip
    views, the camera 24 degrees above the table."""
    x, y, z = (palm_axes[:, k] for k in range(3))
    cams = {"side": (-y - 0.12 * x + 0.05 * z, z), "fingertips": (x + 0.5 * z - 0.2 * y, z),
            "palm": (z + 0.15 * x + 0.1 * y, x)}
    if up is None:
        return cams
    n = np.asarray(up, float) / np.linalg.norm(up)
    for view in ("side", "fingertips"):
        d = cams[view][0] / np.linalg.norm(cams[view][0])
        h = d - (d @ n) * n
        for fallback in (-y, x, np.eye(3)[0], np.eye(3)[1]):
            if np.linalg.norm(h) > 0.2:
                break
            h = fallback - (fallback @ n) * n
        cams[view] = (h / np.linalg.norm(h) + 0.45 * n, n)
    return cams


@dataclass
class _Grasp:
    """What one panel draws, in mm: joints (5, 4, 3), palm corners, contacts, the pre-grasp
    hand (or None) and the approach arrow's ends, the palm axes (3, 3)."""

    joints: np.ndarray
    palm: np.ndarray
    contacts: tuple
    pre_joints: np.ndarray | None
    pre_palm: np.ndarray | None
    approach: tuple[np.ndarray, np.ndarray] | None
    approach_mm: float
    palm_axes: np.ndarray
    touching: np.ndarray | None = None
    #: A general hand: link -> (T, 3, 3) triangles, mm, at the grasp and the pre-grasp.
    hand_tris: dict | None = None
    pre_hand_tris: dict | None = None

    def points(self) -> np.ndarray:
        pts = [self.joints.reshape(-1, 3), self.palm]
        if self.pre_joints is not None:
            pts += [self.pre_joints.reshape(-1, 3), self.pre_palm]
        for tris in (self.hand_tris or {}, self.pre_hand_tris or {}):
            pts += [t.reshape(-1, 3) for t in tris.values()]
        return np.vstack(pts)


def _general_grasp_of(item: Any, hand: Any, candidate: Any) -> _Grasp:
    """A :class:`_Grasp` of a general hand: its own collision geometry at the grasp
    (``joint_positions`` at ``wrist_pose``, the root link) and the pre-grasp."""
    wrist = np.asarray(item.wrist_pose, float)
    q = np.asarray(item.joint_positions, float)
    empty = np.zeros((0, 3))
    pre_tris = approach = None
    approach_mm = 0.0
    if candidate is not None and float(candidate.approach_distance) > 0:
        pre_pose = np.asarray(candidate.pre_grasp_pose, float)
        pre_tris = hand_mesh_mm(hand, np.asarray(candidate.pre_grasp_positions, float), pre_pose)
        approach = (pre_pose[:3, 3] * MM, wrist[:3, 3] * MM)
        approach_mm = float(candidate.approach_distance) * MM
    return _Grasp(np.zeros((0, 4, 3)), empty, tuple(item.contacts), None, None, approach, approach_mm,
                  hand_axes(hand, wrist, q), None, hand_mesh_mm(hand, q, wrist), pre_tris)


def _grasp_of(item: Any, hand: HandModel, touching: np.ndarray | None = None, candidate: Any = None) -> _Grasp:
    """A :class:`_Grasp` of a result (its pre-grasp from ``candidate``, default its first
    candidate) or of a candidate."""
    wrist = np.asarray(item.wrist_pose, float)
    candidate = candidate if candidate is not None else (
        item if hasattr(item, "pre_grasp_joints") else next(iter(getattr(item, "candidates", ())), None))
    if is_general_hand(hand):
        return _general_grasp_of(item, hand, candidate)
    pre_joints = pre_palm = approach = None
    approach_mm = 0.0
    if candidate is not None and float(candidate.approach_distance) > 0:
        pre_pose = np.asarray(candidate.pre_grasp_pose, float)
        pre_joints = np.asarray(candidate.pre_grasp_joints, float) * MM
        pre_palm = palm_corners(hand, pre_pose)
        centre = np.asarray(hand.palm_center, float)[None]
        approach = (transform(pre_pose, centre)[0] * MM, transform(wrist, centre)[0] * MM)
        approach_mm = float(candidate.approach_distance) * MM
    return _Grasp(np.asarray(item.joints, float) * MM, palm_corners(hand, wrist), tuple(item.contacts),
                  pre_joints, pre_palm, approach, approach_mm, wrist[:3, :3], touching)


def _object_geometry(obj: Any, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    verts, faces = decimate_for_drawing(np.asarray(obj.mesh.vertices), np.asarray(obj.mesh.faces))
    verts = transform(pose, verts) * MM
    com = transform(pose, np.asarray(obj.center_of_mass, float)[None])[0] * MM
    return verts[faces], com


def _pose_of(result: Any, pose: np.ndarray | None) -> np.ndarray:
    if pose is None:
        return np.asarray(result.wrist_pose, float) @ np.linalg.inv(np.asarray(result.wrist_in_object, float))
    return np.asarray(pose, dtype=float)


def _draw_panel(ax, view: str, grasp: _Grasp, tris: np.ndarray, com: np.ndarray, hand: HandModel, scene: Any,
                bar_mm: float | None, label: str | None) -> tuple[Any, np.ndarray, np.ndarray, list]:
    """Everything of one grasp on one 3-D axis; returns the ``zoom_to_content`` entry."""
    up = scene.planes[0][:3] if scene is not None and len(scene.planes) else None
    direction, picture_up = camera_directions(grasp.palm_axes, up)[view]
    elev, azim, roll = view_angles(direction, picture_up)
    ax.view_init(elev=elev, azim=azim, roll=roll)
    ax.set_proj_type("ortho")
    content = np.vstack([tris.reshape(-1, 3), grasp.points()])
    pad = pad_radius_mm(hand) if grasp.hand_tris is not None else hand.pad_radius * MM
    margin = max(60.0, 0.6 * float(np.ptp(content, axis=0).max()))  # obstacles are clipped to this
    roi_lo, roi_hi = content.min(axis=0) - margin, content.max(axis=0) + margin
    pts = [content]
    if scene is not None:
        for plane in scene.planes:
            corners = table_patch(np.asarray(plane), content)
            draw_table(ax, corners, label_corner(corners, content, direction))
            pts.append(corners)
        pts.append(draw_obstacles(ax, scene, roi_lo, roi_hi))
    draw_object(ax, tris, com, grasp.palm_axes @ np.array([0.3, 0.5, 1.0]))
    tubes: list = []
    if grasp.hand_tris is not None:
        if grasp.pre_hand_tris is not None:
            draw_any_hand(ax, hand, grasp.pre_hand_tris, faint=True)
        draw_any_hand(ax, hand, grasp.hand_tris)
    else:
        if grasp.pre_joints is not None:
            draw_hand(ax, grasp.pre_joints, grasp.pre_palm, hand, faint=True)
        tubes = draw_hand(ax, grasp.joints, grasp.palm, hand, touching=grasp.touching)
    draw_contacts(ax, grasp.contacts, None if grasp.hand_tris is None else
                  {f.name: finger_color(f.name, i) for i, f in enumerate(hand.fingers)})
    if grasp.approach is not None:
        draw_approach(ax, *grasp.approach, label=f"approach {grasp.approach_mm:.0f} mm" if label else None)
    pts = np.vstack(pts)
    lo, hi = pts.min(axis=0) - pad, pts.max(axis=0) + pad
    right_s, up_s = screen_axes(direction, picture_up)
    deco = scale_bar_and_triad(ax, pts, direction, right_s, up_s, bar_mm or nice_length(float((hi - lo).max())))
    view_pts = np.vstack([pts, deco])
    c3, half = framing(view_pts, direction, right_s, up_s)
    ax.set_xlim(c3[0] - half, c3[0] + half)
    ax.set_ylim(c3[1] - half, c3[1] + half)
    ax.set_zlim(c3[2] - half, c3[2] + half)
    ax.set_box_aspect((1, 1, 1))
    ax.set_axis_off()
    if label:
        ax.set_title(label, fontsize=10)
    return ax, view_pts, right_s, tubes


def _legend(fig: Figure, grasp: _Grasp, scene: Any, touching: bool, ncol: int, hand: Any = None) -> None:
    general = grasp.hand_tris is not None
    handles = finger_legend(hand) if general else [
        Line2D([], [], color=FINGER_COLORS[n], linewidth=5, label=n) for n in FINGER_NAMES]
    handles += [
        Line2D([], [], marker="o", linestyle="-", color=CONTACT_COLOR, markerfacecolor="white",
               markeredgewidth=1.5, label="contact + surface normal"),
        Line2D([], [], marker="+", linestyle="none", color=COM_COLOR, markersize=9, label="centre of mass"),
        Patch(facecolor=OBJECT_COLOR, alpha=0.5, label="object"),
    ]
    handles += [Patch(facecolor=PALM_COLOR, alpha=0.6, label="palm and links no finger moves")] if general else [
        Patch(facecolor=PALM_COLOR, edgecolor="#8A6A4A", alpha=0.6, label="palm (face toward object)"),
        Line2D([], [], color="0.5", alpha=0.3, linewidth=9, solid_capstyle="round", label="finger volume (to scale)"),
    ]
    if grasp.approach is not None:
        handles += [Line2D([], [], color=APPROACH_COLOR, linewidth=3, marker=">", markevery=[-1],
                           label="approach (pre-grasp -> grasp)"),
                    Line2D([], [], color="0.4", alpha=PRE_GRASP_ALPHA * 2, linewidth=2, label="pre-grasp hand (open)")]
    if scene is not None and len(scene.planes):
        handles.append(Patch(facecolor=SCENE_COLOR, edgecolor=SCENE_COLOR, alpha=0.35, label="table"))
    if scene is not None and scene.obstacles:
        handles.append(Patch(facecolor=OBSTACLE_COLOR, edgecolor=OBSTACLE_COLOR, alpha=0.4, label="obstacle"))
    if touching:
        handles.append(Line2D([], [], color="black", linewidth=1.3, linestyle=(0, (2, 1.5)),
                              label="link touching the object (not a contact)"))
    fig.legend(handles=handles, loc="lower center", ncol=ncol, fontsize=9, frameon=False, columnspacing=1.2,
               handlelength=2.2)


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
    scene: Any = None,
) -> str:
    """Draw the best grasp, the object and the scene in 3-D; write a PNG.

    Parameters
    ----------
    result : GraspResult
        A planned grasp (``joints``, ``wrist_pose``, ``contacts`` in the planning frame; the
        pre-grasp and approach of ``candidates[0]`` when present).
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
        The hand planned with (palm box, link and pad radii); the shipped hand when None. A
        general hand (:class:`grasp_apso.model.hands.HandModel`) is drawn from its own
        collision geometry (:mod:`grasp_apso.tools.any_hand_drawing`).
    views : sequence of "side" | "fingertips" | "palm"
        One panel per view, side by side.
    dpi : int
    scene : Scene, optional
        The support planes and obstacles planned with (planning frame).

    Returns
    -------
    str
        ``path``.
    """
    hand = hand or load_hand()
    unknown = [v for v in views if v not in _VIEW_LABELS]
    if unknown or not views:
        raise ValueError(f"views: expected some of {sorted(_VIEW_LABELS)}, got {list(views)!r}")
    tris, com = _object_geometry(obj, _pose_of(result, pose))
    touching = np.zeros((0, 3), dtype=bool) if is_general_hand(hand) else result.touching_links()
    grasp = _grasp_of(result, hand, touching)
    table = scene is not None and len(scene.planes) > 0
    fig = Figure(figsize=(5.9 * len(views), 6.4))
    fig.suptitle(title if title is not None else grasp_title(result, getattr(obj, "name", None)), fontsize=12)
    extent = np.vstack([tris.reshape(-1, 3), grasp.points()])
    bar_mm = nice_length(float(np.ptp(extent, axis=0).max()))
    panels = []
    for k, view in enumerate(views):
        ax = fig.add_subplot(1, len(views), k + 1, projection="3d", computed_zorder=False)
        label = _view_label(view, hand) + ("; table level" if table and view != "palm" else "")
        panels.append(_draw_panel(ax, view, grasp, tris, com, hand, scene, bar_mm, label))
    _legend(fig, grasp, scene, bool(touching.any()), ncol=6, hand=hand)
    fig.subplots_adjust(left=0.0, right=1.0, bottom=0.11, top=0.88, wspace=0.0)
    zoom_to_content(fig, panels)
    return save(fig, path, dpi)


def plot_candidates(
    result: Any,
    obj: Any,
    pose: np.ndarray | None = None,
    path: str | os.PathLike = "candidates.png",
    title: str | None = None,
    hand: HandModel | None = None,
    view: str = "side",
    dpi: int = 90,
    scene: Any = None,
    columns: int = 3,
) -> str:
    """Small multiples: one panel per ranked candidate of ``result`` (best first), each with
    the object, the scene, the pre-grasp and the approach, in the same ``view``; write a PNG.

    Parameters are those of :func:`plot_grasp`; ``columns`` panels per row.
    """
    hand = hand or load_hand()
    if view not in _VIEW_LABELS:
        raise ValueError(f"view: expected one of {sorted(_VIEW_LABELS)}, got {view!r}")
    candidates = list(result.candidates)
    if not candidates:
        raise ValueError("result: no candidates to draw")
    tris, com = _object_geometry(obj, _pose_of(result, pose))
    grasps = [_grasp_of(c, hand) for c in candidates]
    extent = np.vstack([tris.reshape(-1, 3)] + [g.points() for g in grasps])
    bar_mm = nice_length(float(np.ptp(extent, axis=0).max()))
    cols = max(1, min(columns, len(candidates)))
    rows = math.ceil(len(candidates) / cols)
    height = 4.5 * rows + 1.6
    fig = Figure(figsize=(4.3 * cols, height))
    name = getattr(obj, "name", None) or "object"
    fig.suptitle(title if title is not None else
                 f"{name}: {len(candidates)} ranked {str(result.algorithm).upper()} candidates, "
                 f"{_view_label(view, hand).split(' (')[0]}", fontsize=12)
    panels = []
    for k, (cand, grasp) in enumerate(zip(candidates, grasps)):
        ax = fig.add_subplot(rows, cols, k + 1, projection="3d", computed_zorder=False)
        panels.append(_draw_panel(ax, view, grasp, tris, com, hand, scene, bar_mm, None))
        ax.set_title(candidate_title(cand), fontsize=9)
    _legend(fig, grasps[0], scene, False, ncol=7, hand=hand)
    fig.subplots_adjust(left=0.0, right=1.0, bottom=0.8 / height, top=1 - 0.8 / height, wspace=0.0, hspace=0.15)
    zoom_to_content(fig, panels)
    return save(fig, path, dpi)


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
    return save(fig, path, dpi)
