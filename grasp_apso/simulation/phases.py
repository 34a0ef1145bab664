"""The phases of the simulation protocol, shared by every hand (DESIGN.md Part 2 and 3):
closing ramps, the settle, and the six disturbances measured from the planned pose.

Both :func:`grasp_apso.simulation.protocol.simulate_grasp` (the paper's hand, its
generated MJCF) and :func:`grasp_apso.simulation.any_hand.simulate_any_hand` (any hand,
its own file) run these on a compiled model whose actuators are position servos
(``data.ctrl`` = the driven joints' targets, rad or m), the object a free body.

The honest protocol (DexGraspBench): the support planes take part in the approach and the
closing only; before the disturbances their contacts are switched off
(:func:`disable_contacts`), so the object is in the hand, off the table, and no plane can
carry it. The shift and the turn are measured from the object's *planned* pose, so a grasp
that shoves the object while closing counts against itself.
"""

from __future__ import annotations

import math
from typing import Callable, Sequence

import numpy as np

from ..errors import InputError, SimulationError, TimeoutExceeded
from .mjcf import matrix_to_quat
from .settings import SimulationSettings

__all__ = ["DIRECTIONS", "angle_between", "ramp", "settle", "disable_contacts", "disturb", "check_stop",
           "planned_reference", "rigid_transform"]

#: Disturbance directions in the planning frame, in the order they are tried.
DIRECTIONS: tuple[tuple[str, tuple[float, float, float]], ...] = (
    ("+x", (1.0, 0.0, 0.0)), ("-x", (-1.0, 0.0, 0.0)),
    ("+y", (0.0, 1.0, 0.0)), ("-y", (0.0, -1.0, 0.0)),
    ("+z", (0.0, 0.0, 1.0)), ("-z", (0.0, 0.0, -1.0)),
)
#: Control updates per ramp (the target moves in at most this many steps).
_RAMP_CHUNKS = 15


def check_stop(should_stop: Callable[[], bool] | None, phase: str) -> None:
    """Raise :class:`~grasp_apso.errors.TimeoutExceeded` (stage "simulation") when
    ``should_stop()`` says so; called between phases."""
    if should_stop is not None and should_stop():
        raise TimeoutExceeded(f"simulation stopped before {phase}", stage="simulation")


