"""A pad under another link of its fingertip's body: the pad moves onto that link.

Some descriptions give a fingertip's skin or cover as a link of its own, fixed to the
distal phalanx: TetherIA's Aero Hand Open fixes ``right_*_tip_link`` (4-6 mm thick over
the pad side) to each distal link, whose bare end reaches 2 mm farther and so is taken
for the tip (:func:`.derive._tip_link`). The pad found on the phalanx then lies under
the cover, and the cover is what touches: the search closed every finger on the cover's
spheres with its pad 4-6 mm off the object, no grasp had the thumb in contact, and none
of 63 best grasps held (``bench/held_rate.py``, the 21 objects on a table, seeds 0-2);
with the pads on the covers 52 of 63 held. :func:`covering_link` looks along the pad's
outward normal for a link fixed to the tip link whose geometry stands more than
:data:`COVERED` in front of the pad; the pad is then found on that link at the point
where the normal leaves it.

A sensor plate fixed inside a fingertip or beside its pad (dex-urdf's Allegro with FSRs),
or a fingertip link fixed to the distal phalanx beyond it (Allegro, the paper hand's
URDF), stands nowhere in front of the pad: of 68 descriptions loaded (dex-urdf's,
menagerie's, the other published hands of docs/hands.md and their variants), only the
Aero hand's four files have covered pads (4.1-6.4 mm); the 26 hands whose loaded models
are compared between changes are unchanged.
"""

from __future__ import annotations

import numpy as np

from .spheres import union_signed_distance

__all__ = ["covering_link", "COVERED", "REACH"]

#: A link of the fingertip's body covers the pad when its geometry stands more than this
#: (m) in front of the pad along the pad's outward normal (more than the sphere covers'
#: stray, :mod:`.spheres`).
COVERED = 0.002
#: How far in front of the pad (m) a cover is looked for, and the step along the normal.
REACH = 0.015
STEP = 1e-4
#: Central-difference step (m) of the pad's outward normal.
_NORMAL_STEP = 2e-4


def fixed_below(hand, link: str) -> list[tuple[str, np.ndarray]]:
    """The links with collision geometry fixed below ``link`` (no joint motion between
    them): (name, pose (4, 4) in ``link``'s frame), file order."""
    i_link = hand.link_index(link)
    poses = hand.link_transforms_batch(np.clip(0.0, hand.lower, hand.upper)[None])[0]
    inverse = np.linalg.inv(poses[i_link])
    out = []
    for i, name in enumerate(hand.links):
        if i == i_link or not hand.collision.get(name):
            continue
        j = i
        while j >= 0 and j != i_link and not hand.motions[j]:
            j = hand.link_parents[j]
        if j == i_link:
            out.append((name, inverse @ poses[i]))
    return out


def outward_normal(geoms, point: np.ndarray) -> np.ndarray:
    """The unit outward normal (3,) of the union of ``geoms`` at a surface point (link
    frame): the signed distance's central-difference gradient."""
    h = _NORMAL_STEP
    offsets = np.vstack([np.eye(3), -np.eye(3)]) * h
    d = union_signed_distance(geoms, np.asarray(point, float)[None] + offsets)
    g = d[:3] - d[3:]
    norm = np.linalg.norm(g)
    return g / norm if norm > 0 else g


def covering_link(hand, link: str, center: np.ndarray) -> tuple[str, np.ndarray, float, np.ndarray] | None:
    """The link covering the pad ``center`` (3,) on ``link`` (link frame, m): (its name,
    the point (3,) where the pad's outward normal leaves it, in its own frame, the cover's
    thickness there m, its pose (4, 4) in ``link``'s frame), the thickest when several
    cover it; None when no link fixed to ``link`` stands more than :data:`COVERED` in
    front of the pad."""
    normal = outward_normal(hand.collision[link], center)
    if not np.any(normal):
        return None
    ts = np.arange(0.0, REACH + 0.5 * STEP, STEP)
    ray = np.asarray(center, float) + ts[:, None] * normal
    best = None
    for name, pose in fixed_below(hand, link):
        local = (ray - pose[:3, 3]) @ pose[:3, :3]  # into the other link's frame
        inside = np.flatnonzero(union_signed_distance(hand.collision[name], local) < 0.0)
        if len(inside) and ts[inside[-1]] > COVERED and (best is None or ts[inside[-1]] > best[2]):
            best = (name, local[inside[-1]], float(ts[inside[-1]]), pose)
    return best
