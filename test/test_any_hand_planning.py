"""Planning with general hands (issue 21): the Allegro-like URDF hand, the Shadow hand, the
Inspire hand and the paper's own hand read from its URDF (``urdf/apso_paper_hand.urdf``: five
fingers, mimic couplings, a fingertip sphere fixed to each distal link) through the same
general path, on the built-in cube, sphere and barrel and the real mug, each resting on a
table.

Every returned grasp is checked independently of the planner's code: joint limits from the
hand model; the pads (spheres of ``pad_radius`` whose surface passes through the pad point,
posed by ``hand.link_transforms`` at the returned posture and ``wrist_pose``) on the
object's surface within 2 mm by trimesh's exact proximity; no link
within the clearance of the table by python-fcl on each link's exact collision geometry
(built here from ``hand.collision``); the same seed gives the same result.
"""

from __future__ import annotations

from pathlib import Path

import fcl
import numpy as np
import pytest
import trimesh

from grasp_apso.errors import PlanningError
from grasp_apso.model.builtin import builtin
from grasp_apso.model.hands.load import load_hand
from grasp_apso.model.scene import Scene
from grasp_apso.search.planner import PlanOptions, plan
from hand_files import installed_hand, write_allegro_like

ROOT = Path(__file__).resolve().parents[1]
OBJECTS = ("cube", "sphere", "barrel", "mug")
HANDS = ("allegro", "shadow", "inspire", "paper_urdf")
SEEDS = (0, 1)
OPTIONS = PlanOptions(particles=30, iterations=20, max_grasps=3)
PAD_TOLERANCE = 0.002
#: Seeds tried, at most, for a plan with a scenario the test needs (a grasp that held in
#: the simulation; a second search).
SIMULATE_SEEDS = 4
SECOND_SEARCH_SEEDS = 10
FALLBACK_SEEDS = 4
#: Inspire plans (object, seed; the default swarm, simulate) with a grasp that dropped and
#: held with the firmer squeeze (measured over 8 objects, seeds 0-1: only the gelatin box's
#: seed 1).
FIRMER_PLANS = (("gelatin_box", 1),)
#: Allegro-like plans of the screwdriver (seeds; the default swarm, simulate): seed 4's
#: grasps all dropped in three searches and held in the fourth, seed 5's held in its second
#: (measured).
LATER_SEARCH_SEEDS = (4, 5)
#: m, the median pad gap at a hand's pre-grasps (measured 10-25 mm on the cube and the mug;
#: the search's wide-open pre-shapes, 40-140 mm).
NEAR_PRE_GRASP = 0.04


@pytest.fixture(scope="module")
def hands(tmp_path_factory):
    folder = tmp_path_factory.mktemp("hands")
    return {
        "allegro": load_hand(write_allegro_like(folder, "mixed")),
        "shadow": load_hand(installed_hand("shadow")),
        "inspire": load_hand(installed_hand("inspire")),
        "paper_urdf": load_hand(ROOT / "urdf" / "apso_paper_hand.urdf"),
    }


def _reply_robust_epsilon(obj, cand, options) -> float:
    """The robust epsilon of a candidate's contacts as the reply gives them (positions and
    normals), recomputed independently of the planner's own value."""
    from grasp_apso.quality.robustness import normal_uncertainty, robust_epsilon

    points = np.array([c.position for c in cand.contacts])
    normals = np.array([c.normal for c in cand.contacts])
    return robust_epsilon(obj, points, normals, options.friction, normal_uncertainty(obj, points),
                          options.friction_edges)


def _object(name: str):
    """A built-in object, or a shipped mesh by name (:func:`conftest.shipped_object`)."""
    from conftest import shipped_object

    return shipped_object(name)


def _fcl_geometry(geom):
    """python-fcl geometry of one LinkGeometry (its exact shape)."""
    if geom.kind == "box":
        return fcl.Box(*(2.0 * np.asarray(geom.size)))
    if geom.kind == "sphere":
        return fcl.Sphere(geom.size[0])
    if geom.kind == "cylinder":
        return fcl.Cylinder(geom.size[0], 2.0 * geom.size[1])
    if geom.kind == "capsule":
        return fcl.Capsule(geom.size[0], 2.0 * geom.size[1])
    model = fcl.BVHModel()
    model.beginModel(len(geom.mesh.vertices), len(geom.mesh.faces))
    model.addSubModel(np.asarray(geom.mesh.vertices, float), np.asarray(geom.mesh.faces, np.int64))
    model.endModel()
    return model


def _table_distance(hand, q: np.ndarray, root: np.ndarray, plane: np.ndarray) -> float:
    """Least python-fcl distance of the hand's links to a table top (a 2 m slab under the plane)."""
    n, d = plane[:3], plane[3]
    slab = fcl.Box(2.0, 2.0, 0.2)
    rot = trimesh.geometry.align_vectors([0, 0, 1.0], n)[:3, :3]
    centre = -d * n - 0.1 * n
    table = fcl.CollisionObject(slab, fcl.Transform(rot, centre))
    poses = hand.link_transforms(q)
    best = np.inf
    for link, geoms in hand.collision.items():
        for geom in geoms:
            tf = root @ poses[link] @ geom.origin
            obj = fcl.CollisionObject(_fcl_geometry(geom), fcl.Transform(tf[:3, :3], tf[:3, 3]))
            result = fcl.DistanceResult()
            best = min(best, fcl.distance(obj, table, fcl.DistanceRequest(), result))
    return best


