"""The parameters of the simulation check (:class:`SimulationSettings`), apart from the
protocol so that the MJCF builder and the protocol both use them without a cycle."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from ..errors import InputError
from ..search.motion_times import CLOSE_TIME, SQUEEZE_TIME
from .convex import ConvexSettings

__all__ = ["SimulationSettings", "DEXGRASPBENCH_PARAMETERS"]

#: DexGraspBench's evaluation parameters where they differ from this check's
#: (github.com/JYChen18/DexGraspBench, ``src/util/hand_util.py``,
#: ``src/task/eval_func/fc_mocap.py``, ``config/task/eval.yaml`` and its README); the protocol
#: (the wrist fixed, pre-grasp -> grasp -> squeeze, 10 m/s^2 for 2 s in six directions, 5 cm
#: / 15 degrees from the planned pose, 0.1 kg, no table in the disturbance) and the sliding
#: friction (the planner's mu) are the same:
#:
#: - torsional friction 0.02 (``miu_coef: [0.6, 0.02]``; this check's 0.005);
#: - servo gain 5 (its README: "raising the hand's kp from 1 to 5"; this check's 2);
#: - contacts: it gives the hand's geoms solref (0.005, 1) and solimp (0.5, 0.99, 0.0001)
#:   and leaves the object's at MuJoCo's defaults, which MuJoCo averages; this check's object
#:   geoms carry every contact's parameters (priority), so they take that average;
#: - pre-grasp -> grasp and grasp -> squeeze each over 10 x 10 steps of 4 ms (0.4 s), the
#:   disturbance right after the squeeze (no settling).
#:
#: Not replicated: ``noslip_iterations = 2`` (no setting of this check's). With
#: ``simulate`` a general hand's grasp is held only when it holds with this check's
#: parameters and with these (:meth:`SimulationSettings.dexgraspbench`): a client's servos
#: may be stiffer than this check's, and its contacts softer (``bench/held_rate.py
#: --dexgraspbench`` replays every candidate with both).
DEXGRASPBENCH_PARAMETERS = {"torsional_friction": 0.02, "kp": 5.0, "solref": (0.0125, 1.0),
                            "solimp": (0.7, 0.97, 0.00055), "hand_close_time": 0.4, "hand_squeeze_time": 0.4,
                            "settle_time": 0.0, "max_settle_time": 0.0}


@dataclass(frozen=True)
class SimulationSettings:
    """Parameters of the simulation check (SI units).

    Attributes
    ----------
    object_mass : float, kg
        0.1 unless given (DESIGN.md).
    friction : float
        Sliding friction coefficient of every contact: the planner's mu, 0.5.
    torsional_friction, rolling_friction : float, m
        MuJoCo's torsional (used with condim >= 4) and rolling (condim 6) coefficients.
        The torsional one bounds the moment about the contact normal, ``torsional_friction
        * normal force``; a pressed patch of radius a carries ``2/3 mu a`` (uniform
        pressure), so 0.005 (MuJoCo's default) is a fingertip patch of 15 mm radius at mu
        0.5, already a broad pad. DexGraspBench's 0.02 would be a 60 mm patch (50 mm at its
        mu 0.6), wider than any fingertip: its check holds grasps that spin on the pads in ours (measured in
        docs/any-hand-measurements.md), and the check keeps the physical value.
    condim : int
        4 (sliding + torsional friction) or 6 (+ rolling); 3 is accepted too.
    disturbance : float, m/s^2
        Acceleration of the disturbance (force = object_mass * disturbance).
    duration : float, s
        Disturbance time per direction.
    max_shift : float, m
        Held only if the centre of mass moves less than this in every direction.
    max_turn : float, rad
        ... and the object turns less than this.
    squeeze : float, rad
        Extra flexion beyond the grasp posture (clipped to the limits): the paper hand's
        squeeze, and a general hand's when its contacts are not known.
    squeeze_force : float, N
        Mean contact force a general hand's squeeze aims at (``q_grasp + J^T f / kp``,
        :func:`grasp_apso.quality.closing.squeeze_toward_forces`, with this ``kp``): 2.4 N
        per contact. The squeeze is a posture, so the force it makes is the gain of the
        servos that run it times the posture's offset, and the planner does not know that
        gain: DexGraspBench runs a reply's postures at 5 N m/rad, 2.5 times this check's,
        so a squeeze meant as 4 N pressed 10 N there and turned or shoved the object out
        of some hands (the LinkerHand L20, the Wuji hand). 2.4 N here is 6 N at its gain:
        over the two gains the force brackets the 4 N that three contacts with mu 0.5 need
        to carry the 1 N disturbance with a wide margin. Measured (``bench/held_rate.py
        --dexgraspbench``, 21 objects on a table, seeds 0-2, 15 hands, best grasps held,
        this check / DexGraspBench's parameters): 708 / 763 of 942 at 4 N, 711 / 806 at
        2.4 N (docs/any-hand-measurements.md, "The stop of 2026-12-06, eighth").
    pregrasp_fraction : float
        Where a general hand's fingers start closing: this fraction of the way from the
        grasp posture back to the given pre-grasp; 1 (the default): the pre-grasp itself,
        as DexGraspBench replays a grasp's pregrasp posture. The planner's replies carry a
        near pre-grasp (:data:`grasp_apso.search.any_hand_select.NEAR`: the fingers a
        quarter of their closing travel off the contacts when that approach is clear), so
        the check replays exactly what a client receives. (Closing from the search's
        wide-open pre-shape instead, fingers arriving one after another shove the object:
        Allegro, 21 objects on a table, best grasps held 8 of 20 from the wide pre-shape,
        13 of 20 from the near pre-grasp.)
    close_time, squeeze_time, settle_time : float, s
        Durations of the closing ramp, the squeeze ramp and the hold before the tests (the
        paper hand's check, its published protocol).
    hand_close_time, hand_squeeze_time : float, s
        A general hand's closing and squeeze ramps: the times of the reply's
        ``hand_trajectory`` (:mod:`grasp_apso.search.motion_times`), so that the check
        replays the motion a client is given.
    max_settle_time : float, s; rest_speed : float, m/s; rest_spin : float, rad/s
        After ``settle_time`` the hold goes on until the object rests (its speed and spin
        below these) or ``max_settle_time`` has passed: the squeeze leaves a transient
        (fingertips rolling the object into force balance) that decays in about 1 s and
        would otherwise be counted as the disturbance's motion (measured on the plan's
        sphere grasp: 5.7 mm / 9.9 deg of drift in 2 s with no disturbance after a 0.2 s
        hold, 2.0 mm / 4.1 deg after 1 s).
    timestep : float, s
        4 ms: with the contact time constant ``solref[0]`` = 20 ms the contacts are
        resolved over 5 steps (MuJoCo advises >= 2) and a whole check (12.6 to 13.4 s
        of simulated time, 3,150 to 3,350 steps) fits the 0.25 s budget per candidate:
        median 206 ms (167-444 ms) over 20 planned grasps on the four built-in objects
        on the shared 2-core machine (``bench/bench_simulation.py``). Checked against
        2 ms on the known-outcome grasps of ``test/test_simulation.py``: same verdicts.
    check_every : float, s
        How often the shift and turn are measured during a disturbance.
    kp : float, N m / rad
        Position gain of the finger servos (a fingertip force of a few newtons for the
        squeeze: 2 N m/rad * 0.14 rad / 0.07 m ~ 4 N); a general hand's coupled leader gets
        it times ``HandModel.servo_weight`` (it drives several joints).
    max_torque : float, N m
        Servo torque limit; a general hand's coupled leader gets it times
        ``HandModel.servo_force_scale`` (the most loaded joint it drives bears this).
    joint_damping : float, N m s / rad; joint_armature : float, kg m^2
        Critically damped servos: damping ~ 2 sqrt(kp * armature).
    max_joint_damping : float, N m s / rad (N s / m for a slide)
        A general hand's joint damping is capped at this (robosuite's Inspire gives 1): a
        servo's gain is raised on a joint damped more, to keep its time constant, and
        Gazebo-tuned URDF damping (Wonik's Allegro V5: 3-10) then made 100 times stiffer
        servos than the squeeze is computed for, which pushed the object out of the hand.
    max_joint_friction : float, N m (N for a slide)
        A general hand's joint friction (MuJoCo's ``frictionloss``, a URDF's ``<dynamics
        friction>``) is capped at this, a twentieth of ``max_torque``: the servos are this
        check's, and a joint whose friction exceeds what its servo can exert never moves
        (Wonik's Allegro V5 URDF gives 5-12 N m, for its own 15 N m actuators: its fingers
        stayed where the closing started). The hands' own files give at most 0.001.
    impratio : float
        Frictional-to-normal impedance ratio (elliptic cones).
    solref, solimp : tuple of float
        MuJoCo contact softness (time constant, damping ratio) and impedance.
    decomposition : ConvexSettings
        CoACD parameters for non-convex objects.
    """

    object_mass: float = 0.1
    friction: float = 0.5
    torsional_friction: float = 0.005
    rolling_friction: float = 0.0001
    condim: int = 4
    disturbance: float = 10.0
    duration: float = 2.0
    max_shift: float = 0.05
    max_turn: float = math.radians(15.0)
    squeeze: float = math.radians(8.0)
    squeeze_force: float = 2.4
    pregrasp_fraction: float = 1.0
    close_time: float = 0.3
    squeeze_time: float = 0.1
    hand_close_time: float = CLOSE_TIME
    hand_squeeze_time: float = SQUEEZE_TIME
    settle_time: float = 0.2
    max_settle_time: float = 1.0
    rest_speed: float = 0.002
    rest_spin: float = 0.05
    timestep: float = 0.004
    check_every: float = 0.04
    kp: float = 2.0
    max_torque: float = 1.0
    joint_damping: float = 0.1
    joint_armature: float = 0.001
    max_joint_damping: float = 1.0
    max_joint_friction: float = 0.05
    impratio: float = 10.0
    solref: tuple[float, float] = (0.02, 1.0)
    solimp: tuple[float, float, float] = (0.9, 0.95, 0.001)
    decomposition: ConvexSettings = field(default_factory=ConvexSettings)

    def __post_init__(self) -> None:
        ranges = {
            "object_mass": (1e-4, 100.0), "friction": (1e-3, 5.0), "torsional_friction": (0.0, 0.1),
            "rolling_friction": (0.0, 0.1), "disturbance": (0.0, 1000.0), "duration": (1e-3, 60.0),
            "max_shift": (1e-4, 10.0), "max_turn": (1e-4, math.pi), "squeeze": (0.0, 0.5), "squeeze_force": (0.0, 100.0),
            "pregrasp_fraction": (0.0, 1.0),
            "close_time": (0.0, 10.0), "squeeze_time": (0.0, 10.0),
            "hand_close_time": (0.0, 10.0), "hand_squeeze_time": (0.0, 10.0), "settle_time": (0.0, 10.0),
            "max_settle_time": (0.0, 20.0), "rest_speed": (0.0, 1.0), "rest_spin": (0.0, 10.0),
            "timestep": (1e-4, 0.02), "check_every": (1e-4, 1.0), "kp": (1e-3, 1e4),
            "max_torque": (1e-3, 1e3), "joint_damping": (0.0, 1e3), "joint_armature": (0.0, 1.0),
            "max_joint_damping": (0.0, 1e3), "max_joint_friction": (0.0, 1e3),
            "impratio": (1.0, 100.0),
        }
        for name, (low, high) in ranges.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                    or not low <= value <= high:
                raise InputError(f"settings.{name}: {value!r} must be a number in [{low}, {high}]")
        if self.condim not in (3, 4, 6):
            raise InputError(f"settings.condim: {self.condim!r} must be 3, 4 or 6")
        if len(self.solref) != 2 or len(self.solimp) != 3 or not all(
                isinstance(v, (int, float)) and math.isfinite(v) for v in (*self.solref, *self.solimp)):
            raise InputError("settings.solref/solimp: expected 2 and 3 finite numbers")
        if not isinstance(self.decomposition, ConvexSettings):
            raise InputError("settings.decomposition: expected a ConvexSettings")

    def dexgraspbench(self) -> "SimulationSettings":
        """These settings with DexGraspBench's evaluation parameters
        (:data:`DEXGRASPBENCH_PARAMETERS`), the others kept."""
        return replace(self, **DEXGRASPBENCH_PARAMETERS)
