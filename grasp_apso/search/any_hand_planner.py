"""Planning with a general hand (:class:`grasp_apso.model.hands.HandModel`), next to the
paper hand's path: :func:`grasp_apso.search.planner.plan` comes here when ``hand`` is one.

The swarm (:func:`grasp_apso.search.swarm.run_swarm`) optimises particles of the hand's
layout (:mod:`grasp_apso.geometry.any_hand_tables`) decoded by
:mod:`grasp_apso.geometry.any_hand_decoder`, scored by the paper's fitness
(:func:`grasp_apso.quality.fitness.evaluate` over F fingers); GRG is
:mod:`grasp_apso.search.any_hand_grg`; the leaders' archive offers the distinct
candidates, verified and ranked in :mod:`grasp_apso.search.any_hand_select`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from ..errors import InputError, PlanningError
from ..geometry.any_hand_decoder import AnyDecoded, AnyHandModel, decode_any, make_any_hand_model, with_any_scene
from ..geometry.contact_settings import ContactSettings
from .archive import LeaderArchive
from .any_hand_grg import AnyHandGenerator
from .any_hand_select import best_class, build_result, select_any
from .selection_report import SelectionCounts, append_note, shortfall_message
from .grg import classify_shape
from .options import PlanOptions
from .problem import ARCHIVE_FACTOR, SwarmProblem
from .result import SIM_HELD, SIM_NOT_RUN
from .swarm import IterationStats, run_swarm

__all__ = ["AnyHandProblem", "plan_any_hand", "prepare_any_hand", "warm_up_any_hand", "SIMULATED_ROUNDS",
           "ANALYTIC_ROUNDS", "TURNED_ROUNDS_FROM", "analytic_iterations"]

#: With ``simulate``, searches run at most this many times: another search (the generator
#: goes on, so other grasps) when none of a round's verified grasps held in the simulation.
#: Measured on the Allegro hand, 6 hard objects on a table, 3 seeds: a seed whose best grasp
#: dropped often had another that held (gelatin box 1 of 3, bowl 1 of 3, orange 2 of 3).
#: The later searches run only for plans that have no held grasp yet (a plan that held is
#: the same whatever this bound): ``bench/held_rate.py --seeds 3 --simulate``, the plans
#: whose best grasp dropped with 2 (the bowl, the large marker, the screwdriver, Inspire's
#: master chef can), searched up to 8 times: held at search 3 (Shadow's screwdriver seed 0;
#: the Allegro-like's bowl seeds 0 and 1, screwdriver seed 1), 4 (Inspire's master chef can
#: seed 1, the Allegro-like's screwdriver seed 2), 5 (Shadow's screwdriver seed 2) and 6
#: (Inspire's bowl seed 0); none at 7 or 8. Best grasps held, 63 plans each: Shadow 54 -> 56,
#: Inspire 56 -> 58, Allegro-like 56 -> 60. A plan that never holds (the large marker, the
#: bowl) takes longer: the slowest plans 3.7 -> 9.4 s (Shadow), 5.5 -> 12.5 s (Inspire),
#: within the request's time bound (``should_stop`` between searches). For a long object
#: (:attr:`~grasp_apso.search.grg.ShapeClass.long`) two more searches with its guidance
#: turned (:data:`TURNED_ROUNDS_FROM`): 6 -> 8; other objects stop at
#: :data:`TURNED_ROUNDS_FROM` searches (more of the same searches held none, above).
SIMULATED_ROUNDS = 8
#: With ``simulate``, the searches from this one on (0: the first) turn a long object's
#: guidance (:meth:`~grasp_apso.search.grg.ShapeClass.turned`: the fingers along it, the
#: thumb's opposition across it). The paper's guidance lays a long object along palm y,
#: the axis along which a five-fingered hand's thumb opposes the other fingers (51-84
#: degrees from palm x on the Shadow, Inspire, Allegro, LEAP and Ability hands), so a pinch
#: across a lying screwdriver is never drawn. Only plans whose first six searches held
#: nothing reach these searches (the others are as before). Measured
#: (``bench/held_rate.py --seeds 3 --first-seed 3 --simulate``): the Shadow's screwdriver
#: held in 0 of 3 plans -> 3 of 3; turning every other search instead of adding two
#: (which moves the draws of the later searches) gave Shadow 54 -> 56, Inspire 57 -> 56,
#: Allegro-like 60 -> 58 best grasps of 63.
TURNED_ROUNDS_FROM = 6
#: Without ``simulate``, searches run at least this many times while fewer than
#: ``max_grasps`` of the verified grasps are balanced robust force closure
#: (:attr:`~grasp_apso.search.any_hand_select.AnyChecked.balanced`); a later search's
#: verified grasps join the earlier ones', ranked together, and it verifies only grasps that
#: can rank above their best class (``select_any``'s ``prior``). Measured
#: (``bench/held_rate.py --seeds 3 --hand allegro_like``, 63 plans on a table): balanced
#: best grasps held 43 of 48, the others 2 of 15; with the hold score ranking, best grasp
#: held 47/63 with one search, 51/63 with two (the extra search ran for the hard plans
#: only: thin objects lying flat, the bowl's rim). The second search also runs when the
#: first found some balanced grasps but fewer than asked for (2026-12-07, third): a client
#: asking for five got five in 16 of LEAP's 63 plans and 31 of the Shadow's (dex-urdf),
#: 36 and 45 now (``bench/held_rate.py --seeds 3 --dexgraspbench``; 13 hands: 564 -> 642 of
#: 819), the candidates held with DexGraspBench's parameters 168 / 200 -> 208 / 245 and
#: 209 / 233 -> 249 / 273, the best grasps held as before (53 and 57 of 63; 13 hands 662 ->
#: 664); LEAP's median plan 2.0x -> 3.3x the paper hand's, the test hands' 1.5-1.6x
#: (``bench/bench_any_hand.py``). Searching on to four times for them gave 45 and 55 plans
#: of five, the best grasps as now, LEAP's median plan 5.6x (docs/any-hand-measurements.md,
#: "The stop of 2026-12-07, third").
ANALYTIC_ROUNDS = 2
#: ... and up to this many while none of the rounds' verified grasps is balanced robust force
#: closure (a later round verifies only grasps above the earlier rounds' best class, so
#: these rounds only add balanced ones): a plan whose first two searches found one is as
#: before, draw for draw. Best grasps by their robust epsilon, 399 plans of seven hands
#: (``bench/held_rate.py --seeds 3 --dexgraspbench``): robust epsilon 0 held 10 % in our
#: check (30 % with DexGraspBench's parameters), below 0.01 64 % (84 %), 0.02 and above
#: 90-100 % (97-100 %). Measured (``bench/held_rate.py --seeds 3 --dexgraspbench``, 13 hands,
#: 819 plans on a table, by default), against up to four searches only while none found
#: force closure (2026-12-06): best grasps held 580 -> 589 in our check and 656 -> 662 with
#: DexGraspBench's parameters, 645 -> 663 of them robust; the Schunk SVH 25 / 36 -> 28 / 38;
#: one plan (the DFQ's mug) holds less with DexGraspBench's parameters, none in ours
#: (docs/any-hand-measurements.md, "The stop of 2026-12-07, second"). Six searches instead:
#: 147 / 180 -> 146 / 181 on four of the weaker hands. The rule it replaced (up to four only
#: while none found force closure) had raised the best grasps in force closure 436 -> 451
#: of 504 on eight test hands and 403 -> 409 of 441 on seven published ones.
UNBALANCED_ROUNDS = 4
#: Without ``simulate``, the first search runs this fraction of the iterations (the swarm's
#: best is still rising slowly by then; a second search, when needed, looks elsewhere).
#: Measured (``bench/held_rate.py --seeds 3``, 11 hands, 693 plans on a table): best grasps
#: held 488 with the full first search, 484 with 0.7 (per hand -4..+3, within the seeds'
#: spread); ``bench/bench_any_hand.py --runs 5``: Shadow 3.0x -> 2.5x of the paper hand's
#: plan time, Inspire 2.7x -> 2.1x, Allegro-like 2.7x -> 2.2x, LEAP 3.5x -> 2.7x.
ANALYTIC_FIRST_ITERATIONS = 0.7
#: ... and a second search this fraction.
ANALYTIC_RETRY_ITERATIONS = 0.5
#: In this share of a search's iterations (the first ones) APSO's social term pulls each
#: particle toward its neighbourhood's best, not the swarm's
#: (:func:`~grasp_apso.search.swarm.run_swarm`'s ``local_best``); then toward the swarm's.
#: With the swarm's best throughout, the Allegro-like hand's first search on the sphere
#: ended on two-finger pinches (fitness at most 0.575, no force closure) in 8 of 10 seeds,
#: the whole swarm drawn into the first pinch it found; with 0.4, in none of seeds 0-5
#: (force-closure tripods, fitness 0.63-0.86). With the neighbourhood's best throughout
#: (1.0), the same six seeds gave force closure in four, but the grasps, less refined, held
#: less often (``bench/held_rate.py --seeds 3``: Shadow 46 -> 43 best grasps of 63 and
#: 210 -> 162 candidates, Inspire 45 -> 42, Allegro-like 48 -> 46).
LOCAL_BEST = 0.4
#: How often best grasps in force closure without a robust epsilon held (the plan's message
#: says it): ``bench/held_rate.py --seeds 3 --dexgraspbench``, 13 hands, 21 objects on a
#: table, the stop of 2026-12-07, second: 25 of 156 with DexGraspBench's parameters.
FRAGILE_HELD = "of 156 such best grasps, 25 held in DexGraspBench's MuJoCo test"
#: The class of a balanced robust force-closure grasp in :func:`~.any_hand_select.best_class`.
BALANCED_CLASS = 3
#: ... and of a force-closure grasp.
CLOSURE_CLASS = 2


class AnyHandProblem(SwarmProblem):
    """The optimisation problem of one plan with a general hand (the swarm's ``Problem``):
    its decoder and GRG (:class:`~grasp_apso.search.problem.SwarmProblem` holds the rest)."""

    def make_generator(self, rng: np.random.Generator, should_stop: Callable[[], bool] | None) -> AnyHandGenerator:
        return AnyHandGenerator(self.model, self.shape, rng, self.wrist_position, should_stop)

    def decode(self, x: np.ndarray) -> AnyDecoded:
        return decode_any(self.model, x, self.wrist_position)


def prepare_any_hand(obj, hand, options: PlanOptions) -> AnyHandModel:
    """The model of ``obj`` with ``hand`` (grids and tables cached)."""
    extents = np.asarray(obj.principal_extents, dtype=float)
    if extents[0] < 0.005:
        raise PlanningError(f"object: too small for a precision grasp: its largest extent is {extents[0] * 1000:.1f} mm")
    return make_any_hand_model(hand, obj, ContactSettings(tolerance=options.contact_tolerance))


def plan_any_hand(obj, pose: np.ndarray, options: PlanOptions, rng: np.random.Generator, hand,
                  progress: Callable[[IterationStats], None] | None, should_stop: Callable[[], bool] | None,
                  scene_obj, scene) -> "GraspResult":  # noqa: F821
    """The general hand's plan; arguments as :func:`grasp_apso.search.planner.plan`
    (``scene_obj``: the scene in the object frame, or None; ``scene`` as given)."""
    if options.wrist_position is not None and np.shape(options.wrist_position) != (3,):
        raise InputError("wrist_position: expected (3,)", "wrist_position")
    t0 = time.perf_counter()
    model = prepare_any_hand(obj, hand, options)
    shape = classify_shape(obj)
    if scene_obj is not None:
        model = with_any_scene(model, scene_obj, options.clearance, options.approach_distance)
        if len(scene_obj.planes):
            shape = shape.with_support(scene_obj.planes[:, :3])
    preparation = time.perf_counter() - t0
    t1 = time.perf_counter()
    first, first_class, evaluations = None, -1, 0
    first_checked: tuple = ()
    if options.simulate:
        rounds = SIMULATED_ROUNDS if shape.long else TURNED_ROUNDS_FROM
    else:
        rounds = max(ANALYTIC_ROUNDS, UNBALANCED_ROUNDS)
    # the iterations of the rounds so far, their progress (numbered on) and the searches run
    done, history, searches = 0, [], 0
    counts = SelectionCounts()  # without simulate, over the rounds whose grasps are ranked together
    note = ""  # the best grasp's note (its selection's)
    for round_ in range(rounds):
        if not options.simulate and round_ >= ANALYTIC_ROUNDS and first_class >= BALANCED_CLASS:
            break  # past ANALYTIC_ROUNDS only while no search found balanced robust force closure
        searches = round_ + 1
        # A later round's progress goes on from the earlier rounds' (iteration, evaluations,
        # elapsed): the progress topic and the result's history count every iteration once.
        shift = _Shift(done, evaluations, time.perf_counter() - t1)
        round_progress = None if progress is None else (lambda stats, _s=shift: progress(_s(stats)))
        archive = LeaderArchive(ARCHIVE_FACTOR * options.max_grasps, options.min_orientation_gap,
                                options.min_position_gap)
        round_shape = shape.turned() if options.simulate and round_ >= TURNED_ROUNDS_FROM else shape
        problem = AnyHandProblem(model, round_shape, options, rng, archive, should_stop)
        swarm_options = options.swarm_options()
        if not options.simulate:
            swarm_options = replace(swarm_options, iterations=analytic_iterations(round_, options.iterations))
        swarm = run_swarm(problem, swarm_options, rng, options.algorithm == "apso", round_progress, should_stop,
                          local_best=LOCAL_BEST)
        evaluations += problem.evaluations
        history.extend(shift(stats) for stats in swarm.history)
        done += swarm.iterations_run
        # A later round without simulate adds to the first round's verified grasps (the
        # ranking takes the best of both), verifying only grasps that can rank above them.
        prior = first_checked if (first is not None and not options.simulate) else ()
        try:
            checked, selection = select_any(model, problem, swarm, archive, options, pose, obj, scene, prior)
        except PlanningError:
            if first is None and (round_ + 1 == rounds or swarm.cancelled):
                raise
            continue
        # with simulate a round's result stands alone; otherwise it ranks every round's grasps
        counts = selection.counts if options.simulate else counts + selection.counts
        if selection.unchanged:  # a later search without a grasp to add: the earlier result stands
            first = replace(first, candidates_message=_message(len(checked), options, counts, searches, note))
            continue
        note = selection.note
        message = _message(len(checked), options, counts, 1 if options.simulate else searches, note)
        result = build_result(model, checked, message, swarm, problem, options, pose, shape, preparation, t1, obj,
                              scene, should_stop)
        if options.simulate:
            if any(c.sim_result == SIM_HELD for c in result.candidates):
                first = result
                break
            # none held: the round of the best class (force closure over none), the earlier
            # of equal ones
            klass = best_class(checked)
            if first is None or klass > first_class:
                first, first_class = result, klass
            if all(c.sim_result == SIM_NOT_RUN for c in result.candidates) and (
                    first_class >= BALANCED_CLASS or round_ + 1 >= UNBALANCED_ROUNDS):
                # The simulation did not run (MuJoCo refused the hand: the reply says why);
                # later rounds could not hold either: searched on only as without
                # ``simulate`` (while no balanced robust force-closure grasp was found).
                break
        else:
            first, first_class, first_checked = result, best_class(checked), tuple(checked)
            balanced = sum(c.valid and c.balanced for c in checked)
            if balanced >= options.max_grasps or (first_class >= BALANCED_CLASS and searches >= ANALYTIC_ROUNDS):
                break
        if swarm.cancelled or (should_stop is not None and should_stop()):
            break
    # simulate: a round with a grasp that held, else the first round of the best class;
    # otherwise the grasps of every round, ranked together
    message = first.candidates_message
    if not options.simulate and first_class < CLOSURE_CLASS and not first.cancelled:
        # candidates without force closure, as many as asked for, would not say so: why, and what may help
        where = " from the free side of the scene" if scene_obj is not None else ""
        message = append_note(message, (
            f"no force-closure grasp: {searches} searches found none with hand {hand.name!r} (its fingers may not "
            f"oppose across this object{where}); another seed, more particles or iterations, or simulate (each "
            "grasp checked in MuJoCo) may find one"))
    elif not options.simulate and not first.cancelled and not any(c.robust_closure for c in first_checked):
        # force closure only where the normals' spread undoes it: such best grasps seldom hold
        message = append_note(message, (
            f"no robust force-closure grasp: {searches} searches found force closure only with contacts where the "
            f"surface normals' spread (an edge, a rim, a thin wall) undoes it (robust epsilon 0: {FRAGILE_HELD}); "
            "another seed, more particles or iterations, or simulate may find a firmer one"))
    return replace(first, evaluations=evaluations, iterations_run=done, history=tuple(history),
                   planning_time=time.perf_counter() - t1, candidates_message=message)


def _message(returned: int, options: PlanOptions, counts, searches: int, note: str) -> str:
    """The reply's candidates message: why fewer than asked for (if so), then the best grasp's note."""
    return append_note(shortfall_message(returned, options, counts, searches), note)


def analytic_iterations(round_: int, iterations: int) -> int:
    """The iterations of search ``round_`` (0: the first) without ``simulate``, from the
    requested ``iterations``: :data:`ANALYTIC_FIRST_ITERATIONS` of them for the first,
    :data:`ANALYTIC_RETRY_ITERATIONS` for a later one; at least 1."""
    share = ANALYTIC_RETRY_ITERATIONS if round_ else ANALYTIC_FIRST_ITERATIONS
    return max(1, int(share * iterations))


@dataclass(frozen=True)
class _Shift:
    """Renumbers a later round's :class:`IterationStats` after the rounds before it."""

    iterations: int
    evaluations: int
    elapsed: float

    def __call__(self, stats: IterationStats) -> IterationStats:
        return replace(stats, iteration=stats.iteration + self.iterations, iterations=stats.iterations + self.iterations,
                       evaluations=stats.evaluations + self.evaluations, elapsed=stats.elapsed + self.elapsed)


def warm_up_any_hand(hand) -> float:
    """Load (or, once after an install, compile: about 20 s) the general hand's kernels and
    build the hand's tables before its first plan: a tiny plan of the built-in cube on a
    table. The node calls it for a configured general hand as it calls
    :func:`grasp_apso.search.planner.warm_up` for the paper hand. Returns the seconds it took."""
    from ..model.builtin import builtin
    from ..model.scene import Scene

    t0 = time.perf_counter()
    cube = builtin("cube")
    table = Scene.table_under(np.asarray(cube.mesh.vertices))
    options = PlanOptions(particles=4, iterations=1, neighborhood_size=2, max_grasps=1)
    try:
        plan_any_hand(cube, np.eye(4), options, np.random.default_rng(0), hand, None, None, table, table)
    except PlanningError:
        pass  # the kernels ran; a tiny swarm may find no grasp
    return time.perf_counter() - t0