def _pad_sphere(hand, finger) -> np.ndarray:
    """The pad sphere's centre in the pad link's frame, from the exact geometry (trimesh):
    the pad point moved ``pad_radius`` inward along the face normal nearest to it."""
    mesh = trimesh.util.concatenate([g.to_trimesh() for g in hand.collision[finger.pad_link]])
    _, _, face = trimesh.proximity.closest_point(mesh, np.asarray(finger.pad_center, float)[None])
    return np.asarray(finger.pad_center) - finger.pad_radius * mesh.face_normals[face[0]]


def _pad_gaps(hand, cand, q: np.ndarray, mesh: trimesh.Trimesh) -> list[float]:
    """Signed gap (m) between each contact finger's pad sphere, at posture q and the
    candidate's wrist pose, and the object's surface (negative: inside)."""
    poses = hand.link_transforms(q)
    out = []
    for contact in cand.contacts:
        finger = hand.finger(contact.finger)
        centre = (cand.wrist_pose @ poses[finger.pad_link] @ np.append(_pad_sphere(hand, finger), 1.0))[:3]
        _, distance, _ = trimesh.proximity.closest_point(mesh, centre[None])
        inside = bool(mesh.contains(centre[None])[0])
        out.append((-1.0 if inside else 1.0) * float(distance[0]) - finger.pad_radius)
    return out


def _pad_errors(hand, result, mesh: trimesh.Trimesh) -> list[float]:
    """|distance of each contact finger's pad sphere centre to the object's surface - pad radius| (m):
    how far the pad's surface is from the object's."""
    poses = hand.link_transforms(result.joint_positions)
    out = []
    for contact in result.contacts:
        finger = hand.finger(contact.finger)
        centre = result.wrist_pose @ poses[finger.pad_link] @ np.append(_pad_sphere(hand, finger), 1.0)
        _, distance, _ = trimesh.proximity.closest_point(mesh, centre[None, :3])
        out.append(abs(float(distance[0]) - finger.pad_radius))
    return out


def _pad_link_distances(hand, cand, mesh: trimesh.Trimesh) -> list[float]:
    """|python-fcl signed distance| (m) of each contact finger's pad link (its collision
    geometry as the file gives it) to the object's mesh, at the candidate's grasp: its
    depth from python-fcl's contacts when it touches (the distance query then reads -1)."""
    model = fcl.BVHModel()
    model.beginModel(len(mesh.vertices), len(mesh.faces))
    model.addSubModel(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64))
    model.endModel()
    obj = fcl.CollisionObject(model, fcl.Transform())
    poses = hand.link_transforms(cand.joint_positions)
    out = []
    for contact in cand.contacts:
        link = hand.finger(contact.finger).pad_link
        best = np.inf
        for geom in hand.collision[link]:
            tf = cand.wrist_pose @ poses[link] @ geom.origin
            part = fcl.CollisionObject(_fcl_geometry(geom), fcl.Transform(tf[:3, :3], tf[:3, 3]))
            request = fcl.DistanceRequest(enable_signed_distance=True)
            distance = fcl.distance(part, obj, request, fcl.DistanceResult())
            if distance < 0.0:  # touching: python-fcl reads -1 against a mesh; the depth from the contacts
                result = fcl.CollisionResult()
                fcl.collide(part, obj, fcl.CollisionRequest(num_max_contacts=64, enable_contact=True), result)
                distance = max((c.penetration_depth for c in result.contacts), default=0.0)
            best = min(best, abs(distance))
        out.append(best)
    return out


@pytest.fixture(scope="module")
def plans(hands):
    out = {}
    for hand_name in HANDS:
        for obj_name in OBJECTS:
            obj = _object(obj_name)
            table = Scene.table_under(np.asarray(obj.mesh.vertices))
            for seed in SEEDS:
                try:
                    result = plan(obj, options=OPTIONS, rng=np.random.default_rng(seed), hand=hands[hand_name],
                                  scene=table)
                except PlanningError as exc:
                    result = exc
                out[hand_name, obj_name, seed] = (obj, table, result)
    return out


def test_most_plans_return_a_grasp(plans):
    returned = {k: not isinstance(v[2], Exception) for k, v in plans.items()}
    for hand in HANDS:
        rate = np.mean([ok for k, ok in returned.items() if k[0] == hand])
        print(f"{hand}: {rate * 100:.0f}% of {len(OBJECTS) * len(SEEDS)} plans returned a grasp")
    assert np.mean(list(returned.values())) >= 0.75, returned


