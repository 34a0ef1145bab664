"""The simulation check of a grasp for any hand (DESIGN.md Part 3), on the hand's own
description file: :func:`simulate_any_hand`.

The protocol is the paper hand's (:mod:`.protocol`, phases in :mod:`.phases`), with the
postures given over ``hand.actuated_joints``:

1. The scene (:mod:`.any_hand_model`): the hand from its file, its root link held at
   ``root_pose``, position servos on the actuated joints, the object a free body at
   ``obj_pose``, the scene's planes and obstacles, gravity off.
2. The fingers start at ``q_pre`` (``pregrasp_fraction`` 1: the planner's replies carry a
   near pre-grasp, just off the contacts, as DexGraspBench's pregrasp; a smaller fraction
   starts that far from ``q_grasp`` back to ``q_pre``); the servo targets move to ``q_grasp`` in
   ``hand_close_time``, then to ``q_squeeze`` in ``hand_squeeze_time`` (the reply's
   ``hand_trajectory`` times), and hold there
   ``settle_time`` (longer, up to ``max_settle_time``, until the object rests).
3. The scene's contacts are switched off (the object is in the hand, off the table), then
   six disturbances of ``object_mass * disturbance`` (10 m/s^2), ``duration`` (2 s) each,
   from the same squeezed state. Held: within ``max_shift`` (5 cm) and ``max_turn`` (15
   degrees) of the *planned* object pose in every direction, the squeezed state included.

Deterministic (MuJoCo on one thread; the convex parts are cached). Bounded: a fixed number
of steps per phase; ``should_stop()`` is polled between the phases and before each
direction (then :class:`~grasp_apso.errors.TimeoutExceeded`, stage "simulation").
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Callable

import numpy as np

from ..errors import InputError, SimulationError
from .any_hand_model import AnyHandScene, build_any_hand_scene
from .convex import decompose
from .phases import check_stop, disable_contacts, disturb, planned_reference, ramp, rigid_transform, settle
from .protocol import SimResult
from .settings import SimulationSettings

__all__ = ["simulate_any_hand", "SimOutcome", "prepare_any_hand", "squeezed_positions"]

#: The verdict type (the paper hand's check returns the same).
SimOutcome = SimResult


def _posture(hand, value, field_name: str) -> np.ndarray:
    """``value`` as (n,) actuated positions within the limits, or an InputError naming the
    field and the joint."""
    n = hand.n_joints
    q = np.asarray(value, dtype=float) if value is not None else None
    if q is None or q.shape != (n,) or not np.all(np.isfinite(q)):
        raise InputError(f"{field_name}: expected {n} finite values over hand.actuated_joints", field_name)
    lo, hi = np.asarray(hand.lower, float), np.asarray(hand.upper, float)
    bad = np.flatnonzero((q < lo - 1e-6) | (q > hi + 1e-6))
    if bad.size:
        j = int(bad[0])
        raise InputError(f"{field_name}: {hand.actuated_joints[j]} = {q[j]:.4f} outside "
                         f"[{lo[j]:.4f}, {hi[j]:.4f}]", field_name)
    return np.clip(q, lo, hi)


def squeezed_positions(hand, q_grasp, squeeze: float | None = None) -> np.ndarray:
    """The grasp posture pushed ``squeeze`` rad (default ``SimulationSettings.squeeze``, 8
    degrees) further along each joint's closing sense (``Finger.closing``; pre-shape
    joints unchanged), clipped to the limits. q_grasp (n,) -> (n,) over
    ``hand.actuated_joints``."""
    _check_hand(hand)
    q = _posture(hand, q_grasp, "q_grasp").copy()
    step = SimulationSettings().squeeze if squeeze is None else float(squeeze)
    for finger in hand.fingers:
        for joint, sense in zip(finger.joints, finger.closing):
            q[hand.actuated_joints.index(joint)] += sense * step
    return np.clip(q, hand.lower, hand.upper)


def _check_hand(hand) -> None:
    from ..model.hands.model import HandModel

    if not isinstance(hand, HandModel):
        raise InputError("hand: expected a grasp_apso.model.hands.HandModel (load_hand(path))", "hand")


def _check_friction(friction) -> float:
    if isinstance(friction, bool) or not isinstance(friction, (int, float)) or not math.isfinite(friction) \
            or not 1e-3 <= friction <= 5.0:
        raise InputError(f"friction: {friction!r} must be a number in [0.001, 5]", "friction")
    return float(friction)


def prepare_any_hand(hand, obj, obj_pose, root_pose, q_pre, scene=None, friction: float = 0.5,
                     settings: SimulationSettings | None = None,
                     should_stop: Callable[[], bool] | None = None) -> tuple[AnyHandScene, SimulationSettings]:
    """The compiled scene with the fingers at ``q_pre`` (servo targets too), and the
    settings with ``friction`` applied. Arguments as :func:`simulate_any_hand`."""
    import mujoco

    _check_hand(hand)
    settings = settings or SimulationSettings()
    if not isinstance(settings, SimulationSettings):
        raise InputError("settings: expected a SimulationSettings", "settings")
    settings = replace(settings, friction=_check_friction(friction))
    obj_pose = rigid_transform(obj_pose, "obj_pose")
    root_pose = rigid_transform(root_pose, "root_pose")
    pre = _posture(hand, q_pre, "q_pre")
    if not all(hasattr(obj, a) for a in ("mesh", "mesh_hash", "center_of_mass")):
        raise InputError("obj: expected a GraspObject (mesh, mesh_hash, center_of_mass)", "obj")
    if scene is not None and not hasattr(scene, "planes"):
        raise InputError("scene: expected a grasp_apso.model.scene.Scene or None", "scene")
    check_stop(should_stop, "the convex decomposition")
    found = decompose(obj, settings.decomposition, should_stop=should_stop)
    if found.parts is None:
        check_stop(should_stop, "the simulation")
        raise SimulationError(f"simulation: no convex parts of the object ({found.note or found.method})")
    check_stop(should_stop, "building the model")
    sc = build_any_hand_scene(hand, obj, found.parts, obj_pose, root_pose, scene, settings)
    full = hand.full_positions(pre)
    for adr, index in sc.joint_qpos:
        sc.data.qpos[adr] = full[index]
    sc.data.ctrl[:] = pre
    mujoco.mj_forward(sc.model, sc.data)
    return sc, settings


#: A start posture whose links are this deep in the object (m) is not used (see _start_near).
START_PENETRATION = 1e-3


def _start_near(sc: AnyHandScene, hand, grasp: np.ndarray, pre: np.ndarray, fraction: float) -> None:
    """Put the fingers (and their servo targets) ``fraction`` of the way from the grasp
    posture back to the pre-grasp, or, when a link would then lie inside the object (a
    grasp posture that is not a touching one), half-way, else at the pre-grasp itself."""
    import mujoco

    model, data = sc.model, sc.data
    for f in [float(fraction)] + [f for f in (0.5, 1.0) if f > fraction]:
        start = grasp + f * (pre - grasp)
        full = hand.full_positions(start)
        for adr, index in sc.joint_qpos:
            data.qpos[adr] = full[index]
        data.ctrl[:] = start
        mujoco.mj_forward(model, data)
        deepest = 0.0
        for c in data.contact[:data.ncon]:
            bodies = (model.geom_bodyid[c.geom1], model.geom_bodyid[c.geom2])
            if (sc.object_body in bodies and c.geom1 not in sc.scene_geoms and c.geom2 not in sc.scene_geoms):
                deepest = max(deepest, -float(c.dist))
        if deepest <= START_PENETRATION:
            return


def simulate_any_hand(hand, obj, obj_pose, root_pose, q_pre, q_grasp, q_squeeze, scene=None,
                      friction: float = 0.5, settings: SimulationSettings | None = None,
                      should_stop: Callable[[], bool] | None = None,
                      observer: Callable[[str, object, object], None] | None = None,
                      stop_at_first_failure: bool = False) -> SimResult:
    """Check in MuJoCo that a grasp of any hand holds the object (module docstring).

    Parameters
    ----------
    hand : grasp_apso.model.hands.HandModel
        Loaded from its file (``load_hand(path)``): the model is compiled from that file.
    obj : GraspObject
    obj_pose : (4, 4) float
        Object frame in the planning (world) frame, m.
    root_pose : (4, 4) float
        The hand's root link in the planning frame (the candidate's ``wrist_pose``).
    q_pre, q_grasp, q_squeeze : (n,) float, rad or m
        Pre-grasp, grasp and squeezed postures over ``hand.actuated_joints`` (the fingers
        start ``settings.pregrasp_fraction`` of the way from ``q_grasp`` back to ``q_pre``).
    scene : grasp_apso.model.scene.Scene or None
        Planning frame; in the model for the closing only.
    friction : float
        The planner's mu (every contact with the object and the scene).
    settings : SimulationSettings, optional
        ``friction`` overrides its ``friction``.
    should_stop : callable() -> bool, optional
        Polled between the phases; True stops with TimeoutExceeded.
    observer : callable(phase, model, data), optional
        Sees the state after "pre_grasp", "grasp", "squeezed" and each direction ("+x" ...).
    stop_at_first_failure : bool
        Skip the remaining directions once one fails.

    Returns
    -------
    SimResult (``SimOutcome``): held, max_shift m, max_turn rad (from the planned pose),
    per_direction, sim_time s.

    Raises
    ------
    InputError
        A malformed argument (the message names it).
    SimulationError
        MuJoCo could not build or run the scene.
    TimeoutExceeded
        ``should_stop()`` turned true.
    """
    import mujoco

    t0 = time.perf_counter()
    _check_hand(hand)
    grasp = _posture(hand, q_grasp, "q_grasp")
    squeeze = _posture(hand, q_squeeze, "q_squeeze")
    sc, settings = prepare_any_hand(hand, obj, obj_pose, root_pose, q_pre, scene, friction, settings, should_stop)
    model, data = sc.model, sc.data
    _start_near(sc, hand, grasp, _posture(hand, q_pre, "q_pre"), settings.pregrasp_fraction)
    pre = np.array(data.ctrl, dtype=float)
    notify = observer or (lambda *_: None)
    notify("pre_grasp", model, data)
    try:
        check_stop(should_stop, "the closing")
        ramp(model, data, ((pre, grasp, settings.hand_close_time),), settings.timestep)
        notify("grasp", model, data)
        check_stop(should_stop, "the squeeze")
        ramp(model, data, ((grasp, squeeze, settings.hand_squeeze_time),), settings.timestep)
        data.ctrl[:] = squeeze
        settle(model, data, settings, sc.object_body)
    except mujoco.FatalError as exc:  # pragma: no cover - unstable physics
        raise SimulationError(f"simulation: MuJoCo failed while closing hand {hand.name!r}: {exc}") from exc
    notify("squeezed", model, data)
    # The planes and obstacles carried the object during the closing only.
    disable_contacts(model, sc.scene_geoms)
    ref_pos, ref_quat = planned_reference(rigid_transform(obj_pose, "obj_pose"), obj.center_of_mass)
    per_direction = disturb(model, data, sc.object_body, settings, ref_pos, ref_quat,
                            stop_at_first_failure, should_stop, observer)
    return SimResult(
        held=len(per_direction) == 6 and all(h for *_, h in per_direction),
        max_shift=max(s for _, s, _, _ in per_direction),
        max_turn=max(t for _, _, t, _ in per_direction),
        per_direction=tuple(per_direction),
        sim_time=time.perf_counter() - t0,
    )
