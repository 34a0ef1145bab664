"""A pad under another link of its fingertip's body: the pad moves onto that link.

Some descriptions give a fingertip's skin or cover as a link of its own, fixed to the
distal phalanx: TetherIA's Aero Hand Open fixes ``right_*_tip_link`` (4-6 mm thick over
the pad side) to each distal link, whose bare end reaches 2 mm farther and so is taken
for the tip (:func:`.derive._tip_link`). The pad found on the phalanx then lies under
the cover, and the cover is what touches: the search closed every finger on the cover's
spheres with its pad 4-6 mm off the object, no grasp had the thumb in contact, and none
of 63 best grasps held (``bench/held_rate.py``, the 21 objects on a table, seeds 0-2);
with the pads on the covers 52 of 63 held. :func:`covering_link` looks along the pad's
outward normal for a link of the tip link's rigid body (fixed below it, or beside it on
the same phalanx) whose geometry stands more than :data:`COVERED` in front of the pad; the
pad is then found on that link at the point where the normal leaves it.

A sensor plate fixed inside a fingertip or beside its pad (dex-urdf's Allegro with FSRs),
or a fingertip link fixed to the distal phalanx beyond it (Allegro, the paper hand's
URDF), stands nowhere in front of the pad: of 68 descriptions loaded (dex-urdf's,
menagerie's, the other published hands of docs/hands.md and their variants), only the
Aero hand's four files have covered pads (4.1-6.4 mm); the 26 hands whose loaded models
are compared between changes are unchanged. Looking beside the tip link too (the links
fixed to the phalanx it is fixed to) moved the pads of DexRobot's DexHand021 URDF alone
of the 109 descriptions loaded on 2026-12-06 (the paper hand's URDF and the test hands
included).
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


def body_links(hand, link: str) -> list[tuple[str, np.ndarray]]:
    """The other links with collision geometry of ``link``'s rigid body (the nearest link
    at or above it that a joint moves, and every link fixed below that one: no joint motion
    between them): (name, pose (4, 4) in ``link``'s frame), file order. Besides the links
    fixed below ``link``, the body holds the phalanx it is fixed to and the links fixed
    beside it: DexRobot's DexHand021 takes its fingertip's nail shell for the tip link (it
    reaches farthest), and the phalanx's own palmar face and its tactile pad, fixed beside
    the nail, stand 4 mm in front of the pad found on it."""
    i_link = hand.link_index(link)
    poses = hand.link_transforms_batch(np.clip(0.0, hand.lower, hand.upper)[None])[0]
    inverse = np.linalg.inv(poses[i_link])
    base = hand.rigid_base(i_link)
    return [(name, inverse @ poses[i]) for i, name in enumerate(hand.links)
            if i != i_link and hand.collision.get(name) and hand.rigid_base(i) == base]


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
    cover it; None when no other link of ``link``'s rigid body (:func:`body_links`) stands
    more than :data:`COVERED` in front of the pad."""
    normal = outward_normal(hand.collision[link], center)
    if not np.any(normal):
        return None
    ts = np.arange(0.0, REACH + 0.5 * STEP, STEP)
    ray = np.asarray(center, float) + ts[:, None] * normal
    best = None
    for name, pose in body_links(hand, link):
        local = (ray - pose[:3, 3]) @ pose[:3, :3]  # into the other link's frame
        inside = np.flatnonzero(union_signed_distance(hand.collision[name], local) < 0.0)
        if len(inside) and ts[inside[-1]] > COVERED and (best is None or ts[inside[-1]] > best[2]):
            best = (name, local[inside[-1]], float(ts[inside[-1]]), pose)
    return best