@pytest.mark.parametrize("hand_name", HANDS)
def test_returned_grasps_are_sound(hands, plans, hand_name):
    hand = hands[hand_name]
    checked = 0
    pre_gaps = []
    for (h, obj_name, seed), (obj, table, result) in plans.items():
        if h != hand_name or isinstance(result, Exception):
            continue
        assert result.joint_names == hand.actuated_joints
        assert result.hand_name == hand.name and result.hand_hash == hand.source_hash
        assert result.joints.shape == (0, 4, 3)
        for cand in result.candidates:
            for q in (cand.joint_positions, cand.pre_grasp_positions, cand.squeeze_positions):
                assert q.shape == (hand.n_joints,)
                assert np.all(q >= hand.lower - 1e-9) and np.all(q <= hand.upper + 1e-9), (obj_name, seed)
        for cand in result.candidates:
            if cand.valid:
                assert cand.n_contacts >= 2
                # each contact's pad on the surface: its pad sphere, or (a curved fingertip
                # resting beside its pad point) the pad link's own collision geometry
                errors = np.minimum(_pad_errors(hand, cand, obj.mesh), _pad_link_distances(hand, cand, obj.mesh))
                assert max(errors) <= PAD_TOLERANCE, (obj_name, seed, cand.rank, errors)
        for cand in result.candidates:
            # The pre-grasp at the grasp's wrist pose (a DexGraspBench replay starts there):
            # clear of the object, the pads just off it (the closing then starts near the
            # contacts instead of wide open).
            gaps = _pad_gaps(hand, cand, cand.pre_grasp_positions, obj.mesh)
            assert min(gaps) >= -0.001, (obj_name, seed, cand.rank, gaps)
            pre_gaps.append(float(np.median(gaps)))
        plane = table.planes[0]
        for cand in result.candidates:
            assert _table_distance(hand, cand.joint_positions, cand.wrist_pose, plane) >= OPTIONS.clearance - 1e-4, (
                obj_name, seed, cand.rank)
            assert _table_distance(hand, cand.pre_grasp_positions, cand.pre_grasp_pose, plane) >= (
                OPTIONS.clearance - 1e-4), (obj_name, seed, cand.rank, "pre-grasp")
        checked += 1
    assert checked >= 1
    assert np.median(pre_gaps) <= NEAR_PRE_GRASP, sorted(pre_gaps)


def test_same_seed_same_result(hands, plans):
    obj, table, first = plans["allegro", "cube", 0]
    again = plan(obj, options=OPTIONS, rng=np.random.default_rng(0), hand=hands["allegro"], scene=table)
    assert np.array_equal(first.joint_positions, again.joint_positions)
    assert np.array_equal(first.wrist_pose, again.wrist_pose)
    assert [c.fitness for c in first.candidates] == [c.fitness for c in again.candidates]


def test_simulate_ranks_held_grasps_first(hands):
    """With ``simulate`` every candidate of a general hand is checked in MuJoCo
    (simulate_any_hand) and only held ones are returned when any held."""
    obj = builtin("cube")
    table = Scene.table_under(np.asarray(obj.mesh.vertices))
    options = PlanOptions(particles=30, iterations=20, max_grasps=2, simulate=True)
    held = False
    # a small swarm: the first seeds until a plan has a grasp that held (seed 0's two
    # grasps both drop; bounded)
    for seed in range(SIMULATE_SEEDS):
        result = plan(obj, options=options, rng=np.random.default_rng(seed), hand=hands["inspire"], scene=table)
        sims = [c.sim_result for c in result.candidates]
        assert all(s in (0, 1) for s in sims), sims
        assert sims == sorted(sims, reverse=True)
        assert all(np.isfinite(c.sim_max_shift) for c in result.candidates)
        if 1 in sims:
            # grasps that dropped are not returned next to ones that held
            assert set(sims) == {1}, (seed, sims)
            held = True
            break
    assert held, "no plan had a grasp that held"


@pytest.fixture
def searches(monkeypatch):
    """The searches of the plans made in a test, one entry per search: whether it turned a
    long object's guidance. Counted by spying on (not replacing) the selection, which each
    search calls once with its problem."""
    from grasp_apso.search import any_hand_planner

    select = any_hand_planner.select_any
    seen: list[bool] = []

    def spying(*args, **kwargs):
        seen.append(args[1].shape.across)  # args[1]: the search's problem
        return select(*args, **kwargs)

    monkeypatch.setattr(any_hand_planner, "select_any", spying)
    return seen