def rigid_transform(value, field_name: str) -> np.ndarray:
    """``value`` as a (4, 4) rigid transform, or an InputError naming ``field_name``."""
    t = np.asarray(value, dtype=float) if value is not None else None
    if t is None or t.shape != (4, 4) or not np.all(np.isfinite(t)):
        raise InputError(f"{field_name}: expected a finite (4, 4) transform", field_name)
    r = t[:3, :3]
    if not np.allclose(r.T @ r, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0 \
            or not np.allclose(t[3], [0, 0, 0, 1]):
        raise InputError(f"{field_name}: not a rigid transform (rotation not orthonormal)", field_name)
    return t


def angle_between(q_ref: np.ndarray, q: np.ndarray) -> float:
    """Rotation angle (rad) between two unit quaternions (w, x, y, z)."""
    dot = abs(float(np.dot(q_ref, q)))
    return 2.0 * math.acos(min(1.0, dot))


def planned_reference(pose: np.ndarray, center_of_mass: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The planned centre of mass (3,) m in the world and the planned orientation (4,)
    quaternion (w, x, y, z) of an object whose frame is at ``pose`` (4, 4)."""
    pose = np.asarray(pose, float)
    return pose[:3, :3] @ np.asarray(center_of_mass, float) + pose[:3, 3], matrix_to_quat(pose[:3, :3])


def ramp(model, data, segments: Sequence[tuple[np.ndarray, np.ndarray, float]], dt: float) -> None:
    """Move the servo targets linearly ``start -> end`` over ``duration`` s, per segment.

    segments : ((n,), (n,), s) triples.
    """
    import mujoco

    for start, end, duration in segments:
        n = int(round(duration / dt))
        chunks = max(1, min(n, _RAMP_CHUNKS))
        done = 0
        for c in range(1, chunks + 1):
            steps = int(round(n * c / chunks)) - done
            data.ctrl[:] = start + (end - start) * (c / chunks)
            if steps > 0:
                mujoco.mj_step(model, data, nstep=steps)
            done += steps


def settle(model, data, settings: SimulationSettings, body: int) -> None:
    """Hold the current targets ``settle_time``, then on until the object (free body
    ``body``) rests (speed below ``rest_speed`` m/s and ``rest_spin`` rad/s) or
    ``max_settle_time`` has passed."""
    import mujoco

    dt = settings.timestep
    adr = model.jnt_dofadr[model.body_jntadr[body]]
    n_min = int(round(settings.settle_time / dt))
    if n_min:
        mujoco.mj_step(model, data, nstep=n_min)
    n_chunk = max(1, int(round(settings.check_every / dt)))
    n_more = int(round(max(0.0, settings.max_settle_time - settings.settle_time) / dt))
    done = 0
    while done < n_more:
        v = data.qvel[adr:adr + 6]
        if np.linalg.norm(v[:3]) < settings.rest_speed and np.linalg.norm(v[3:]) < settings.rest_spin:
            break
        steps = min(n_chunk, n_more - done)
        mujoco.mj_step(model, data, nstep=steps)
        done += steps


def disable_contacts(model, geoms: Sequence[int]) -> None:
    """Take geoms out of collision (``contype`` = ``conaffinity`` = 0): the support planes
    before the disturbances. The model is built per check, so nothing is restored."""
    for g in geoms:
        model.geom_contype[g] = 0
        model.geom_conaffinity[g] = 0


def instabilities(data) -> int:
    """How often MuJoCo met a non-finite or huge acceleration in this check (its
    ``mjWARN_BADQACC`` count; the data is made fresh per check). MuJoCo then resets the
    state, putting the object back where the compiled model has it, which can be the
    planned pose: nothing measured after it is the grasp's doing (a Shadow grasp whose
    servos blew up within the closing read "held", 4 mm from the planned pose, in every
    direction)."""
    import mujoco

    return int(data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number)


def disturb(model, data, body: int, settings: SimulationSettings, ref_pos: np.ndarray, ref_quat: np.ndarray,
            stop_at_first_failure: bool = False, should_stop: Callable[[], bool] | None = None,
            observer: Callable[[str, object, object], None] | None = None) -> list[tuple[str, float, float, bool]]:
    """The six disturbances from the current (squeezed) state.

    For each direction: restore the squeezed state, push the object's centre of mass with
    ``object_mass * disturbance`` N for ``duration`` s and track the centre of mass's
    distance from ``ref_pos`` (3,) m and the turn from ``ref_quat`` (4,) (the planned
    pose); the direction fails (and stops) once the shift reaches ``max_shift`` or the
    turn ``max_turn``, and every direction fails once the physics went unstable
    (:func:`instabilities`: in the closing or squeeze, or in an earlier direction).
    ``should_stop`` is polled before each direction; ``observer(name, model, data)``, when
    given, sees the state at the end of each direction.

    Returns ``[(direction, shift m, turn rad, held), ...]``.
    """
    import mujoco

    dt = settings.timestep
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    saved = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, saved, spec)
    force = settings.object_mass * settings.disturbance
    n_total = int(round(settings.duration / dt))
    n_chunk = max(1, int(round(settings.check_every / dt)))
    ref_pos = np.asarray(ref_pos, float)
    ref_quat = np.asarray(ref_quat, float)
    out: list[tuple[str, float, float, bool]] = []
    for name, direction in DIRECTIONS:
        check_stop(should_stop, f"the disturbance {name}")
        mujoco.mj_setState(model, data, saved, spec)
        data.xfrc_applied[:] = 0.0
        data.xfrc_applied[body, :3] = force * np.asarray(direction)
        # The squeezed state itself counts: a grasp that shoved the object is judged on it.
        mujoco.mj_forward(model, data)
        shift = float(np.linalg.norm(data.xipos[body] - ref_pos))
        turn = angle_between(ref_quat, data.xquat[body])
        held = shift < settings.max_shift and turn < settings.max_turn and not instabilities(data)
        done = 0
        try:
            while held and done < n_total:
                steps = min(n_chunk, n_total - done)
                mujoco.mj_step(model, data, nstep=steps)
                done += steps
                shift = max(shift, float(np.linalg.norm(data.xipos[body] - ref_pos)))
                turn = max(turn, angle_between(ref_quat, data.xquat[body]))
                if shift >= settings.max_shift or turn >= settings.max_turn \
                        or not np.all(np.isfinite(data.qpos)) or instabilities(data):
                    held = False
        except mujoco.FatalError as exc:  # pragma: no cover - unstable physics
            raise SimulationError(f"simulation: MuJoCo failed in direction {name}: {exc}") from exc
        out.append((name, shift, turn, held))
        if observer is not None:
            observer(name, model, data)
        if not held and stop_at_first_failure:
            break
    return out
