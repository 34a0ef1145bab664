"""The object along a general hand's approach, in the decoder (the grid's signed distance).

The python-fcl verification (:func:`.any_hand_fcl.approach_report`) refuses a grasp whose
open hand passes through the object on its way in from the pre-grasp; the search must
see it too, or it converges on such grasps and every one of them is refused at the end
(measured: the Inspire hand on the apple, the orange and the soup can on a table: the
thumb, swung under the object by its rotation joint, sweeps through it 50-55 mm before
the grasp; 72 of 72 verified grasps refused, no plan). :func:`object_approach_margins`
measures, for the open pre-shape moved back along the palm normal by each of
:data:`APPROACH_STEPS` beyond :data:`.hand_fcl.CONTACT_ZONE`, the least clearance of the
hand's collision spheres from the object (one compiled kernel, :func:`.any_hand_kernels.approach_clearance`:
the fingers posed once for all the retreats, bounding spheres beyond the least clearance
found so far skipped; measured 8x faster than a look-up per retreat, Shadow hand and mug;
a whole finger skipped at a retreat by one sphere bounding its links: 4000 random particles,
the mug, 196 -> 30 ms for the Shadow hand, 83 -> 26 ms for the paper hand's URDF, the same
clearances below the cut).
"""

from __future__ import annotations

import numpy as np

from . import any_hand_kernels as hk
from .hand_fcl import CONTACT_ZONE

__all__ = ["object_approach_margins", "APPROACH_STEPS", "APPROACH_MARGIN"]

#: Retreats checked, as fractions of the approach distance (the python-fcl check steps every
#: 5 mm; a link sweeping through the object is inside it for a stretch of the approach).
APPROACH_STEPS = tuple(np.linspace(0.125, 1.0, 8))
#: m: the open hand's spheres keep this far from the object on the way in (a link's exact
#: mesh may stick out of its sphere cover by a millimetre or two, and the steps are 10 mm apart).
APPROACH_MARGIN = 0.002
#: Clearances above this (m) are lower bounds: only the sign of the margin decides.
CUTOFF = 0.004


def object_approach_margins(model, rot: np.ndarray, trans: np.ndarray, q_open: np.ndarray,
                            approach_distance: float) -> np.ndarray:
    """Least clearance (m; negative: inside the object) of the open hand along the approach.

    Parameters
    ----------
    model : AnyHandModel
    rot : (P, 3, 3) float; trans : (P, 3) float, m
        The root at the grasp, object frame.
    q_open : (P, n) float, rad or m
        The open pre-shapes.
    approach_distance : float, m

    Returns
    -------
    (P,) float, m: the clearance less :data:`APPROACH_MARGIN`; ``inf`` when no retreat lies
    beyond the contact zone.
    """
    t = model.tables
    backs = np.array([f * float(approach_distance) for f in APPROACH_STEPS], dtype=float)
    backs = np.ascontiguousarray(backs[backs > CONTACT_ZONE])
    if len(backs) == 0:
        return np.full(len(rot), np.inf)
    rot = np.ascontiguousarray(rot)
    approach = np.ascontiguousarray(rot @ t.basis[:, 2])                # (P, 3) object frame
    best = np.empty(len(rot))
    hk.approach_clearance(model.sdf._values64, model.sdf._origin64, float(model.sdf.spacing), rot,
                          np.ascontiguousarray(trans), approach, backs, np.ascontiguousarray(q_open), t.palm_groups,
                          t.palm_pose, t.palm_bound, model.kin, CUTOFF, best)
    return best - APPROACH_MARGIN