def test_simulate_searches_again_until_a_grasp_held(hands, searches):
    """With ``simulate`` a plan whose grasps all dropped searches again, up to
    ``SIMULATED_ROUNDS`` searches: it stops at the first search with a grasp that held and
    returns only held grasps; a plan that never held searched the whole bound, the searches
    from ``TURNED_ROUNDS_FROM`` on with the long object's guidance turned."""
    from grasp_apso.search.any_hand_planner import SIMULATED_ROUNDS, TURNED_ROUNDS_FROM
    from grasp_apso.search.result import SIM_HELD

    calls = searches
    obj = _object("phillips_screwdriver")
    table = Scene.table_under(np.asarray(obj.mesh.vertices))
    options = PlanOptions(max_grasps=5, simulate=True)
    held_late = []
    for seed in LATER_SEARCH_SEEDS:
        calls.clear()
        result = plan(obj, options=options, rng=np.random.default_rng(seed), hand=hands["allegro"], scene=table)
        sims = [c.sim_result for c in result.candidates]
        assert 1 <= len(calls) <= SIMULATED_ROUNDS
        assert calls == [i >= TURNED_ROUNDS_FROM for i in range(len(calls))], (seed, calls)
        if SIM_HELD in sims:
            assert set(sims) == {SIM_HELD}, (seed, sims)
            if len(calls) > 2:
                held_late.append(seed)
        else:
            assert len(calls) == SIMULATED_ROUNDS, (seed, len(calls))
    assert held_late, "no plan held only after its third search"


def test_simulate_searches_an_object_with_no_long_axis_only_with_its_own_guidance(hands, searches):
    """The bowl (sphere-like: no long axis to turn) with a small swarm, whose grasps all
    drop: the plan stops after ``TURNED_ROUNDS_FROM`` searches, none turned, and returns the
    grasps of the first search of the best class with their verdicts."""
    from grasp_apso.search.any_hand_planner import SIMULATED_ROUNDS, TURNED_ROUNDS_FROM
    from grasp_apso.search.result import SIM_DROPPED

    obj = _object("bowl")
    table = Scene.table_under(np.asarray(obj.mesh.vertices))
    options = PlanOptions(max_grasps=1, simulate=True, particles=20, iterations=10)
    result = plan(obj, options=options, rng=np.random.default_rng(1), hand=hands["inspire"], scene=table)
    assert TURNED_ROUNDS_FROM < SIMULATED_ROUNDS
    assert searches == [False] * TURNED_ROUNDS_FROM
    assert [c.sim_result for c in result.candidates] == [SIM_DROPPED]


def test_simulate_without_the_simulation_answers_as_without_it(hands, searches, monkeypatch):
    """When the simulation cannot run (MuJoCo not installed here; a hand file MuJoCo
    refuses, as DexHand's zero inertias did before 90d432c, the same way) ``simulate``
    cannot hold a grasp. The plan no longer searches ``TURNED_ROUNDS_FROM`` times for one:
    it stops once a search found balanced robust force closure, as without ``simulate`` (at
    most ``UNBALANCED_ROUNDS`` searches), and returns the
    grasps of the search of the best class, not the first search's (DexHand's mug: the
    first search's five grasps without force closure where a later one had three with it);
    the reply says why nothing was simulated."""
    from grasp_apso.search import any_hand_simulate
    from grasp_apso.search.any_hand_planner import UNBALANCED_ROUNDS
    from grasp_apso.search.result import SIM_NOT_RUN

    found = any_hand_simulate.optional_module
    monkeypatch.setattr(any_hand_simulate, "optional_module",
                        lambda name: None if name == "grasp_apso.simulation.any_hand" else found(name))
    obj = _object("mug")
    table = Scene.table_under(np.asarray(obj.mesh.vertices))
    for seed in (0, 1):
        searches.clear()
        result = plan(obj, options=PlanOptions(max_grasps=3, simulate=True), rng=np.random.default_rng(seed),
                      hand=hands["allegro"], scene=table)
        assert "MuJoCo check of a general hand is not available" in result.candidates_message
        assert all(c.sim_result == SIM_NOT_RUN for c in result.candidates)
        assert all(c.force_closure for c in result.candidates), seed
        assert 1 <= len(searches) <= UNBALANCED_ROUNDS, (seed, len(searches))


def test_simulate_turns_a_long_objects_guidance_in_its_last_searches(hands, searches):
    """The Shadow's screwdriver lying on a table (seed 0): none of the six searches with the
    paper's guidance (palm y along the handle, so the thumb opposes along it) found a grasp
    that held; the first search with the guidance turned (the fingers along the handle,
    the thumb's opposition across it) did, and the plan returns only held grasps."""
    from grasp_apso.search.any_hand_planner import TURNED_ROUNDS_FROM
    from grasp_apso.search.result import SIM_HELD

    obj = _object("phillips_screwdriver")
    table = Scene.table_under(np.asarray(obj.mesh.vertices))
    result = plan(obj, options=PlanOptions(max_grasps=5, simulate=True), rng=np.random.default_rng(0),
                  hand=hands["shadow"], scene=table)
    assert searches == [False] * TURNED_ROUNDS_FROM + [True]
    assert result.candidates and {c.sim_result for c in result.candidates} == {SIM_HELD}
    # the held grasp's fingers lie along the handle: palm x (the hand's palm basis turned
    # by the root's pose) within 45 degrees of its long axis
    from grasp_apso.geometry.any_hand_tables import hand_tables

    palm_x = np.asarray(result.candidates[0].wrist_pose)[:3, :3] @ hand_tables(hands["shadow"]).basis[:, 0]
    assert abs(palm_x @ np.asarray(obj.principal_axes)[0]) > np.cos(np.radians(45))


