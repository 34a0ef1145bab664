"""The squeeze of a general hand's grasp: the posture its reply squeezes to and the contact
forces it exerts (DexGraspBench / BODex: ``q_squeeze = q_grasp + K^-1 J^T f``).

A grasp whose contacts can take balanced forces is squeezed with friction-balanced contact
forces of mean normal part ``squeeze_force`` (:func:`balanced_squeeze`); the others by
the simulation's uniform ``squeeze`` along every closing joint (:func:`squeeze_posture`).
With ``simulate`` a grasp that drops is tried again with :func:`firmer_squeeze`.
"""

from __future__ import annotations

import functools
import importlib
import math

import numpy as np

from ..quality.closing import balanced_forces, closing_forces, squeeze_toward_forces

__all__ = ["FIRM_SQUEEZE", "SQUEEZE", "optional_module", "sim_settings", "closing_imbalance", "balanced_squeeze",
           "squeeze_posture", "firmer_squeeze"]

#: With ``simulate``: a grasp that dropped is simulated once more with its squeeze at this
#: share of the force (the balanced forces' ``squeeze_force``, or the uniform squeeze's
#: angle); when that holds, the grasp is held and its reply carries that squeeze. 5/3 of
#: the balanced squeeze's 2.4 N is 4 N, the force this check's squeeze aimed at before it
#: was set to hold under a stiffer client's servos too (``SimulationSettings.squeeze_force``):
#: grasps of some hands (the Shadow's) need the firmer squeeze in this check. Measured
#: (``bench/held_rate.py --simulate``, seeds 0-2, 63 plans, best grasps held, candidates
#: held), retried at 5/3 / at half the force: Shadow 58, 247 of 268 / 57, 237 of 261;
#: Inspire 58, 259 of 284 / 58, 258 of 283; Allegro-like 60, 262 of 277 / 59, 251 of 271
#: (docs/any-hand-measurements.md, "The stop of 2026-12-06, eighth").
FIRM_SQUEEZE = 5.0 / 3.0

#: The squeeze (rad or m) when the simulation settings are not importable.
SQUEEZE = math.radians(8.0)


def optional_module(name: str):
    """The module ``name``, or None when it cannot be imported (the selection then does
    without the simulation or python-fcl)."""
    try:
        return importlib.import_module(name)
    except ImportError:
        return None


@functools.lru_cache(maxsize=1)
def sim_settings():
    """The simulation's default settings (None when the simulation package is not there):
    one frozen instance, built once (the selection reads them for every grasp it analyses)."""
    settings = optional_module("grasp_apso.simulation.settings")
    return settings.SimulationSettings() if settings is not None else None


def closing_imbalance(model, decoded, obj, solve_from: int = 2) -> tuple[float, bool]:
    """The closing imbalance of one decoded grasp (normal forces of mean ``squeeze_force``,
    :func:`grasp_apso.quality.closing.closing_forces`) and whether its squeeze aims at
    balanced contact forces (:func:`balanced_squeeze`); with fewer than two contacts, or
    without the simulation's settings, imbalance 1 and the uniform squeeze. With fewer than
    ``solve_from`` contacts the imbalance is not solved for (read 1), the squeeze the same."""
    mask = decoded.contact[0]
    settings = sim_settings()
    if mask.sum() < 2 or settings is None:
        return 1.0, False
    if mask.sum() < solve_from:
        return 1.0, True
    fingers = np.flatnonzero(mask)
    points, normals = decoded.contact_points[0][fingers], decoded.contact_normals[0][fingers]
    imbalance = closing_forces(points, normals, np.asarray(obj.center_of_mass, float),
                               float(obj.characteristic_radius), settings.squeeze_force)[1]
    return imbalance, True


def balanced_squeeze(model, decoded, obj, mu: float, settings, report=None,
                     share: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The squeeze of one decoded grasp and the contact forces (contacts, 3) N it exerts:
    the friction-balanced forces of mean normal part ``share * squeeze_force``
    (:func:`grasp_apso.quality.closing.balanced_forces`, friction ``mu``); with the
    python-fcl ``report`` the pads' exact distances to the object are taken up first."""
    fingers = np.flatnonzero(decoded.contact[0])
    points, normals = decoded.contact_points[0][fingers], decoded.contact_normals[0][fingers]
    inv = np.linalg.inv(decoded.root[0])  # object -> root frame
    points_root = points @ inv[:3, :3].T + inv[:3, 3]
    normals_root = normals @ inv[:3, :3].T
    gaps = None
    if report is not None and getattr(report, "link_distance", None) is not None:
        links = list(report.links)
        gaps = np.array([float(report.link_distance[links.index(model.hand.fingers[f].pad_link)])
                         if model.hand.fingers[f].pad_link in links else 0.0 for f in fingers])
        gaps = np.where(np.isfinite(gaps), gaps, 0.0)
    forces, _ = balanced_forces(points, normals, np.asarray(obj.center_of_mass, float),
                                float(obj.characteristic_radius), mu, share * settings.squeeze_force)
    squeeze = squeeze_toward_forces(model.hand, decoded.q[0], fingers, points_root, normals_root,
                                    forces @ inv[:3, :3].T, settings.kp * model.hand.servo_weight,
                                    settings.max_torque * model.hand.servo_force_scale, gaps=gaps)
    return squeeze, forces


def squeeze_posture(model, q: np.ndarray, share: float = 1.0) -> np.ndarray:
    """The grasp posture q (n,) pushed the simulation's ``squeeze`` further along every
    joint's closing sense, within the limits: the same posture as
    :func:`grasp_apso.simulation.any_hand.squeezed_positions` (which imports MuJoCo, so it is
    not called for every plan)."""
    settings = sim_settings()
    amount = share * (settings.squeeze if settings is not None else SQUEEZE)
    hand = model.hand
    out = np.array(q, dtype=float)
    for finger in hand.fingers:
        for joint, sense in zip(finger.joints, finger.closing):
            out[hand.actuated_joints.index(joint)] += sense * amount
    return np.clip(out, hand.lower, hand.upper)


def firmer_squeeze(model, c, obj, friction: float) -> tuple[np.ndarray, np.ndarray | None]:
    """The squeeze of a verified grasp c (``AnyChecked``: its decoding, contact forces and
    python-fcl report) at :data:`FIRM_SQUEEZE` of its force: (posture (n,), contact forces
    (contacts, 3) N, None for the uniform squeeze)."""
    if c.forces is None:
        return squeeze_posture(model, c.decoded.q[0], FIRM_SQUEEZE), None
    return balanced_squeeze(model, c.decoded, obj, friction, sim_settings(), c.fcl, FIRM_SQUEEZE)
