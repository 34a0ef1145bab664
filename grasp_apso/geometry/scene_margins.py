"""The decoder's scene check: how far the hand stays from the scene (support planes,
boxes, spheres, cylinders) at the grasp and along the approach, and whether its open
pre-shape passes the object on the way in; python wrappers of
:mod:`grasp_apso.geometry.scene_kernels` over a ``GraspModel`` with a scene
(:func:`grasp_apso.geometry.decoder.with_scene`).

Margins are distances minus the clearance, in m: negative means too close (illegal).
Only their sign and how negative they are are read (the fitness's penalty), so gaps are
computed up to :data:`SCENE_HORIZON` beyond the clearance only.
"""

from __future__ import annotations

import numpy as np

from . import palm_kernels, scene_kernels
from .link_points import APPROACH_COEFF, APPROACH_JOINT_COLUMNS, JOINT_COLUMNS

#: Scene gaps are computed up to this far beyond the clearance (m); farther is "clear".
SCENE_HORIZON = 0.002
#: Finger gaps are reduced by this (m), at least: against obstacles along the approach the
#: link spheres leave up to ``GraspModel.approach_cover`` of the capsules out (1.0 mm for
#: the built-in hand); at the grasp the capsules and against planes the joints are exact.
FINGER_COVER_MARGIN = 0.001
#: Along the approach the open hand may touch the object only in the last this many m
#: before the grasp (``hand_fcl.CONTACT_ZONE``); elsewhere a finger whose link spheres
#: come within APPROACH_TOUCH of it makes the particle illegal (scene_margin < 0).
APPROACH_CONTACT_ZONE = 0.010
APPROACH_TOUCH = 0.0005
#: Least step (m) of the approach's tracing past the object, and the most (m) it reports
#: (farther is "clear": only a touch makes the particle illegal).
APPROACH_MIN_STEP = 0.002
APPROACH_GAP_CAP = 0.01


def _scene_arrays(model) -> tuple:
    """The scene's packed arrays in the order the kernels take them."""
    sc = model.scene
    return (sc["planes"], sc["box_inv"], sc["box_half"], sc["sphere_center"], sc["sphere_radius"],
            sc["cyl_inv"], sc["cyl_radius"], sc["cyl_half_height"])


def finger_path_margins(model, rows, rot, trans, planes, distal0, proximal0) -> np.ndarray:
    """Scene margin (R,) m of the finger rows' open pre-shape along the approach
    (:func:`grasp_apso.geometry.scene_kernels.finger_path_gaps`; against obstacles at the
    approach points, every other link sphere: their gaps leave up to
    ``model.approach_cover`` of the capsules out, which is subtracted)."""
    gaps = np.empty(len(rows))
    scene_kernels.finger_path_gaps(
        rows, rot, trans, planes, model.link_lengths, float(model.hand.coupling_ratio),
        np.ascontiguousarray(distal0).reshape(-1), np.ascontiguousarray(proximal0).reshape(-1),
        APPROACH_COEFF, model.approach_radii, APPROACH_JOINT_COLUMNS, model.joint_radii, model.link_radii,
        model.approach_distance,
        model.scene_clearance + SCENE_HORIZON, *_scene_arrays(model), gaps,
    )
    return gaps - model.scene_clearance - max(FINGER_COVER_MARGIN, model.approach_cover)


def finger_grasp_margins(model, rows, rot, pts) -> np.ndarray:
    """Scene margin (R,) m of the finger rows' closed pose ``pts`` (R, K, 3) at the grasp
    (:func:`grasp_apso.geometry.scene_kernels.finger_grasp_gaps`)."""
    gaps = np.empty(len(rows))
    scene_kernels.finger_grasp_gaps(
        rows, rot, JOINT_COLUMNS, model.joint_radii, model.link_radii, np.ascontiguousarray(pts),
        model.scene_clearance + SCENE_HORIZON, *_scene_arrays(model), gaps,
    )
    return gaps - model.scene_clearance - FINGER_COVER_MARGIN


def palm_scene_margins(model, wrist: np.ndarray) -> np.ndarray:
    """Scene margin (P,) m (least distance minus the clearance, negative: too close) of
    the palm box at wrists (P, 4, 4) (object frame), swept over the approach; ``inf``
    without a scene. Cheap (no fingers): GRG screens wrists with it before decoding."""
    if model.scene is None:
        return np.full(len(wrist), np.inf)
    gaps = np.empty(len(wrist))
    palm_kernels.palm_scene_gaps(
        np.ascontiguousarray(wrist[:, :3, :3]), np.ascontiguousarray(wrist[:, :3, 3]), model.palm_center,
        model.palm_half_extents, model.approach_distance, model.scene_clearance + SCENE_HORIZON,
        *_scene_arrays(model), gaps)
    return gaps - model.scene_clearance


def approach_object_gaps(model, rows, rot, trans, planes, distal0, proximal0) -> np.ndarray:
    """Clearance (R,) m of the open pre-shape of the finger rows from the object along the
    approach, before the last :data:`APPROACH_CONTACT_ZONE` (0 = touching)."""
    gaps = np.empty(len(rows))
    sdf = model.sdf
    scene_kernels.approach_object_gaps(
        rows, rot, trans, planes, model.link_lengths, float(model.hand.coupling_ratio),
        np.ascontiguousarray(distal0).reshape(-1), np.ascontiguousarray(proximal0).reshape(-1),
        APPROACH_COEFF, model.approach_radii, sdf._values64, sdf._origin64, float(sdf.spacing),
        model.object_box[0], model.object_box[1], model.approach_distance, APPROACH_CONTACT_ZONE,
        APPROACH_MIN_STEP, APPROACH_GAP_CAP, gaps,
    )
    return gaps


def trace_approaches(model, decoded, rot, trans, planes, distal0, proximal0) -> None:
    """Trace the open hand's approach past the object (the costly part of the scene
    check) for the fingers not traced yet of the particles that are otherwise legal with
    2 or more contacts; a particle illegal anyway is rejected or regenerated whatever
    its approach. Updates ``decoded.scene_margin`` and ``decoded.approach_traced``."""
    ready = decoded.legal(model.settings.max_penetration) & (decoded.n_contacts >= 2)
    todo = np.flatnonzero((ready[:, None] & ~decoded.approach_traced).reshape(-1))
    if todo.size:
        margin = decoded.scene_margin.reshape(-1)
        margin[todo] = np.minimum(margin[todo], approach_object_gaps(
            model, todo, rot, trans, planes, distal0, proximal0) - APPROACH_TOUCH)
        decoded.approach_traced.reshape(-1)[todo] = True
