"""A verified grasp's contacts on the object's exact surface and on the pad bodies.

The search places a finger's contact at the object's surface point nearest its pad as the
signed-distance grid reads it (one Newton step,
:meth:`grasp_apso.geometry.sdf.ObjectSDF.closest_surface_point`): off the mesh by up to
3 mm where the grid rounds a rim or an edge (measured, ``bench/unseen_hands.py --quick``
on the seven dex-urdf hands: LEAP's thumb on the mug 3.1 mm, the Shadow's on the sphere
0.9 mm; the median 4-17 um), and now and then more than
:data:`~.exact_touch.TOUCH_GAP` from the finger's pad body (the pad link and the links fixed
to it, exact geometry) where the grid's nearest point and the body's differ (6 contacts of
the 199 candidates there, 2.0-2.2 mm from their pad body). The verification's epsilon and the reply's contacts
are these points, and a client executes and checks the contacts it receives, so
:func:`exact_contacts` moves each onto the mesh (its exact closest point,
:meth:`grasp_apso.model.hands.mesh_distance.MeshDistance.closest`) and, when that point
lies farther than ``TOUCH_GAP`` from the finger's pad body, to the object's point nearest
that body (the body's surface samples read in the exact distance,
:func:`.exact_seat.pad_nearest`) when that is nearer it: the rule of
:func:`grasp_apso.search.any_hand_select._touch`, read on the exact distance.
"""

from __future__ import annotations

import numpy as np

from .exact_seat import pad_body_distances, pad_body_rows, pad_nearest
from .exact_touch import TOUCH_GAP

__all__ = ["exact_contacts", "RECLOSE_FROM"]

#: m: when one of a grasp's contacts moved farther than this, its closure and closing
#: imbalance are computed again (a smaller move changes the epsilon by about move / object
#: size, 0.2 % for 0.1 mm on a 5 cm object, and the analysis costs milliseconds).
RECLOSE_FROM = 1e-4


def exact_contacts(model, hc, shape, q: np.ndarray, root: np.ndarray, fingers: np.ndarray,
                   points: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The contacts of one grasp on the object's mesh and on the fingers' pad bodies.

    Parameters
    ----------
    model : AnyHandModel
    hc : HandCollision
        The hand's exact geometry.
    shape : ObjectShape
        The object (its exact distance ``shape.distance``).
    q : (n,) float, rad or m; root : (4, 4) float, the root link in the object frame.
    fingers : (C,) int; points, normals : (C, 3) float
        The contacting fingers and their contacts, object frame (m, unit outward normals).

    Returns
    -------
    points, normals : (C, 3) float
        On the mesh; a normal is the grid's gradient where its point moved to the pad
        body's nearest point, else as given.
    """
    points = np.array(points, dtype=float).reshape(-1, 3)
    normals = np.array(normals, dtype=float).reshape(-1, 3)
    if len(points) == 0:
        return points, normals
    points = shape.distance.closest(points)[1]
    gaps = pad_body_distances(model.hand, q, root, fingers, points)
    for i in np.flatnonzero(gaps > TOUCH_GAP):
        parts = np.flatnonzero(np.isin(hc.shapes.part_link, pad_body_rows(model.hand, hc, int(fingers[i]))))
        if len(parts) == 0:  # (a pad body without collision geometry: inf, stays)
            continue
        # the object's point nearest the body's surface sample nearest it (exact distances)
        other = shape.distance.closest(pad_nearest(hc, q, root, shape, parts)[1][None])[1][0]
        if pad_body_distances(model.hand, q, root, fingers[[i]], other[None])[0] < gaps[i]:
            points[i] = other
            normals[i] = model.sdf.distance_and_gradient(other[None])[1][0]
    return points, normals
