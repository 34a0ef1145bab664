#!/usr/bin/env python3
"""How many planned grasps HOLD in the MuJoCo check, objects resting on a table (issue 13.6).

Rerunnable, not a test::

    .venv/bin/python bench/held_rate.py --quick                # particles 30, iterations 20, 1 seed
    .venv/bin/python bench/held_rate.py --seeds 3 --poses 2    # default swarm, seeds 0..2, 2 poses
    .venv/bin/python bench/held_rate.py --quick --algorithms apso --objects cube mug
    .venv/bin/python bench/held_rate.py --quick --algorithms apso --hand shadow [--simulate]
    .venv/bin/python bench/held_rate.py --quick --algorithms apso --hand path/to/hand.urdf
    .venv/bin/python bench/held_rate.py --seeds 3 --algorithms apso --hand shadow --stable  # resting poses

``--hand``: any URDF / MJCF file (:func:`grasp_apso.model.hands.load_hand`), a test hand of
``test/hand_files.py`` (``shadow``, ``inspire``, ``allegro_like``, ...), one of the local
dex-urdf hands (``allegro``, ``leap``, ``ability``, ``schunk``, ``barrett``, ``inspire_urdf``,
``shadow_urdf`` under ``/work/extern/dex-urdf``, never copied into the repository) or
``paper`` (the default: the paper hand's own path). A general hand is planned with
``plan(..., hand=h)`` and each candidate checked with
:func:`~grasp_apso.simulation.any_hand.simulate_any_hand` (the hand's own description; the
table only during the closing; held = within 5 cm and 15 degrees of the planned pose).
Results go to ``bench/results/held_rate_<hand>[_simulate].json``.

For each object (the four built-ins and every mesh of ``grasp_apso/data/meshes``), each
pose (identity, then seeded random rotations about z; with ``--stable`` each mesh first
turned into its most probable resting pose, :func:`stable_pose`), each algorithm (APSO, the simple
PSO) and each seed 0..N-1: the object rests on a table (``Scene.table_under`` its lowest
point), :func:`~grasp_apso.search.planner.plan` returns its ranked candidates, and every
candidate is checked with :func:`~grasp_apso.simulation.simulate_grasp` (planes = the
table; pre-grasp and grasp = the candidate's first 15 joints; its wrist pose).

Per candidate it also records what may tell a failure apart: the contacts (fingers, thumb
present), their normal uncertainty (:func:`~grasp_apso.quality.robustness.normal_uncertainty`,
large at an edge or a corner), their height below the object's top (a rim) and above the
table, epsilon and the robust epsilon (:func:`~grasp_apso.quality.robustness.robust_epsilon`).

``--dexgraspbench``: every general-hand candidate is also checked with DexGraspBench's own
contact and servo parameters (:func:`dexgraspbench_settings`), the same protocol and limits
otherwise; the totals print both held rates. Our check is the stricter of the two (mostly its
torsional friction, a quarter of DexGraspBench's).

A general hand's candidates also take DexGraspBench's tabletop test (:func:`lift_test`,
from the squeezed state of each check, on copies: the hand lifted 10 cm off the table against
the object's weight), with our parameters and, with ``--dexgraspbench``, its own; the totals
print the *lifted* rates.

A general hand's candidates also record where the object stood, from its planned pose,
after the closing and after the squeeze (``grasp_*`` / ``squeezed_*`` shift mm and turn
deg), and the totals count the dropped best grasps by where they went wrong
(:func:`drop_phase`): the squeezed object already past the limits, moved a third of a
limit or more by the closing and squeeze, or dropped in the disturbance; with
``--dexgraspbench`` the same for its check (``dgb_grasp_*``, ``dgb_squeezed_*``).

Prints a table per object (best held / candidates held / median shift mm and turn deg /
the directions that fail), the totals per algorithm, the failed grasps with their features,
and "re-ranked" held rates: the best grasp chosen among the force-closure candidates by
the robust epsilon or the margin instead of the planner's rank (no extra simulation: every
candidate is simulated). Writes ``bench/results/held_rate.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

# DexGraspBench's simulation parameters where they differ from ours (one source, which says
# where each comes from; with ``simulate`` the planner holds a general hand's grasps to them too)
from grasp_apso.simulation.settings import DEXGRASPBENCH_PARAMETERS as DEXGRASPBENCH  # noqa: E402

MESH_DIR = REPO / "grasp_apso" / "data" / "meshes"
BUILTINS = ("sphere", "cube", "barrel", "fish")
#: Rules for choosing the best grasp among a plan's candidates, compared offline (every
#: candidate is simulated): "max <key>" sorts the force-closure candidates by that key;
#: "first robust" keeps the planner's order but skips candidates whose robust epsilon is
#: 0; "first margin>=0.25" skips those keeping under a quarter of their epsilon.
RERANK_KEYS = ("robust_epsilon", "margin", "epsilon", "first_robust", "first_margin")


def mesh_names() -> list[str]:
    entries = json.loads((MESH_DIR / "manifest.json").read_text())
    return [Path(e["file"]).stem for e in entries]


def load(name: str):
    from grasp_apso.model.builtin import builtin
    from grasp_apso.model.mesh_files import from_file
    return builtin(name) if name in BUILTINS else from_file(MESH_DIR / f"{name}.stl")


def stable_pose(name: str) -> np.ndarray:
    """A mesh's most probable resting pose (trimesh's ``compute_stable_poses``, one sample:
    deterministic), centred back over the origin; the identity for a built-in. The meshes'
    own frames stand most of them upright, where trimesh finds the cracker box and the
    mustard bottle likelier lying down."""
    if name in BUILTINS:
        return np.eye(4)
    obj = load(name)
    poses, _ = obj.mesh.compute_stable_poses(n_samples=1, threshold=0.0)
    out = np.array(poses[0], dtype=float)
    out[:2, 3] -= (out[:3, :3] @ obj.center_of_mass + out[:3, 3])[:2]
    return out


def pose_list(count: int, seed: int = 13) -> list[np.ndarray]:
    """Identity, then ``count - 1`` seeded random rotations about z (object upright)."""
    rng = np.random.default_rng(seed)
    out = [np.eye(4)]
    for angle in rng.uniform(0.0, 2.0 * math.pi, size=count - 1):
        m = np.eye(4)
        c, s = math.cos(angle), math.sin(angle)
        m[:2, :2] = [[c, -s], [s, c]]
        out.append(m)
    return out


#: The local dex-urdf hands (never in the repository; for measurement only).
DEX_URDF = Path(os.environ.get("DEX_URDF", "/work/extern/dex-urdf/robots/hands"))
DEX_HANDS = {"allegro": "allegro_hand/allegro_hand_right.urdf", "leap": "leap_hand/leap_hand_right.urdf",
             "ability": "ability_hand/ability_hand_right.urdf", "schunk": "schunk_hand/schunk_svh_hand_right.urdf",
             "barrett": "barrett_hand/bhand_model.urdf", "inspire_urdf": "inspire_hand/inspire_hand_right.urdf",
             "shadow_urdf": "shadow_hand/shadow_hand_right.urdf", "dclaw": "dclaw_gripper/dclaw_gripper.urdf"}
_HANDS: dict = {}


def hand_path(spec: str) -> Path | None:
    """The description file of ``--hand`` (None: the paper hand's own path)."""
    if spec in ("paper", ""):
        return None
    if spec in DEX_HANDS:
        return DEX_URDF / DEX_HANDS[spec]
    sys.path.insert(0, str(REPO / "test"))
    import hand_files  # noqa: PLC0415 -- the test hands (installed wheels / written here)
    if spec == "allegro_like":
        import tempfile
        # one folder per process: the workers write the hand at once, and one could read
        # another's half-written mesh
        return hand_files.write_allegro_like(Path(tempfile.gettempdir()) / f"held_rate_hands_{os.getpid()}",
                                             coupled=False)
    if spec in hand_files.HANDS:
        return hand_files.installed_hand(spec)
    path = Path(spec)
    if not path.is_file():
        raise SystemExit(f"--hand: {spec!r} is neither a file nor a known hand name")
    return path


def general_hand(spec: str):
    """The loaded general hand of ``--hand`` (once per process)."""
    if spec not in _HANDS:
        from grasp_apso.model.hands.load import load_hand as load_any
        _HANDS[spec] = load_any(hand_path(spec))
    return _HANDS[spec]


def dexgraspbench_settings():
    """The simulation settings of DexGraspBench's evaluation: ours with
    :data:`DEXGRASPBENCH` (``SimulationSettings().dexgraspbench()``); the protocol and the
    sliding friction (the planner's mu) stay ours."""
    from grasp_apso.simulation.settings import SimulationSettings

    return SimulationSettings().dexgraspbench()


def run_case(task: tuple) -> dict:
    """Plan one (object, pose, algorithm, seed) on a table with the paper hand or the
    general hand of ``--hand`` and simulate every candidate (the paper hand with
    ``simulate_grasp``, a general hand with ``simulate_any_hand`` on its own file)."""
    from grasp_apso.model.scene import Scene
    from grasp_apso.quality.closing import closing_forces
    from grasp_apso.quality.robustness import normal_uncertainty, robust_epsilon
    from grasp_apso.search.options import PlanOptions
    from grasp_apso.search.planner import plan

    name, pose_index, pose, algorithm, seed, swarm, simulate, spec, dexgraspbench = task
    general = spec not in ("paper", "")
    if general:
        hand, plan_hand = general_hand(spec), general_hand(spec)
    else:
        from grasp_apso.model.hand import load_hand
        hand, plan_hand = load_hand(), None
    obj = load(name)
    rot = pose[:3, :3]
    vertices = np.asarray(obj.mesh.vertices) @ rot.T + pose[:3, 3]
    scene = Scene.table_under(vertices)
    top, low = float(vertices[:, 2].max()), float(vertices[:, 2].min())
    options = PlanOptions(algorithm=algorithm, simulate=simulate, **swarm)
    row = {"object": name, "pose": pose_index, "algorithm": algorithm, "seed": seed, "candidates": []}
    if general:
        row["hand"] = spec
    t0 = time.perf_counter()
    try:
        result = plan(obj, pose, options, np.random.default_rng(seed), hand=plan_hand, scene=scene)
    except Exception as exc:  # a failed plan is a recorded outcome, not a crash of the bench
        row.update(error=f"{type(exc).__name__}: {exc}", plan_s=time.perf_counter() - t0)
        return row
    row["plan_s"] = time.perf_counter() - t0
    row["message"] = result.candidates_message
    for cand in result.candidates:
        pts = np.array([c.position for c in cand.contacts]).reshape(-1, 3)
        nrm = np.array([c.normal for c in cand.contacts]).reshape(-1, 3)
        pts_obj, nrm_obj = (pts - pose[:3, 3]) @ rot, nrm @ rot  # planning -> object frame
        unc = normal_uncertainty(obj, pts_obj) if len(pts) else np.zeros(0)
        nominal = robust_epsilon(obj, pts_obj, nrm_obj, options.friction, np.zeros(len(pts)),
                                 options.friction_edges) if len(pts) >= 2 else 0.0
        robust = robust_epsilon(obj, pts_obj, nrm_obj, options.friction, unc,
                                options.friction_edges) if len(pts) >= 2 else 0.0
        features = {
            "rank": cand.rank, "epsilon": float(cand.epsilon), "force_closure": bool(cand.force_closure),
            "fitness": float(cand.fitness), "quality": float(cand.grasp_quality),
            "scene_distance_mm": 1000 * float(cand.scene_distance),
            "nominal_epsilon": nominal, "robust_epsilon": robust,
            "margin": min(1.0, robust / nominal) if nominal > 0 else 0.0,
            "fingers": [c.finger for c in cand.contacts],
            "thumb": any((hand.finger(c.finger).is_thumb if general else c.finger == "thumb")
                         for c in cand.contacts),
            "uncertainty_deg": np.degrees(unc).round(1).tolist(),
            "below_top_mm": (1000 * (top - pts[:, 2])).round(1).tolist(),
            "above_table_mm": (1000 * (pts[:, 2] - low)).round(1).tolist(),
            # where the contacts lie about the centre of mass (object frame, mm): the lever the
            # disturbance's force at the centre of mass has about them
            "contacts_com_mm": (1000 * (pts_obj - obj.center_of_mass)).round(1).tolist(),
        }
        if general:
            features["planner_sim"] = int(cand.sim_result)
            features["imbalance"] = closing_forces(pts_obj, nrm_obj, obj.center_of_mass,
                                                   obj.characteristic_radius)[1] if len(pts) >= 2 else 1.0
            features.update(_simulate_any(hand, obj, pose, cand, scene, options, row))
            if dexgraspbench:
                features.update(_held_dexgraspbench(hand, obj, pose, cand, scene, options, row))
        else:
            from grasp_apso.simulation import simulate_grasp

            sim = simulate_grasp(hand, obj, pose, cand.wrist_pose, cand.pre_grasp_positions[:15],
                                 cand.joint_positions[:15], planes=scene.planes)
            features.update({
                "held": bool(sim.held), "shift_mm": 1000 * sim.max_shift, "turn_deg": math.degrees(sim.max_turn),
                "failed": [d for d, _, _, ok in sim.per_direction if not ok], "sim_s": sim.sim_time,
            })
        row["candidates"].append(features)
    return row


def _from_planned(model, data, ref_pos: np.ndarray, ref_quat: np.ndarray) -> tuple[float, float]:
    """The object's shift (mm) and turn (deg) from its planned pose (``ref_pos`` (3,) m,
    ``ref_quat`` (4,)) in a check's current state."""
    from grasp_apso.simulation.any_hand_model import OBJECT_BODY
    from grasp_apso.simulation.phases import angle_between

    body = model.body(OBJECT_BODY).id
    return (1000 * float(np.linalg.norm(data.xipos[body] - ref_pos)),
            math.degrees(angle_between(ref_quat, data.xquat[body])))


def _simulate_any(hand, obj, pose, cand, scene, options, row: dict) -> dict:
    """A general hand's candidate in ``simulate_any_hand``: the verdict fields (an error is
    recorded in ``row["sim_errors"]`` and counted as dropped), and where the object was
    before the disturbances, from the planned pose: after the closing (``grasp_*``) and
    after the squeeze and its settling (``squeezed_*``); and DexGraspBench's tabletop test
    from the squeezed state (``lift_*``, :func:`lift_test`)."""
    from grasp_apso.simulation.any_hand import simulate_any_hand
    from grasp_apso.simulation.phases import planned_reference
    from grasp_apso.simulation.settings import SimulationSettings

    ref_pos, ref_quat = planned_reference(pose, obj.center_of_mass)
    seen: dict = {}
    settings = SimulationSettings()

    def observe(phase, model, data) -> None:
        if phase in ("grasp", "squeezed"):
            seen[phase] = _from_planned(model, data, ref_pos, ref_quat)
        if phase == "squeezed":
            seen["lift"] = lift_test(model, data, settings, ref_pos, ref_quat)

    try:
        sim = simulate_any_hand(hand, obj, pose, cand.wrist_pose, cand.pre_grasp_positions,
                                cand.joint_positions, cand.squeeze_positions, scene, options.friction,
                                settings=settings, observer=observe)
    except Exception as exc:  # recorded, counted as dropped
        row.setdefault("sim_errors", []).append(f"{type(exc).__name__}: {exc}")
        sim = None
    out = {
        "held": bool(sim is not None and sim.held),
        "shift_mm": 1000 * sim.max_shift if sim else math.inf,
        "turn_deg": math.degrees(sim.max_turn) if sim else math.inf,
        "failed": [d for d, _, _, ok in sim.per_direction if not ok] if sim else ["error"],
        "sim_s": sim.sim_time if sim else 0.0,
    }
    for phase in ("grasp", "squeezed"):
        out[f"{phase}_shift_mm"], out[f"{phase}_turn_deg"] = seen.get(phase, (math.inf, math.inf))
    held, shift, turn = seen.get("lift", (False, math.inf, math.inf))
    out.update(lift_held=bool(sim is not None and held), lift_shift_mm=1000 * shift, lift_turn_deg=math.degrees(turn))
    return out


def _held_dexgraspbench(hand, obj, pose, cand, scene, options, row: dict) -> dict:
    """Whether a general hand's candidate holds with :func:`dexgraspbench_settings` in the
    six directions (``dgb_held``), and in the tabletop test (:func:`lift_test`) from the
    same squeezed state (``dgb_lift_held``); where the object stood after the closing and
    after the squeeze (``dgb_grasp_*`` / ``dgb_squeezed_*`` shift mm and turn deg, as
    :func:`_simulate_any`). An error is recorded in ``row["sim_errors"]`` and counted as
    dropped."""
    from grasp_apso.simulation.any_hand import simulate_any_hand
    from grasp_apso.simulation.phases import planned_reference

    settings = dexgraspbench_settings()
    ref_pos, ref_quat = planned_reference(pose, obj.center_of_mass)
    seen: dict = {}

    def observe(phase, model, data) -> None:
        if phase in ("grasp", "squeezed"):
            seen[phase] = _from_planned(model, data, ref_pos, ref_quat)
        if phase == "squeezed":
            seen["lift"] = lift_test(model, data, settings, ref_pos, ref_quat)[0]

    try:
        sim = simulate_any_hand(hand, obj, pose, cand.wrist_pose, cand.pre_grasp_positions, cand.joint_positions,
                                cand.squeeze_positions, scene, options.friction, settings=settings, observer=observe)
    except Exception as exc:  # recorded, counted as dropped
        row.setdefault("sim_errors", []).append(f"dexgraspbench: {type(exc).__name__}: {exc}")
        sim = None
    out = {"dgb_held": bool(sim is not None and sim.held),
           "dgb_lift_held": bool(sim is not None and seen.get("lift", False)),
           "dgb_failed": [d for d, _, _, ok in sim.per_direction if not ok] if sim else ["error"]}
    for phase in ("grasp", "squeezed"):
        out[f"dgb_{phase}_shift_mm"], out[f"dgb_{phase}_turn_deg"] = seen.get(phase, (math.inf, math.inf))
    return out


#: DexGraspBench's tabletop test (``src/task/eval_func/tabletop_mocap.py``): after the
#: squeeze, 1 N down on the 0.1 kg object (``settings.object_mass * settings.disturbance``,
#: gravity off), the hand lifted LIFT_HEIGHT m in LIFT_TIME s (its 10 x 10 steps of 4 ms);
#: held within 5 cm and 15 degrees of the object's start raised LIFT_HEIGHT, read at the end.
LIFT_HEIGHT = 0.1
LIFT_TIME = 0.4


def lift_test(model, data, settings, ref_pos: np.ndarray, ref_quat: np.ndarray) -> tuple[bool, float, float]:
    """DexGraspBench's tabletop test from a squeezed state, in the hand's frame, on copies of
    the MuJoCo model and data (the check goes on from that state unchanged).

    The hand here is fixed to the world, so the lift is taken in the hand's frame, where it
    is the same motion: the table (the scene's geoms) drops away and the object starts
    moving down at the lift's speed (``LIFT_HEIGHT / LIFT_TIME``, at once: DexGraspBench's
    hand follows its mocap target through a weld, a softer start), pressed down by its
    weight, for ``LIFT_TIME``. (Moving the fixed hand instead, through its ``body_pos``,
    teleports it: MuJoCo sees no velocity, so friction never drags the object along.)
    Returns (held, shift m, turn rad) at the end: the centre of mass from ``ref_pos`` (3,),
    the turn from ``ref_quat`` (the planned pose); never held after a physics blow-up."""
    import copy

    import mujoco

    from grasp_apso.simulation.any_hand_model import OBJECT_BODY, SCENE_GEOM_PREFIX
    from grasp_apso.simulation.phases import angle_between, disable_contacts, instabilities

    m, d = copy.copy(model), copy.copy(data)
    body = m.body(OBJECT_BODY).id
    # the table and obstacles: the hand leaves them
    disable_contacts(m, [g for g in range(m.ngeom) if m.geom(g).name.startswith(SCENE_GEOM_PREFIX)])
    d.xfrc_applied[:] = 0.0
    d.xfrc_applied[body, 2] = -settings.object_mass * settings.disturbance
    dof = m.jnt_dofadr[m.body_jntadr[body]]  # the free joint: linear velocity first (world frame)
    d.qvel[dof + 2] -= LIFT_HEIGHT / LIFT_TIME
    try:
        mujoco.mj_step(m, d, nstep=max(1, int(round(LIFT_TIME / settings.timestep))))
    except mujoco.FatalError:  # unstable physics: not held
        return False, math.inf, math.inf
    shift = float(np.linalg.norm(d.xipos[body] - np.asarray(ref_pos, float)))
    turn = angle_between(np.asarray(ref_quat, float), d.xquat[body])
    held = bool(np.all(np.isfinite(d.qpos)) and not instabilities(d) and shift < settings.max_shift
                and turn < settings.max_turn)
    return held, shift, turn


#: A dropped grasp's object, after the closing, the squeeze and its settling, before any
#: disturbance, was: past the check's limits (``SimulationSettings.max_shift`` and
#: ``max_turn``, 5 cm and 15 degrees: dropped whatever the disturbance), moved at least
#: SHOVED_SHARE of a limit (16.7 mm or 5 degrees: the closing and squeeze used up a third
#: of what the disturbance may add), or near its planned pose (the disturbance dropped it).
SHOVED_SHARE = 1.0 / 3.0
DROP_PHASES = ("past the limits when squeezed", "moved a third of a limit by the closing and squeeze",
               "in the disturbance", "not simulated (an error, in sim_errors)")


def drop_phase(c: dict, check: str = "") -> str | None:
    """Where a dropped general-hand candidate went wrong (one of :data:`DROP_PHASES`) in our
    check, or with ``check="dgb_"`` in the check with DexGraspBench's parameters; None when
    it held or its phases were not recorded (the paper hand's check)."""
    from grasp_apso.simulation.settings import SimulationSettings  # the check's own limits

    # (runs saved before the phases were recorded have no squeezed shift: not counted)
    if c.get(f"{check}held", True) or f"{check}squeezed_shift_mm" not in c:
        return None
    if "error" in c.get(f"{check}failed", ()):  # the simulation did not run (MuJoCo refused the model)
        return DROP_PHASES[3]
    limits = SimulationSettings()  # both checks have the same limits
    shift = c[f"{check}squeezed_shift_mm"] / (1000 * limits.max_shift)
    turn = c[f"{check}squeezed_turn_deg"] / math.degrees(limits.max_turn)
    if max(shift, turn) >= 1.0:
        return DROP_PHASES[0]
    return DROP_PHASES[1] if max(shift, turn) >= SHOVED_SHARE else DROP_PHASES[2]


def best_by(cands: list[dict], key: str) -> dict | None:
    """The best grasp by ``key`` among the force-closure candidates (planner rank breaks
    ties); the planner's best when none is force closure. ``first_robust`` /
    ``first_margin``: the first candidate in the planner's order with a robust epsilon
    > 0 / a margin >= 0.25 (the planner's best when none)."""
    if not cands:
        return None
    if key.startswith("first_"):
        ok = (lambda c: c["robust_epsilon"] > 0.0) if key == "first_robust" else (lambda c: c["margin"] >= 0.25)
        return next((c for c in cands if ok(c)), cands[0])
    pool = [c for c in cands if c["force_closure"]] or cands[:1]
    return max(pool, key=lambda c: (c[key], -c["rank"]))


def summarise(rows: list[dict]) -> dict:
    """Held rates of one group of plans: best, all candidates, and re-ranked bests."""
    cands = [c for r in rows for c in r["candidates"]]
    planned = [r for r in rows if r["candidates"]]
    out = {"plans": len(rows), "plan_errors": sum("error" in r for r in rows),
           "plans_with_grasp": len(planned),
           "median_plan_s": statistics.median([r["plan_s"] for r in rows]) if rows else math.nan,
           "best_held": sum(r["candidates"][0]["held"] for r in planned),
           "candidates": len(cands), "candidates_held": sum(c["held"] for c in cands),
           "median_shift_mm": statistics.median([c["shift_mm"] for c in cands]) if cands else math.nan,
           "median_turn_deg": statistics.median([c["turn_deg"] for c in cands]) if cands else math.nan,
           "failed_directions": {}}
    for c in cands:
        for d in c["failed"]:
            out["failed_directions"][d] = out["failed_directions"].get(d, 0) + 1
    for key in RERANK_KEYS:
        out[f"best_held_by_{key}"] = sum(best_by(r["candidates"], key)["held"] for r in planned)
    robust = [c for c in cands if c["robust_epsilon"] > 0.0]
    out["robust_candidates"], out["robust_candidates_held"] = len(robust), sum(c["held"] for c in robust)
    for check in ("lift", "dgb", "dgb_lift"):  # the other checks' verdicts, when recorded
        key = f"{check}_held"
        if cands and all(key in c for c in cands):
            out[f"{check}_best_held"] = sum(r["candidates"][0][key] for r in planned)
            out[f"{check}_candidates_held"] = sum(c[key] for c in cands)
    for check in ("", "dgb_"):
        phases = [drop_phase(r["candidates"][0], check) for r in planned]
        if any(phases):
            out[f"{check}best_dropped_by_phase"] = {p: phases.count(p) for p in DROP_PHASES}
    return out


def _rate(n: int, d: int) -> str:
    return f"{n:3d}/{d:<3d} {100.0 * n / d:5.1f}%" if d else "   —        "


def print_report(rows: list[dict], algorithms: list[str], objects: list[str]) -> dict:
    summary = {}
    for alg in algorithms:
        print(f"\n== {alg.upper()} ==")
        print(f"{'object':22s} {'best held':>13s} {'cands held':>13s} {'shift mm':>8s} {'turn deg':>8s}  "
              f"{'by robust':>9s}  failing directions")
        per_object = {}
        for name in objects:
            group = [r for r in rows if r["algorithm"] == alg and r["object"] == name]
            s = summarise(group)
            per_object[name] = s
            fails = " ".join(f"{d}:{n}" for d, n in sorted(s["failed_directions"].items()))
            err = f" ({s['plan_errors']} plan errors)" if s["plan_errors"] else ""
            print(f"{name:22s} {_rate(s['best_held'], s['plans'] - s['plan_errors'])} "
                  f"{_rate(s['candidates_held'], s['candidates'])} {s['median_shift_mm']:8.1f} "
                  f"{s['median_turn_deg']:8.1f}  {s['best_held_by_robust_epsilon']:4d}/{s['plans'] - s['plan_errors']:<4d}"
                  f"  {fails}{err}")
        for label, names in (("built-ins", [n for n in objects if n in BUILTINS]),
                             ("meshes", [n for n in objects if n not in BUILTINS]), ("all", objects)):
            group = [r for r in rows if r["algorithm"] == alg and r["object"] in names]
            if not group:
                continue
            s = summarise(group)
            planned = s["plans"] - s["plan_errors"]
            print(f"{'TOTAL ' + label:22s} {_rate(s['best_held'], planned)} {_rate(s['candidates_held'], s['candidates'])}"
                  f"   plans with a grasp {_rate(planned, s['plans'])}, median plan {s['median_plan_s']:.1f} s")
            print(f"{'':22s} best re-ranked: " + ", ".join(f"{k} {_rate(s['best_held_by_' + k], planned)}"
                                                          for k in RERANK_KEYS))
            print(f"{'':22s} candidates with robust epsilon > 0: "
                  f"{_rate(s['robust_candidates_held'], s['robust_candidates'])} held")
            if "dgb_best_held" in s:
                print(f"{'':22s} with DexGraspBench's parameters: best {_rate(s['dgb_best_held'], planned)}, "
                      f"candidates {_rate(s['dgb_candidates_held'], s['candidates'])}")
            if "lift_best_held" in s:
                lift = (f"{'':22s} lifted 10 cm off the table (DexGraspBench's tabletop test): best "
                        f"{_rate(s['lift_best_held'], planned)}, candidates "
                        f"{_rate(s['lift_candidates_held'], s['candidates'])}")
                if "dgb_lift_best_held" in s:
                    lift += (f"; with its parameters: best {_rate(s['dgb_lift_best_held'], planned)}, candidates "
                             f"{_rate(s['dgb_lift_candidates_held'], s['candidates'])}")
                print(lift)
            for check, which in (("", ""), ("dgb_", " with DexGraspBench's parameters")):
                if f"{check}best_dropped_by_phase" in s:
                    print(f"{'':22s} best grasps dropped{which}, the object when squeezed: "
                          + ", ".join(f"{n} {p}" for p, n in s[f"{check}best_dropped_by_phase"].items()))
            summary[f"{alg}/{label}"] = s
        summary[f"{alg}/per_object"] = per_object
    return summary


def print_failures(rows: list[dict]) -> None:
    """One line per dropped candidate, then held vs dropped feature medians."""
    print("\n== dropped grasps (rank, fingers, uncertainty deg per contact, mm below top, eps, robust eps, "
          "shift mm / turn deg, failing directions) ==")
    for r in rows:
        for c in r["candidates"]:
            if not c["held"]:
                print(f"{r['algorithm']:4s} {r['object']:20s} p{r['pose']} s{r['seed']} #{c['rank']} "
                      f"{'+'.join(f[0].upper() for f in c['fingers']):6s} unc {c['uncertainty_deg']} "
                      f"top {c['below_top_mm']} eps {c['epsilon']:.3f} rob {c['robust_epsilon']:.3f} "
                      f"{c['shift_mm']:.0f}/{c['turn_deg']:.0f} {','.join(c['failed'])}"
                      + (f" squeezed {c['squeezed_shift_mm']:.0f}/{c['squeezed_turn_deg']:.0f}"
                         if "squeezed_shift_mm" in c else ""))
    cands = [c for r in rows for c in r["candidates"]]
    features = {
        "contacts": lambda c: len(c["fingers"]), "thumb": lambda c: float(c["thumb"]),
        "max uncertainty deg": lambda c: max(c["uncertainty_deg"] or [0.0]),
        "contacts > 20 deg": lambda c: sum(u > 20 for u in c["uncertainty_deg"]),
        "min mm below top": lambda c: min(c["below_top_mm"] or [math.nan]),
        "epsilon": lambda c: c["epsilon"], "robust epsilon": lambda c: c["robust_epsilon"],
        "margin": lambda c: c["margin"],
        "closing imbalance": lambda c: c.get("imbalance", math.nan),
    }
    print(f"\n{'feature (median / mean)':24s} {'held':>16s} {'dropped':>16s}")
    for label, f in features.items():
        vals = {k: [f(c) for c in cands if c["held"] == k] for k in (True, False)}
        cells = [f"{statistics.median(v):7.3f} /{statistics.fmean(v):7.3f}" if v else f"{'—':>16s}"
                 for v in (vals[True], vals[False])]
        print(f"{label:24s} {cells[0]:>16s} {cells[1]:>16s}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="particles 30, iterations 20, 1 seed")
    parser.add_argument("--seeds", type=int, default=3, help="seeds 0..N-1 (default 3; --quick: 1)")
    parser.add_argument("--first-seed", type=int, default=0, help="seeds from this one on (default 0)")
    parser.add_argument("--poses", type=int, default=1, help="identity + N-1 random rotations about z")
    parser.add_argument("--stable", action="store_true",
                        help="each mesh in its most probable resting pose (trimesh) before those rotations, "
                             "instead of its file's frame")
    parser.add_argument("--algorithms", nargs="+", default=["apso", "pso"], choices=["apso", "pso"])
    parser.add_argument("--objects", nargs="+", default=None, help="default: 4 built-ins + every mesh")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--simulate", action="store_true",
                        help="plan with PlanOptions.simulate (the simulation in the final selection: "
                             "held candidates first); every candidate is then simulated again here")
    parser.add_argument("--failures", action="store_true", help="print every dropped grasp")
    parser.add_argument("--dexgraspbench", action="store_true",
                        help="a general hand's candidates also checked with DexGraspBench's contact and servo "
                             "parameters (dexgraspbench_settings)")
    parser.add_argument("--hand", default="paper",
                        help="paper (default), a test hand (shadow, inspire, allegro_like, ...), a dex-urdf "
                             "hand (allegro, leap, ability, ...) or a URDF / MJCF file")
    parser.add_argument("--out", type=Path, default=None,
                        help="default bench/results/held_rate[_<hand>][_simulate].json")
    parser.add_argument("--from-json", type=Path, help="reprint the tables of a saved run, no planning")
    args = parser.parse_args(argv)
    if args.from_json:
        saved = json.loads(args.from_json.read_text())
        rows = saved["runs"]
        algs = list(dict.fromkeys(r["algorithm"] for r in rows))
        print_report(rows, algs, list(dict.fromkeys(r["object"] for r in rows)))
        if args.failures:
            print_failures(rows)
        print(f"(from {args.from_json}: {saved['command']})")
        return 0
    objects = args.objects or list(BUILTINS) + mesh_names()
    seeds = 1 if args.quick else args.seeds
    swarm = {"particles": 30, "iterations": 20} if args.quick else {}
    poses = pose_list(args.poses)
    if args.hand not in ("paper", ""):
        hand_path(args.hand)  # a bad name fails here, before any worker starts
    tag = "" if args.hand == "paper" else "_" + Path(args.hand).stem
    out = args.out or REPO / "bench" / "results" / f"held_rate{tag}{'_simulate' if args.simulate else ''}.json"
    if args.dexgraspbench and args.hand in ("paper", ""):
        raise SystemExit("--dexgraspbench: for a general hand (--hand); the paper hand keeps its published check")
    rest = {name: stable_pose(name) if args.stable else np.eye(4) for name in objects}
    tasks = [(name, k, pose @ rest[name], alg, seed, swarm, args.simulate, args.hand, args.dexgraspbench)
             for alg in args.algorithms for name in objects
             for k, pose in enumerate(poses) for seed in range(args.first_seed, args.first_seed + seeds)]
    t0 = time.perf_counter()
    load0 = os.getloadavg()[0]
    if args.workers > 1:
        with ProcessPoolExecutor(args.workers) as pool:
            rows = list(pool.map(run_case, tasks))
    else:
        rows = [run_case(t) for t in tasks]
    wall = time.perf_counter() - t0
    summary = print_report(rows, args.algorithms, objects)
    if args.failures:
        print_failures(rows)
    print(f"\n{len(tasks)} plans in {wall:.0f} s ({args.workers} workers, load average {load0:.1f} -> "
          f"{os.getloadavg()[0]:.1f})")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({
        "benchmark": "held_rate", "hand": args.hand, "simulate": args.simulate,
        "dexgraspbench": DEXGRASPBENCH if args.dexgraspbench else None, "command": " ".join(["bench/held_rate.py", *(argv or sys.argv[1:])]),
        "swarm": swarm or "default", "seeds": list(range(args.first_seed, args.first_seed + seeds)), "poses": [p.tolist() for p in poses],
        "stable": args.stable,
        "wall_s": round(wall, 1), "summary": summary, "runs": rows}, indent=1, default=float) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
