"""Triangles of a hand's own collision geometry in a posture, for the pictures and the RViz
markers (no matplotlib, no ROS here).

- :func:`decimate_for_drawing`: simplify a triangle mesh by vertex clustering.
- :func:`hand_triangles`: every link's collision geometry
  (:meth:`LinkGeometry.to_trimesh <grasp_apso.model.hands.geometry.LinkGeometry.to_trimesh>`)
  placed by ``hand.link_transforms(q)`` and the root link's pose, decimated to about
  :data:`MAX_DRAWN_TRIANGLES` for the whole hand. The link meshes are decimated once per
  hand (cached by ``hand.source_hash`` through :mod:`grasp_apso.cache`).
"""

from __future__ import annotations

import re

import math
from typing import Any

import numpy as np

from ..cache import cached
from .palette import FINGER_COLORS, PALM_COLOR

__all__ = ["MAX_DRAWN_TRIANGLES", "EXTRA_FINGER_COLORS", "decimate_for_drawing", "finger_color", "hand_triangles",
           "link_colors", "link_meshes"]

#: Colours of fingers whose names the palette does not know (Okabe-Ito, then greys).
EXTRA_FINGER_COLORS = ("#56B4E9", "#F0E442", "#000000", "#7F7F7F", "#B07AA1")

#: Meshes with more triangles are simplified (vertex clustering) before drawing.
MAX_DRAWN_TRIANGLES = 3000
#: Fewest triangles a link keeps when the hand's budget is shared out.
_MIN_LINK_TRIANGLES = 24


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


#: Other names of the palette's fingers (the Shadow hand's ff, mf, rf, lf, th; pinky).
_ALIASES = {"ff": "index", "first": "index", "mf": "middle", "rf": "ring", "lf": "little", "pinky": "little",
            "th": "thumb"}


def finger_color(name: str, index: int) -> str:
    """The palette's colour for a finger called like the paper's (index, thumb, ...),
    otherwise one of ``EXTRA_FINGER_COLORS`` by the finger's index."""
    key = name.lower()
    for known, color in FINGER_COLORS.items():
        if known in key:
            return color
    for token in re.split(r"[^a-z]+", key):
        if token in _ALIASES:
            return FINGER_COLORS[_ALIASES[token]]
    return EXTRA_FINGER_COLORS[index % len(EXTRA_FINGER_COLORS)]


def link_colors(hand: Any) -> dict[str, str]:
    """Every link with collision geometry -> its finger's colour (:func:`finger_color`),
    the palm's for the links no finger moves."""
    colors: dict[str, str] = {}
    for i, finger in enumerate(hand.fingers):
        for link in hand.finger_links(finger):
            colors.setdefault(link, finger_color(finger.name, i))
    return {link: colors.get(link, PALM_COLOR) for link in hand.collision}




def link_meshes(hand: Any, max_triangles: int = MAX_DRAWN_TRIANGLES) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each link's collision geometry as one mesh in the link frame, decimated so that the
    hand has about ``max_triangles`` triangles (shared out by the links' own counts).

    Returns
    -------
    dict link -> (vertices (V, 3) float m, faces (T, 3) int); links without geometry left out.
    """
    key = f"{hand.source_hash}:{int(max_triangles)}"

    def build() -> dict:
        raw = {}
        for link, geoms in hand.collision.items():
            parts = [g.to_trimesh() for g in geoms]
            if not parts:
                continue
            offsets = np.cumsum([0] + [len(m.vertices) for m in parts[:-1]])
            v = np.vstack([np.asarray(m.vertices, float) for m in parts])
            f = np.vstack([np.asarray(m.faces, np.int64) + o for m, o in zip(parts, offsets)])
            raw[link] = (v, f)
        total = sum(len(f) for _, f in raw.values()) or 1
        out = {}
        for link, (v, f) in raw.items():
            budget = max(_MIN_LINK_TRIANGLES, int(max_triangles * len(f) / total))
            out[link] = decimate_for_drawing(v, f, budget)
        return out

    return cached("hand_drawing", key, build)


def hand_triangles(hand: Any, q: np.ndarray, root_pose: np.ndarray,
                   max_triangles: int = MAX_DRAWN_TRIANGLES) -> dict[str, np.ndarray]:
    """The hand's collision geometry at posture ``q`` with its root link at ``root_pose``.

    Parameters
    ----------
    hand : grasp_apso.model.hands.HandModel
    q : (n,) float -- over ``hand.actuated_joints`` (rad, or m for a prismatic joint)
    root_pose : (4, 4) float -- the root link in the drawing frame (a grasp's ``wrist_pose``)

    Returns
    -------
    dict link -> (T, 3, 3) float, m -- each link's triangles in the drawing frame
    """
    poses = hand.link_transforms(np.asarray(q, dtype=float))
    root = np.asarray(root_pose, dtype=float)
    out = {}
    for link, (v, f) in link_meshes(hand, max_triangles).items():
        tf = root @ poses[link]
        out[link] = (v @ tf[:3, :3].T + tf[:3, 3])[f]
    return out
