"""Command line ``grasp_apso_plan``: plan a precision grasp without ROS, print it, draw it.

Examples::

    grasp_apso_plan                                   # APSO on the built-in sphere
    grasp_apso_plan --object fish --table             # the fish resting on a table
    grasp_apso_plan --object cube --table --obstacle box:0.08,0,0,0.04,0.2,0.1 --grasps 5
    grasp_apso_plan --object fish --algorithm both --seed 3
    grasp_apso_plan --mesh part.stl --mesh-scale 0.001 --json grasp.json

It prints a header (object, scene, algorithm, swarm size, seed), a progress bar while
planning (on a terminal; otherwise one line every 10 iterations, on stderr), then the hand
configuration Cg with the Table 2 limits, the wrist pose and the approach, the contacts and
the quality figures; with ``--grasps K`` a table of the ranked candidates; with
``--algorithm both`` it runs APSO and the simple PSO with the same seed and compares them.
Pictures go to ``--out`` (default ``./grasp_apso_out/``): ``<object>_<algorithm>_grasp.png``
(hand, object, table, obstacles, approach arrow and the faint pre-grasp hand; two views),
``<object>_<algorithm>_candidates.png`` (one panel per candidate, with ``--grasps`` > 1) and
``<object>_convergence.png``. ``--json FILE`` writes a machine-readable summary (SI units:
metres, radians, seconds) with every candidate.

The scene (``--table``, ``--obstacle``) is in the planning frame, which on the command line
is the object's own frame (metres); obstacle formats: :mod:`grasp_apso.tools.cli_inputs`.

Exit status: 0 when the plan ran (check ``valid`` in the output or the JSON: a plan can
end without a valid grasp), 2 for bad input (unknown object, unreadable mesh, invalid
option or obstacle, object the hand cannot grasp), 130 when interrupted before any result.
Ctrl-C during planning stops the swarm at the end of the current iteration and reports
the best grasp so far; a second Ctrl-C aborts.

Also runnable as ``python -m grasp_apso.tools.cli``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from typing import Any, Sequence

import numpy as np

from ..errors import GraspApsoError, ObjectTooLargeError, UsageError
from ..model import builtin as builtin_objects
from ..model import objects
from ..model.planning_hand import load_planning_hand
from ..search.planner import GraspResult, PlanOptions, plan, warm_up
from ..tunables import default
from .cli_inputs import (OBSTACLE_FORMATS, algorithms, build_scene, cli_message, finite_number, load_object,
                         safe_name, source_option, whole_number)
from .cli_progress import Interrupt, Progress
from .export import result_to_dict, scene_to_dict
from ..presentation.summary import format_candidates, format_comparison, format_report, summary_line

PROG = "grasp_apso_plan"
DEFAULT_OUT = "grasp_apso_out"
#: Printed under the candidate table, whose rank column counts from 1 for reading.
RANK_NOTE = ("  rank: 1 = best here; --json, the Python API (GraspCandidate.rank) and the ROS reply "
             "count from 0 (rank 1 = candidates[0])")


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, no usage dump
        raise UsageError(f"{message} (see {PROG} --help)")


def build_parser() -> argparse.ArgumentParser:
    """The option parser (``--help`` documents every option and the obstacle format)."""
    parser = _Parser(
        prog=PROG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Plan a precision (fingertip) grasp for a multi-fingered hand (the paper's, or any URDF / MJCF hand: --hand) with APSO "
                    "(adaptive particle swarm + guided random generation) or the simple PSO, "
                    "without ROS. Prints the hand configuration and the grasp quality and "
                    "draws the grasp and the convergence of the swarm.",
        epilog="Scene: positions and sizes in metres in the planning frame (= the object's frame "
               "here).\n  --obstacle " + "\n  --obstacle ".join(f[2] for f in OBSTACLE_FORMATS.values())
               + "\n  e.g. --object cube --table --obstacle box:0.08,0,0,0.04,0.2,0.1\n"
               "Units: the printed tables use mm and degrees; --json uses metres and radians.\n"
               "Exit status: 0 planned (see 'valid'), 2 bad input or ungraspable object, 130 interrupted.",
    )
    src = parser.add_mutually_exclusive_group()
    src.add_argument("--object", metavar="NAME",
                     help=f"built-in object: {', '.join(builtin_objects.BUILTIN_OBJECTS)} (default: sphere)")
    src.add_argument("--mesh", metavar="FILE",
                     help=f"mesh file ({', '.join(objects.MESH_FORMATS).upper()}), coordinates in metres "
                          "(see --mesh-scale)")
    parser.add_argument("--mesh-scale", type=finite_number, default=None, metavar="S",
                        help="with --mesh: multiply the mesh coordinates by S, e.g. 0.001 for a file in mm "
                             "(default 1)")
    parser.add_argument("--algorithm", default="apso", metavar="ALG",
                        help="apso (default), pso (simple PSO baseline), or both (same seed, compared)")
    parser.add_argument("--particles", type=whole_number, default=60, metavar="N",
                        help="swarm size np, 2..1000 (default 60)")
    parser.add_argument("--iterations", type=whole_number, default=50, metavar="N",
                        help="iterations nit, 1..10000 (default 50)")
    parser.add_argument("--seed", type=whole_number, default=None, metavar="S",
                        help="random seed; the same seed gives the same grasp (default: random, printed)")
    parser.add_argument("--friction", type=finite_number, default=0.5, metavar="MU",
                        help="Coulomb friction coefficient for the fitness and epsilon, (0, 5] (default 0.5)")
    scene = parser.add_argument_group("scene, approach and candidates")
    scene.add_argument("--table", action="store_true",
                       help="the object rests on a table: a support plane (normal +z) under its lowest point; "
                            "the hand stays above it")
    scene.add_argument("--obstacle", action="append", default=[], metavar="SPEC",
                       help="an obstacle the hand never touches, repeatable: "
                            + "; ".join(f[2] for f in OBSTACLE_FORMATS.values())
                            + " (metres, planning frame; cylinder axis along z)")
    scene.add_argument("--clearance", type=finite_number, default=default("clearance"), metavar="M",
                       help=f"least distance between the hand and the table / obstacles, m "
                            f"(default {default('clearance'):g})")
    scene.add_argument("--approach-distance", type=finite_number, default=default("approach_distance"),
                       metavar="M", help="the pre-grasp wrist is this far back along the approach, m "
                                         f"(default {default('approach_distance'):g})")
    scene.add_argument("--grasps", type=whole_number, default=1, metavar="K",
                       help="ranked, distinct candidates to return, 1..50 (default 1); more than 1 prints "
                            "a table and draws one panel per candidate")
    scene.add_argument("--simulate", action="store_true",
                       help="check every candidate in the MuJoCo simulation (squeeze, then shake in six "
                            "directions): prints held / dropped, shift and turn")
    parser.add_argument("--hand", metavar="FILE", default=None,
                        help="the hand to plan with: a URDF (.urdf), MJCF (.xml) or the project's YAML (.yaml) "
                             "description (default: the shipped paper hand); check a new hand with grasp_apso_hand")
    parser.add_argument("--hand-config", metavar="FILE", default=None,
                        help="YAML overriding what is derived from the --hand description (root link, fingers, "
                             "thumb, closing senses, palm normal, pads)")
    parser.add_argument("--out", metavar="DIR", default=None,
                        help=f"folder for the pictures (default ./{DEFAULT_OUT}/)")
    parser.add_argument("--no-plots", action="store_true", help="do not draw pictures")
    parser.add_argument("--quiet", action="store_true",
                        help="no progress and no tables: one summary line per run (and the file paths)")
    parser.add_argument("--json", metavar="FILE", default=None,
                        help="write a machine-readable summary (SI units) with every candidate to FILE "
                             "in an existing folder ('-': standard output, the report then goes to "
                             "standard error)")
    return parser


def _options(args: argparse.Namespace, algorithm: str) -> PlanOptions:
    return PlanOptions(algorithm=algorithm, particles=args.particles, iterations=args.iterations,
                       friction=args.friction, clearance=args.clearance,
                       approach_distance=args.approach_distance, max_grasps=args.grasps,
                       simulate=bool(args.simulate))


def _scene_text(scene, args: argparse.Namespace) -> str:
    parts = []
    if args.table:
        parts.append(f"table (support plane, normal +z) at z = {-scene.planes[0][3] * 1000:.1f} mm, "
                     "under the object's lowest point")
    for o in scene.obstacles:
        centre = ", ".join(f"{v * 1000:.0f}" for v in o.pose[:3, 3])
        dims = " x ".join(f"{d * 1000:.0f}" for d in o.dimensions)
        parts.append(f"{o.name.lower()} at ({centre}) mm, {dims} mm")
    return "; ".join(parts) + f"; clearance {args.clearance * 1000:g} mm"


def _hand_text(planning_hand) -> str:
    hand = planning_hand.hand
    where = planning_hand.path or "shipped"
    if not hasattr(hand, "actuated_joints"):
        return f"{hand.name} ({where}): the paper's five-fingered hand, 18 joints"
    fingers = ", ".join(f.name for f in hand.fingers)
    return (f"{hand.name} ({where}): {len(hand.fingers)} fingers ({fingers}), "
            f"{len(hand.actuated_joints)} actuated joints, root link {hand.root_link}")


def _plan_all(args, algorithms_, obj, hand, scene, seed, out, err, show) -> dict[str, GraspResult]:
    """Run each algorithm with the same seed; print each report as it finishes."""
    extra: dict[str, Any] = {} if scene is None else {"scene": scene}
    up = scene.planes[0][:3] if scene is not None and len(scene.planes) else None
    results: dict[str, GraspResult] = {}
    options = {alg: _options(args, alg) for alg in algorithms_}  # all validated before planning
    warm_up()  # the compiled kernels' one-off load is not the planner's time
    with Interrupt(PROG) as interrupt:
        for alg in algorithms_:
            progress = Progress(alg.upper(), args.iterations, err, enabled=show)
            try:
                result = plan(obj, options=options[alg], rng=np.random.default_rng(seed), hand=hand,
                              progress=progress, should_stop=lambda: interrupt.stop, **extra)
            finally:
                progress.close()
            results[alg] = result
            if show:
                print(format_report(result, hand, args.friction, up=up), file=out)
                print("", file=out)
                if args.grasps > 1 or args.simulate:
                    print(format_candidates(result), file=out)
                    print(RANK_NOTE, file=out)
                    print("", file=out)
                out.flush()
            if interrupt.stop:
                break
    return results


def _pictures(args, results, obj, hand, scene, seed) -> list[str]:
    from .plotting import plot_candidates, plot_convergence, plot_grasp

    folder = args.out if args.out is not None else DEFAULT_OUT
    stem = safe_name(obj.name)
    written = []
    for alg, result in results.items():
        written.append(plot_grasp(result, obj, path=os.path.join(folder, f"{stem}_{alg}_grasp.png"),
                                  hand=hand, scene=scene))
        if args.grasps > 1 and result.candidates:
            written.append(plot_candidates(result, obj, path=os.path.join(folder, f"{stem}_{alg}_candidates.png"),
                                           hand=hand, scene=scene))
    title = (f"{obj.name}: best and mean fitness per iteration "
             f"({' vs '.join(a.upper() for a in results)}, {args.particles} particles, seed {seed})")
    written.append(plot_convergence({a.upper(): r for a, r in results.items()},
                                    path=os.path.join(folder, f"{stem}_convergence.png"), title=title))
    return written


def _write_json(args, results, obj, source, shape_name, scene, seed, written) -> None:
    doc = {
        "units": "SI: metres, radians, seconds; poses in the object frame (= planning frame)",
        "object": {"name": obj.name, "source": source, "triangles": int(len(obj.mesh.faces)),
                   "principal_extents": [float(e) for e in obj.principal_extents], "shape_class": shape_name},
        "options": {"particles": args.particles, "iterations": args.iterations, "seed": seed,
                    "friction": args.friction, "clearance": args.clearance,
                    "approach_distance": args.approach_distance, "grasps": args.grasps,
                    "simulate": bool(args.simulate), "table": bool(args.table), "obstacles": list(args.obstacle)},
        "scene": scene_to_dict(scene),
        "results": {alg: result_to_dict(r, args.friction) for alg, r in results.items()},
        "pictures": list(written),
    }
    text = json.dumps(doc, indent=2)
    if args.json == "-":
        sys.stdout.write(text + "\n")
        return
    with open(args.json, "w", encoding="utf-8") as fh:  # its folder was checked before planning
        fh.write(text + "\n")
    written.append(args.json)


def check_arguments(args: argparse.Namespace) -> None:
    """Refuse option combinations argparse cannot see, before anything is loaded or planned:
    ``--mesh-scale`` without ``--mesh``; ``--json`` into a folder that does not exist (it is
    not created) or onto a folder. Sets the default ``--mesh-scale`` (1)."""
    if args.mesh_scale is not None and args.mesh is None:
        raise UsageError("--mesh-scale: applies to --mesh FILE only (the built-in objects are in "
                         "metres already)")
    if args.mesh_scale is None:
        args.mesh_scale = 1.0
    if args.json not in (None, "-"):
        folder = os.path.dirname(os.path.abspath(args.json))
        if os.path.isdir(args.json):
            raise UsageError(f"--json: {args.json} is a folder; give a file name")
        if not os.path.isdir(folder):
            raise UsageError(f"--json: the folder {folder} does not exist (create it first)")
        if not os.access(folder, os.W_OK):
            raise UsageError(f"--json: cannot write into {folder} (permission denied)")


def _run(args: argparse.Namespace, out, err) -> int:
    check_arguments(args)
    algorithms_ = algorithms(args.algorithm)
    for alg in algorithms_:
        _options(args, alg)  # bad options fail before anything is loaded
    planning_hand = load_planning_hand(args.hand, args.hand_config)
    hand = planning_hand.hand
    obj, source = load_object(args)
    scene = build_scene(obj, args.table, args.obstacle)
    if scene is not None:
        try:  # the object inside an obstacle: refused before anything is printed
            scene.check_object_placement(np.asarray(obj.mesh.vertices, float))
        except GraspApsoError as exc:
            raise UsageError(cli_message(exc, source_option(args))) from None
    seed = args.seed
    seed_note = ""
    if seed is None:
        seed = int(np.random.SeedSequence().entropy % (2 ** 31))
        seed_note = f" (random; --seed {seed} repeats this run)"
    elif seed < 0:
        raise UsageError(f"--seed: must be >= 0, got {seed}")

    from ..search.grg import classify_shape

    shape = classify_shape(obj)
    show = not args.quiet
    if show:
        ext = " x ".join(f"{e * 1000:.0f}" for e in obj.principal_extents)
        print(f"{PROG}: precision grasp planning (no ROS)", file=out)
        print(f"  hand       {_hand_text(planning_hand)}", file=out)
        print(f"  object     {obj.name} ({source}): {len(obj.mesh.faces)} triangles, {ext} mm, "
              f"shape class {shape.name}", file=out)
        if scene is not None:
            print(f"  scene      {_scene_text(scene, args)}", file=out)
        print(f"  algorithm  {' and '.join(a.upper() for a in algorithms_)}: {args.particles} particles, "
              f"{args.iterations} iterations, seed {seed}{seed_note}, friction mu {args.friction:g}", file=out)
        if args.grasps > 1 or args.simulate:
            print(f"  grasps     up to {args.grasps} ranked candidates, approach {args.approach_distance * 1000:g} mm"
                  + (", each checked in the MuJoCo simulation" if args.simulate else ""), file=out)
        print("", file=out)
        out.flush()

    results = _plan_all(args, algorithms_, obj, hand, scene, seed, out, err, show)
    if show and len(results) > 1:
        print(format_comparison(results, seed), file=out)
        print("", file=out)
    if args.quiet:
        for result in results.values():
            print(summary_line(result, obj.name), file=out)

    written: list[str] = [] if args.no_plots else _pictures(args, results, obj, hand, scene, seed)
    if args.json is not None:
        _write_json(args, results, obj, source, shape.name, scene, seed, written)
    if written and show:
        print("Files written:", file=out)
    for path in written:
        print(f"  {path}" if show else path, file=out)
    out.flush()
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``grasp_apso_plan``; returns the exit status."""
    parser = build_parser()
    args = None
    try:
        args = parser.parse_args(argv)
        out = sys.stderr if args.json == "-" else sys.stdout
        return _run(args, out, sys.stderr)
    except UsageError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
    except GraspApsoError as exc:
        message = cli_message(exc, source_option(args))
        if isinstance(exc, ObjectTooLargeError) and args is not None and args.mesh is not None:
            message += " (is the mesh in millimetres? try --mesh-scale 0.001)"
        print(f"{PROG}: error: {message}", file=sys.stderr)
    except OSError as exc:
        print(f"{PROG}: error: {exc.filename or ''}: {exc.strerror or exc}", file=sys.stderr)
    except KeyboardInterrupt:
        print(f"\n{PROG}: interrupted", file=sys.stderr)
        return 130
    return 2


if __name__ == "__main__":
    sys.exit(main())