def _verified_grasp(checked, cand):
    """The verified grasp (AnyChecked) a returned candidate came from."""
    return next(c for c in checked if np.allclose(c.decoded.root[0], cand.wrist_in_object)
                and np.allclose(c.decoded.q[0], cand.joint_positions))


def test_simulate_tries_the_grasps_below_the_best_class_last(hands, monkeypatch):
    """With ``simulate`` the verified grasps without (robust) force closure are kept for
    the simulation's last resort instead of being left out: after every other grasp, each
    below a class the others have, and returned only when it held."""
    from grasp_apso.search import any_hand_planner
    from grasp_apso.search.any_hand_select import select_any
    from grasp_apso.search.result import SIM_HELD

    calls = []

    def recording(*args, **kwargs):
        checked, message = select_any(*args, **kwargs)
        calls.append(list(checked))
        return checked, message

    monkeypatch.setattr(any_hand_planner, "select_any", recording)
    obj = _object("mug")
    table = Scene.table_under(np.asarray(obj.mesh.vertices))
    options = PlanOptions(particles=30, iterations=20, max_grasps=2, simulate=True)
    found = False
    for seed in range(FALLBACK_SEEDS):  # bounded: until a search has such grasps
        calls.clear()
        result = plan(obj, options=options, rng=np.random.default_rng(seed), hand=hands["inspire"], scene=table)
        for checked in calls:
            flags = [c.fallback for c in checked]
            assert flags == sorted(flags), flags  # the fallback grasps last
            primary = [c for c in checked if not c.fallback]
            for c in checked[len(primary):]:
                if c.force_closure:
                    assert c.robust_epsilon <= 0.0 and any(p.robust_epsilon > 0.0 for p in primary)
                else:
                    assert any(p.force_closure for p in primary)
            found = found or any(flags)
        checked = calls[-1]
        for cand in result.candidates:
            if _verified_grasp(checked, cand).fallback:
                assert cand.sim_result == SIM_HELD
        if found:
            break
    assert found, "no search had grasps below the best class"


def test_a_grasp_that_held_with_the_firmer_squeeze_is_returned_with_it(hands, monkeypatch):
    """With ``simulate`` a grasp that drops is simulated once more with its squeeze at
    FIRM_SQUEEZE of the force; when that holds, the reply carries that squeeze, and a replay
    of the reply (the simulation called again with the candidate's own postures) holds."""
    from grasp_apso.search.any_hand_squeeze import FIRM_SQUEEZE
    from grasp_apso.search.result import SIM_HELD
    from grasp_apso.simulation import any_hand as sim

    real = sim.simulate_any_hand
    calls = []

    def recording(*args, **kwargs):
        result = real(*args, **kwargs)
        calls.append((np.array(args[5], float), np.array(args[6], float), result.held))  # q_grasp, q_squeeze
        return result

    monkeypatch.setattr(sim, "simulate_any_hand", recording)
    hand = hands["inspire"]
    rescued = None
    for name, seed in FIRMER_PLANS:  # bounded: until a plan has such a grasp
        calls.clear()
        obj = _object(name)
        table = Scene.table_under(np.asarray(obj.mesh.vertices))
        result = plan(obj, options=PlanOptions(max_grasps=5, simulate=True), rng=np.random.default_rng(seed),
                      hand=hand, scene=table)
        pairs = [(a, b) for a, b in zip(calls, calls[1:])
                 if np.array_equal(a[0], b[0]) and not a[2] and b[2]]  # dropped, then held firmer
        if pairs:
            rescued = (obj, table, result, pairs)
            break
    assert rescued is not None, "no plan had a grasp that held only with the firmer squeeze"
    obj, table, result, pairs = rescued
    assert f"held with a firmer squeeze ({FIRM_SQUEEZE:.3g} of the force)" in result.candidates_message
    for (q, first, _), (_, firm, _) in pairs:
        # the firmer squeeze presses the joints farther past the grasp posture
        assert np.linalg.norm(firm - q) > np.linalg.norm(first - q)
        cand = next((c for c in result.candidates if np.array_equal(c.joint_positions, q)), None)
        if cand is None:  # held, but ranked out of the max_grasps returned
            continue
        assert cand.sim_result == SIM_HELD
        assert np.array_equal(cand.squeeze_positions, firm)
        replay = real(hand, obj, np.eye(4), cand.wrist_pose, cand.pre_grasp_positions, cand.joint_positions,
                      cand.squeeze_positions, table, 0.5)
        assert replay.held


