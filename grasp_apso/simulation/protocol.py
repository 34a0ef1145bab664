"""The simulation check of a grasp (MuJoCo), the DexGraspNet / DexGraspBench way.

Protocol (:func:`simulate_grasp`)
---------------------------------
1. Build the scene (:mod:`grasp_apso.simulation.mjcf`): the palm welded at the grasp pose,
   the fingers at the pre-grasp posture, the object a free body at its pose, gravity off,
   the support planes as plane geoms (they take part in the closing only).
2. Close: the 15 position servos move linearly from the pre-grasp to the grasp posture in
   ``close_time`` (0.3 s), then to the *squeezed* posture in ``squeeze_time`` (0.1 s):
   every flexion (distal theta_i1 and proximal theta_i2, not the pivots) ``squeeze``
   (8 degrees) further toward the palm, clipped to the joint limits; then
   ``settle_time`` (0.2 s) at that target, longer (up to ``max_settle_time``, 1 s) until
   the object is at rest. The middle joints follow the distal ones
   through the eq. 1 equality constraint.
3. Switch the support planes' contacts off (the object is in the hand, off the table:
   no plane may carry it) and save the squeezed state. For each direction +x, -x, +y,
   -y, +z, -z of the planning frame: restore it, apply ``object_mass * disturbance``
   (10 m/s^2, so 1 N for 0.1 kg) at the object's centre of mass (``xfrc_applied``) for
   ``duration`` (2 s), and track how far the centre of mass is from its *planned*
   position and how much the object has turned from its *planned* orientation (the
   squeezed state counts too: a grasp that shoved the object while closing is judged on
   it, as DexGraspBench does). A direction fails (and stops early) once the shift reaches
   ``max_shift`` (5 cm) or the turn ``max_turn`` (15 degrees). The phases are
   :mod:`grasp_apso.simulation.phases`, shared with any hand.
4. Held: no direction failed.

Physics choices (justified in :class:`SimulationSettings`): implicit-fast integrator,
elliptic friction cones with ``impratio`` 10 (little creep under tangential load, as
MuJoCo's manipulation models use), ``condim`` 4 (torsional friction at the pads),
friction mu 0.5 (the planner's), timestep 4 ms with contact time constant 20 ms (MuJoCo's
default; a stiff contact needs the time constant >= 2 timesteps), joint armature and
damping that make the servos critically damped. The run is deterministic: the same
input gives the same output (MuJoCo is deterministic on one thread; CoACD uses a fixed
seed and its result is cached).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError, SimulationError
from ..model.hand import FINGER_NAMES, HandModel
from . import mjcf
from .convex import convex_parts
from .phases import DIRECTIONS, disable_contacts, disturb, planned_reference, ramp, rigid_transform, settle
from .settings import SimulationSettings

__all__ = ["SimulationSettings", "SimResult", "simulate_grasp", "build_model", "DIRECTIONS",
           "squeezed_posture"]



@dataclass(frozen=True)
class SimResult:
    """Outcome of :func:`simulate_grasp`.

    Attributes
    ----------
    held : bool
        The object stayed in the hand in every direction.
    max_shift : float, m
        Largest distance of the centre of mass from its planned position over the
        directions tried.
    max_turn : float, rad
        Largest rotation from the planned orientation over the directions tried.
    per_direction : tuple of (str, float, float, bool)
        ``(direction, shift m, turn rad, held)`` for each direction tried (all six unless
        ``stop_at_first_failure``).
    sim_time : float, s
        Wall time of the whole check (model building included).
    """

    held: bool
    max_shift: float
    max_turn: float
    per_direction: tuple[tuple[str, float, float, bool], ...]
    sim_time: float


# ------------------------------------------------------------------------------ input
def _posture(hand: HandModel, value, field_name: str) -> np.ndarray:
    q = np.asarray(value, dtype=float) if value is not None else None
    if q is None or q.ndim != 1 or q.shape[0] not in (15, 18) or not np.all(np.isfinite(q)):
        raise InputError(f"{field_name}: expected 15 (or 18) finite joint values in rad")
    q = q[:15]
    lo, hi = np.asarray(hand.lower[:15]), np.asarray(hand.upper[:15])
    bad = np.flatnonzero((q < lo - 1e-6) | (q > hi + 1e-6))
    if bad.size:
        j = int(bad[0])
        raise InputError(f"{field_name}: {hand.joint_names[j]} = {math.degrees(q[j]):.2f} deg outside "
                         f"[{math.degrees(lo[j]):.1f}, {math.degrees(hi[j]):.1f}] deg")
    return np.clip(q, lo, hi)


def _planes(value) -> np.ndarray | None:
    if value is None:
        return None
    p = np.asarray(value, dtype=float)
    if p.size == 0:
        return None
    if p.ndim == 1 and p.shape == (4,):
        p = p[None]
    if p.ndim != 2 or p.shape[1] != 4 or not np.all(np.isfinite(p)):
        raise InputError("planes: expected (K, 4) finite plane coefficients a, b, c, d")
    bad = np.flatnonzero(np.linalg.norm(p[:, :3], axis=1) < 1e-9)
    if bad.size:
        raise InputError(f"planes: plane {int(bad[0])} has a zero normal (a, b, c)")
    return p


def squeezed_posture(hand: HandModel, grasp_q: np.ndarray, squeeze: float) -> np.ndarray:
    """The grasp posture with every flexion ``squeeze`` rad further, clipped to the limits.

    grasp_q : (15,) rad -> (15,) rad (the pivots are unchanged).
    """
    q = np.array(grasp_q, dtype=float)[:15]
    flex = np.zeros(15, dtype=bool)
    flex[0::3] = flex[1::3] = True
    q[flex] += squeeze
    return np.clip(q, hand.lower[:15], hand.upper[:15])


# ------------------------------------------------------------------------------ model
def build_model(hand: HandModel, obj, pose, wrist_pose, planes=None,
                settings: SimulationSettings | None = None):
    """Compile the MuJoCo model of one check (see :mod:`~grasp_apso.simulation.mjcf`).

    Returns ``(mujoco.MjModel, xml_text)``. Raises
    :class:`~grasp_apso.errors.SimulationError` when MuJoCo refuses the model.
    """
    import mujoco

    settings = settings or SimulationSettings()
    pose = rigid_transform(pose, "pose")
    wrist_pose = rigid_transform(wrist_pose, "wrist_pose")
    planes = _planes(planes)
    parts = convex_parts(obj, settings.decomposition)
    com, inertia = mjcf.object_inertia(obj, settings.object_mass)
    xml = mjcf.scene_xml(hand, parts, com, inertia, pose, wrist_pose, planes, settings)
    try:
        model = mujoco.MjModel.from_xml_string(xml)
    except ValueError as exc:
        raise SimulationError(f"simulation: MuJoCo could not build the scene: {exc}") from exc
    return model, xml


def simulate_grasp(
    hand: HandModel,
    obj,
    pose,
    wrist_pose,
    pre_grasp_q,
    grasp_q,
    planes=None,
    settings: SimulationSettings | None = None,
    stop_at_first_failure: bool = False,
) -> SimResult:
    """Check in MuJoCo that a grasp holds the object (protocol in the module docstring).

    Parameters
    ----------
    hand : HandModel
    obj : GraspObject
        Mesh in the object frame (``obj.mesh``), ``obj.center_of_mass``, ``obj.mesh_hash``.
    pose : (4, 4) float
        Object -> planning frame (m).
    wrist_pose : (4, 4) float
        Palm frame in the planning frame (the planner's ``wrist_pose`` / ``grasp_pose``).
    pre_grasp_q, grasp_q : (15,) float, rad
        Finger joint values, layout of :mod:`grasp_apso.model.hand` (``3*i + (distal,
        proximal, pivot)``); an (18,) configuration is accepted and its wrist angles ignored.
    planes : (K, 4) float, optional
        Support planes ``a, b, c, d`` in the planning frame, solid side
        ``a x + b y + c z + d < 0``.
    settings : SimulationSettings, optional
    stop_at_first_failure : bool
        Skip the remaining directions once one fails (faster for ranking).

    Returns
    -------
    SimResult

    Raises
    ------
    InputError
        A malformed argument (the message names it).
    SimulationError
        MuJoCo could not build or run the scene.
    """
    import mujoco

    t0 = time.perf_counter()
    settings = settings or SimulationSettings()
    if not isinstance(settings, SimulationSettings):
        raise InputError("settings: expected a SimulationSettings")
    if not isinstance(hand, HandModel):
        raise InputError("hand: expected a HandModel")
    pre = _posture(hand, pre_grasp_q, "pre_grasp_q")
    grasp = _posture(hand, grasp_q, "grasp_q")
    model, _ = build_model(hand, obj, pose, wrist_pose, planes, settings)
    data = mujoco.MjData(model)

    # Initial posture: the pre-grasp (middle joints coupled).
    ratio = float(hand.coupling_ratio)
    for f, finger in enumerate(FINGER_NAMES):
        for j, kind in enumerate(("distal", "proximal", "pivot")):
            data.qpos[model.joint(f"{finger}_{kind}").qposadr[0]] = pre[3 * f + j]
        data.qpos[model.joint(f"{finger}_middle").qposadr[0]] = ratio * pre[3 * f]
    data.ctrl[:] = pre
    mujoco.mj_forward(model, data)

    squeezed = squeezed_posture(hand, grasp, settings.squeeze)
    body = model.body(mjcf.OBJECT_BODY).id
    try:
        ramp(model, data, ((pre, grasp, settings.close_time), (grasp, squeezed, settings.squeeze_time)),
             settings.timestep)
        data.ctrl[:] = squeezed
        settle(model, data, settings, body)
    except mujoco.FatalError as exc:  # pragma: no cover - unstable physics
        raise SimulationError(f"simulation: MuJoCo failed while closing the hand: {exc}") from exc

    # The planes carried the object during the closing only.
    disable_contacts(model, [g for g in range(model.ngeom) if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_PLANE])
    ref_pos, ref_quat = planned_reference(rigid_transform(pose, "pose"), obj.center_of_mass)
    per_direction = disturb(model, data, body, settings, ref_pos, ref_quat, stop_at_first_failure)
    return SimResult(
        held=all(h for *_, h in per_direction) and len(per_direction) == len(DIRECTIONS),
        max_shift=max(s for _, s, _, _ in per_direction),
        max_turn=max(t for _, _, t, _ in per_direction),
        per_direction=tuple(per_direction),
        sim_time=time.perf_counter() - t0,
    )
