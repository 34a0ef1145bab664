"""The points along a finger's links where the decoder checks it: (link, fraction of
the link) pairs, their planar-chain coefficients, and the named subsets (joints, pad).

A point (link k, fraction f) is ``sum_j C[j] * segment_j`` of the finger's planar chain
(segments: the three link vectors in the flexion plane); the kernels of
:mod:`grasp_apso.geometry.kernels` and :mod:`grasp_apso.geometry.scene_kernels` read the
(3, K) coefficient arrays.
"""

from __future__ import annotations

import numpy as np

#: Points along the links checked while closing: (link, fraction). The last one is the
#: fingertip pad centre. The finger base (link 0, fraction 0) does not move while closing
#: and is checked at the final pose only. Spacing about 11 mm for 9 mm radii: a capsule
#: may dip up to about 2 mm into the surface between two spheres while sweeping; the
#: dense final check catches that.
SWEEP_POINTS = np.array(
    [[0, 0.25], [0, 0.5], [0, 0.75], [0, 1.0], [1, 1 / 3], [1, 2 / 3], [1, 1.0],
     [2, 1 / 3], [2, 2 / 3], [2, 1.0]]
)
#: Final check of the closed pose: base, joints, and spheres every ~4 mm (the capsule is
#: covered to within 0.3 mm); the last point is the pad.
FINAL_POINTS = np.array(
    [[0, 0.0]] + [[0, f] for f in np.linspace(1 / 12, 1.0, 12)]
    + [[1, f] for f in np.linspace(1 / 8, 1.0, 8)] + [[2, f] for f in np.linspace(1 / 7, 1.0, 7)]
)
#: The joints among them: base, PIP, DIP, tip (as a list and as the kernels' int array).
JOINT_INDEX = [0, 12, 20, 27]
JOINT_COLUMNS = np.array(JOINT_INDEX, dtype=np.int64)
#: The proximal link and the first 5/8 of the middle link (not the knuckle).
NON_TIP_LINKS = slice(1, 18)
#: From the middle of the proximal link to the pad.
CLEAR_OF_PALM = slice(7, 28)


def link_coefficients(points: np.ndarray) -> np.ndarray:
    """(3, K): a point (link k, fraction f) is sum_j C[j] * segment_j of the planar chain."""
    coeff = np.zeros((3, len(points)))
    for col, (link, frac) in enumerate(points):
        coeff[: int(link), col] = 1.0
        coeff[int(link), col] = frac
    return coeff


SWEEP_COEFF = link_coefficients(SWEEP_POINTS)
FINAL_COEFF = link_coefficients(FINAL_POINTS)
#: Every other final point and the pad (the joints among them): the open hand along the
#: approach is checked at these, against the object and against obstacles.
APPROACH_INDEX = np.r_[np.arange(0, len(FINAL_POINTS) - 1, 2), len(FINAL_POINTS) - 1]
APPROACH_COEFF = np.ascontiguousarray(FINAL_COEFF[:, APPROACH_INDEX])
#: The joints' columns among the approach points.
APPROACH_JOINT_COLUMNS = np.searchsorted(APPROACH_INDEX, JOINT_INDEX).astype(np.int64)
if not np.array_equal(APPROACH_INDEX[APPROACH_JOINT_COLUMNS], JOINT_INDEX):
    raise RuntimeError("link_points: the approach points must hold every joint")


def uncovered_depth(index: np.ndarray, link_lengths: np.ndarray, link_radii: np.ndarray, pad_radius: float) -> float:
    """Deepest part (m) of a finger's capsules outside the spheres at the final points
    ``index`` (consecutive points on a link, spheres of their links' radii, the pad's at
    the tip), over the fingers of link_lengths (5, 3) m and radii (3,) m: between two
    spheres of radius r a distance d apart, a capsule of radius R sticks out by
    ``R - sqrt(r^2 - (d / 2)^2)``."""
    pts = FINAL_POINTS[np.asarray(index)]
    chain = pts[:, 0] + pts[:, 1]  # link + fraction: distance along the chain in links
    radii = np.array([link_radii[int(k)] for k in pts[:, 0]])
    radii[np.asarray(index) == len(FINAL_POINTS) - 1] = pad_radius
    worst = 0.0
    for i in range(len(pts) - 1):
        link = min(int(np.ceil(chain[i + 1])) - 1, 2)  # the link the pair lies on
        r = min(radii[i], radii[i + 1])
        for length in np.asarray(link_lengths)[:, link]:
            half = 0.5 * (chain[i + 1] - chain[i]) * length
            worst = max(worst, link_radii[link] - np.sqrt(max(r * r - half * half, 0.0)))
    return float(worst)

for _table in (SWEEP_POINTS, FINAL_POINTS, JOINT_COLUMNS, SWEEP_COEFF, FINAL_COEFF, APPROACH_INDEX, APPROACH_COEFF,
               APPROACH_JOINT_COLUMNS):
    _table.flags.writeable = False