def test_the_replys_squeeze_holds_under_servos_stiffer_than_the_checks(hands):
    """A squeeze is a posture: the force it makes is the gain of the servos that run it
    times its offset. DexGraspBench runs a reply at 5 N m/rad, 2.5 times this check's gain,
    so the squeeze aims at SimulationSettings.squeeze_force (2.4 N) here and the same
    posture must hold at both gains. The Allegro-like hand's barrel (seed 1) is a grasp the
    4 N squeeze turned out of the hand at the stiffer gain (19 degrees; held at 2.4 N,
    bench/held_rate.py --dexgraspbench)."""
    from dataclasses import replace

    from grasp_apso.simulation.any_hand import simulate_any_hand
    from grasp_apso.simulation.settings import SimulationSettings

    hand, obj = hands["allegro"], builtin("barrel")
    table = Scene.table_under(np.asarray(obj.mesh.vertices))
    cand = plan(obj, options=PlanOptions(), rng=np.random.default_rng(1), hand=hand, scene=table).candidates[0]
    assert np.any(cand.squeeze_positions != cand.joint_positions)  # squeezed
    for kp in (SimulationSettings().kp, 5.0):
        result = simulate_any_hand(hand, obj, np.eye(4), cand.wrist_pose, cand.pre_grasp_positions,
                                   cand.joint_positions, cand.squeeze_positions, table, 0.5,
                                   settings=replace(SimulationSettings(), kp=kp))
        assert result.held, (kp, result.per_direction)
        assert np.degrees(result.max_turn) < 12.0, kp  # 4 N: 15 and 19 degrees


def test_paper_hand_result_names_its_hand():
    import hashlib

    from grasp_apso.model.hand import default_hand_path

    result = plan(builtin("cube"), options=PlanOptions(particles=8, iterations=2, neighborhood_size=4),
                  rng=np.random.default_rng(0))
    assert result.hand_name == "apso_paper_hand"
    assert result.hand_hash == hashlib.sha256(default_hand_path().read_bytes()).hexdigest()


def test_a_second_search_goes_on_counting_the_progress(hands):
    """A plan whose first search's best grasp is not balanced robust force closure searches
    again (``ANALYTIC_ROUNDS``): the progress goes on from the first search's iterations,
    evaluations and time, and the result's history and ``iterations_run`` count both
    searches' iterations once (as the node's feedback promises: 1 .. iterations_run)."""
    from grasp_apso.search.any_hand_planner import UNBALANCED_ROUNDS, analytic_iterations

    options = PlanOptions(particles=12, iterations=10, max_grasps=2)
    first, second = analytic_iterations(0, options.iterations), analytic_iterations(1, options.iterations)
    assert (first, second) == (7, 5)
    counts = {first + k * second for k in range(UNBALANCED_ROUNDS)}
    rounds = set()
    for seed in range(4, 8):  # iterations_run 22, 12, 12, 22 (measured)
        obj = builtin("barrel")
        seen = []
        result = plan(obj, options=options, rng=np.random.default_rng(seed), hand=hands["inspire"],
                      scene=Scene.table_under(np.asarray(obj.mesh.vertices)), progress=seen.append)
        assert [s.iteration for s in seen] == list(range(1, result.iterations_run + 1))
        assert [s.iteration for s in result.history] == [s.iteration for s in seen]
        assert all(b.evaluations > a.evaluations and b.elapsed >= a.elapsed for a, b in zip(seen, seen[1:]))
        assert result.evaluations >= seen[-1].evaluations
        assert result.iterations_run in counts  # more than two searches: none found a balanced grasp before
        rounds.add(result.iterations_run)
    assert first + second in rounds  # a second search ran in at least one plan


def test_searches_go_on_while_none_found_a_balanced_grasp(hands, monkeypatch):
    """Without ``simulate`` a plan searches a third and a fourth time while no search found
    a balanced robust force-closure grasp (``UNBALANCED_ROUNDS``): the large marker lying on
    a table, which no hand pinches in force closure above the clearance
    (docs/any-hand-measurements.md), runs every search; the sphere, whose first search found
    force closure that is not balanced and whose second found nothing above it, searches a
    third time, finds a balanced grasp and stops there (up to 2026-12-07 it stopped after
    two searches with the unbalanced grasp). A plan without force closure says so in its
    ``candidates_message``."""
    from grasp_apso.search import any_hand_planner
    from grasp_apso.search.any_hand_planner import (ANALYTIC_ROUNDS, BALANCED_CLASS, CLOSURE_CLASS,
                                                    UNBALANCED_ROUNDS, analytic_iterations)

    assert UNBALANCED_ROUNDS > ANALYTIC_ROUNDS
    options = PlanOptions(particles=12, iterations=10, max_grasps=2)
    first, second = analytic_iterations(0, options.iterations), analytic_iterations(1, options.iterations)
    marker = _object("large_marker")
    result = plan(marker, options=options, rng=np.random.default_rng(0), hand=hands["inspire"],
                  scene=Scene.table_under(np.asarray(marker.mesh.vertices)))
    assert not any(c.force_closure for c in result.candidates)
    assert result.iterations_run == first + (UNBALANCED_ROUNDS - 1) * second
    # the reply says so (the CLI and the node's message carry it), with the searches run
    assert f"no force-closure grasp: {UNBALANCED_ROUNDS} searches found none" in result.candidates_message

    classes = []  # the best class after each search that verified grasps
    real = any_hand_planner.best_class
    monkeypatch.setattr(any_hand_planner, "best_class", lambda checked: classes.append(real(checked)) or classes[-1])
    sphere = builtin("sphere")
    result = plan(sphere, options=options, rng=np.random.default_rng(5), hand=hands["inspire"],
                  scene=Scene.table_under(np.asarray(sphere.mesh.vertices)))
    # force closure, not balanced; the second search found nothing above it; the third a balanced grasp
    assert classes == [CLOSURE_CLASS, BALANCED_CLASS]
    assert result.iterations_run == first + 2 * second
    best = result.candidates[0]
    assert best.force_closure and "no force-closure grasp" not in result.candidates_message
    assert _reply_robust_epsilon(sphere, best, options) > 0.0


def test_a_second_search_adds_to_the_first_searchs_grasps(hands, monkeypatch):
    """The second search's verified grasps join the first's and the ranking takes the best
    of both: every returned grasp was verified by one of the two searches, the second
    search verified only grasps that rank above the first's best class (its floor), and
    the best returned grasp is in the highest class of both searches' grasps."""
    from grasp_apso.search import any_hand_planner
    from grasp_apso.search.any_hand_select import select_any

    calls = []

    def recording(*args, **kwargs):
        prior = args[8] if len(args) > 8 else kwargs.get("prior", ())
        checked, message = select_any(*args, **kwargs)
        calls.append((tuple(prior), list(checked)))
        return checked, message

    monkeypatch.setattr(any_hand_planner, "select_any", recording)
    obj = builtin("sphere")
    options = PlanOptions(particles=20, iterations=10, max_grasps=5)

    def rank_class(c):
        return 3 if c.balanced else 2 if c.force_closure else int(c.valid)

    # The first seeds (bounded) until a plan's first search has no balanced robust
    # force-closure grasp of the sphere, so that a second search runs for that (seed 1 with
    # the Allegro-like hand and a swarm of 20 x 10; with the default swarm the first search
    # found one in each of seeds 0-39, with 12 x 10 the plans of seeds 0-9 searched four times
    # or found nothing in the second search): most first searches find one (a second search that adds
    # more of them: test_a_second_search_runs_while_fewer_balanced_grasps_than_asked_for).
    for seed in range(SECOND_SEARCH_SEEDS):
        calls.clear()
        result = plan(obj, options=options, rng=np.random.default_rng(seed), hand=hands["allegro"],
                      scene=Scene.table_under(np.asarray(obj.mesh.vertices)))
        if len(calls) == 2 and max(rank_class(c) for c in calls[0][1]) < 3:
            break
    assert len(calls) == 2, "no plan searched twice"
    (first_prior, first), (prior, union) = calls
    assert first_prior == ()
    assert [id(c) for c in prior] == [id(c) for c in first]

    new = [c for c in union if all(c is not p for p in prior)]
    assert new, "the second search found grasps above the first's"
    floor = max(rank_class(c) for c in prior)
    assert all(rank_class(c) > floor for c in new)

    def verified(cand):
        return next(c for c in union if np.allclose(c.decoded.root[0], cand.wrist_in_object))

    assert all(any(np.allclose(cand.wrist_in_object, c.decoded.root[0]) for c in union) for cand in result.candidates)
    assert rank_class(verified(result.candidates[0])) == max(rank_class(c) for c in union)


def test_the_analysed_grasps_are_capped_by_groups_of_like_wrists():
    """A swarm converged on one grasp leaves many near copies of it in the selection's pool:
    the cap on the grasps analysed counts groups of like wrists, so the distinct grasps
    after the copies are still analysed (capped by rows, only the copies were)."""
    from grasp_apso.search.any_hand_select import _first_groups

    rng = np.random.default_rng(4)
    wrist = np.tile(np.eye(4), (60, 1, 1))
    wrist[:40, :3, 3] = rng.normal(0.0, 1e-4, (40, 3))            # 40 copies of one wrist
    wrist[40:, :3, 3] = 0.05 * np.arange(1, 21)[:, None] * np.array([1.0, 0.0, 0.0])  # 20 distinct ones
    options = PlanOptions()
    rows, groups = _first_groups(list(range(60)), wrist, 8, options)
    assert rows == list(range(40)) + list(range(40, 47))  # the copies, then 7 other groups' leaders
    assert groups == 8  # the distinct grasps the reply's message counts
    assert _first_groups(list(range(40, 43)), wrist, 8, options)[1] == 3  # fewer groups than the cap


def test_fewer_grasps_than_asked_for_say_what_became_of_the_others(hands, monkeypatch):
    """When fewer candidates than ``max_grasps`` come back, the message counts what the
    searches' selections saw, summed over the searches whose grasps are ranked together:
    the distinct grasps with two or more contacts, those that failed verification and
    those left out below the returned ones' class; and the counts add up (the returned,
    rejected and left-out grasps are distinct grasps the searches found). The Inspire's
    mug, seed 0: one robust grasp of five asked for, after two searches."""
    import re

    from grasp_apso.search import any_hand_planner
    from grasp_apso.search.any_hand_select import select_any

    selections = []

    def recording(*args, **kwargs):
        checked, selection = select_any(*args, **kwargs)
        selections.append(selection)
        return checked, selection

    monkeypatch.setattr(any_hand_planner, "select_any", recording)
    obj = _object("mug")
    result = plan(obj, options=PlanOptions(max_grasps=5), rng=np.random.default_rng(0), hand=hands["inspire"],
                  scene=Scene.table_under(np.asarray(obj.mesh.vertices)))
    n = len(result.candidates)
    assert n < 5
    found = re.search(r"^(\d+) of 5 grasps: (\d+) searches found (\d+) distinct grasps with two or more contacts "
                      r"\(wrists the orientation or position gap apart\); of those verified, (\d+) failed \(legality, "
                      r"contacts, the scene and the approach\)(?:, (\d+) were not \(robust\) force closure next to "
                      r"ones that are \(left out\))?; ", result.candidates_message)
    assert found, result.candidates_message
    returned, searches, distinct, rejected, left_out = (int(g or 0) for g in found.groups())
    assert (returned, searches) == (n, len(selections))
    assert distinct == sum(s.counts.distinct for s in selections)
    assert rejected == sum(s.counts.rejected for s in selections)
    assert left_out == sum(s.counts.fallback for s in selections)
    assert distinct >= returned + rejected + left_out
    assert all(c.force_closure for c in result.candidates)


def test_a_second_search_runs_while_fewer_balanced_grasps_than_asked_for(hands, monkeypatch):
    """Without ``simulate`` a plan whose first search verified some balanced robust
    force-closure grasps, but fewer than ``max_grasps``, searches a second time and no
    more; the second search verifies only balanced grasps (the first's best class), and
    the plan returns more of them than the first search had. A first search with
    ``max_grasps`` balanced grasps is the only one."""
    from grasp_apso.search import any_hand_planner
    from grasp_apso.search.any_hand_select import select_any

    calls = []

    def recording(*args, **kwargs):
        checked, selection = select_any(*args, **kwargs)
        calls.append(list(checked))
        return checked, selection

    monkeypatch.setattr(any_hand_planner, "select_any", recording)
    options = PlanOptions(max_grasps=5)
    seen = set()
    # bounded: until both kinds of plan were seen (the mug's seed 1: 1 balanced grasp, then
    # 3; the cube's seed 0: 5 in the first search)
    for name, seed in [(name, seed) for seed in range(SECOND_SEARCH_SEEDS) for name in ("mug", "cube")]:
        obj = _object(name)
        calls.clear()
        result = plan(obj, options=options, rng=np.random.default_rng(seed), hand=hands["inspire"],
                      scene=Scene.table_under(np.asarray(obj.mesh.vertices)))
        balanced = [sum(c.balanced for c in checked) for checked in calls]
        if balanced[0] >= options.max_grasps:
            assert len(calls) == 1
            seen.add("enough")
        elif balanced[0] > 0:
            assert len(calls) == 2, balanced  # one more search, not the four of a plan without any
            first_ids = {id(c) for c in calls[0]}
            new = [c for c in calls[1] if id(c) not in first_ids]
            assert all(c.balanced for c in new)
            assert len(result.candidates) == min(options.max_grasps, len(calls[1]))
            if new:
                assert len(result.candidates) > min(options.max_grasps, balanced[0])
                seen.add("more")
        if {"enough", "more"} <= seen:
            break
    assert {"enough", "more"} <= seen, seen


def test_a_plan_whose_force_closure_is_not_robust_says_so(hands):
    """A plan whose best grasps are force closure only without the normals' spread (robust
    epsilon 0: contacts on the bowl's rim) says so in its message, with how such grasps
    held; a plan with a robust grasp (the cube) does not. The Shadow's bowl, seed 1 (seed
    0's best grasp is not force closure at all)."""
    from grasp_apso.search.any_hand_planner import FRAGILE_HELD, UNBALANCED_ROUNDS

    options = PlanOptions(particles=30, iterations=20, max_grasps=2)
    bowl = _object("bowl")
    result = plan(bowl, options=options, rng=np.random.default_rng(1), hand=hands["shadow"],
                  scene=Scene.table_under(np.asarray(bowl.mesh.vertices)))
    best = result.candidates[0]
    assert best.force_closure
    assert _reply_robust_epsilon(bowl, best, options) == 0.0  # independent: from the reply's contacts
    assert (f"no robust force-closure grasp: {UNBALANCED_ROUNDS} searches found force closure only"
            in result.candidates_message)
    assert FRAGILE_HELD in result.candidates_message
    cube = builtin("cube")
    result = plan(cube, options=options, rng=np.random.default_rng(0), hand=hands["shadow"],
                  scene=Scene.table_under(np.asarray(cube.mesh.vertices)))
    assert _reply_robust_epsilon(cube, result.candidates[0], options) > 0.0
    assert "robust force-closure" not in result.candidates_message
