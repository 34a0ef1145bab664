"""Command line ``grasp_apso_plan``: plan a precision grasp without ROS, print it, draw it.

Examples::

    grasp_apso_plan                                   # APSO on the built-in sphere
    grasp_apso_plan --object fish --algorithm both --seed 3
    grasp_apso_plan --mesh part.stl --mesh-scale 0.001 --json grasp.json

It prints a header (object, algorithm, swarm size, seed), a progress bar while planning
(on a terminal; otherwise one line every 10 iterations, on stderr), then the hand
configuration Cg with the Table 2 limits, the wrist pose, the contacts and the quality
figures; with ``--algorithm both`` it runs APSO and the simple PSO with the same seed and
compares them. Pictures go to ``--out`` (default ``./grasp_apso_out/``):
``<object>_<algorithm>_grasp.png`` (hand and object in 3-D, two views) and
``<object>_convergence.png`` (best and mean fitness per iteration). ``--json FILE``
writes a machine-readable summary (SI units: metres, radians, seconds).

Exit status: 0 when the plan ran (check ``valid`` in the output or the JSON: a plan can
end without a valid grasp), 2 for bad input (unknown object, unreadable mesh, invalid
option, object the hand cannot grasp), 130 when interrupted before any result.
Ctrl-C during planning stops the swarm at the end of the current iteration and reports
the best grasp so far; a second Ctrl-C aborts.

Also runnable as ``python -m grasp_apso.tools.cli``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import signal
import sys
import threading
from typing import Any, Sequence

import numpy as np

from ..model import objects
from ..model import poses
from ..model import mesh_files
from ..model import builtin as builtin_objects
from ..model.hand import FINGER_NAMES, JOINT_KINDS, load_hand
from ..errors import GraspApsoError, ObjectTooLargeError, UsageError
from ..search.planner import ALGORITHMS, GraspResult, PlanOptions, plan, warm_up

PROG = "grasp_apso_plan"
DEFAULT_OUT = "grasp_apso_out"
#: Iterations at which ``--algorithm both`` compares the best fitness.
COMPARE_AT = (5, 20, 50)
#: python-fcl penetration tolerance of the planner's verification (m).
FCL_TOLERANCE_MM = 1.0
_LINK_NAMES = {f: ("proximal", "middle", "distal") for f in FINGER_NAMES}
_LINK_NAMES["thumb"] = ("metacarpal", "proximal", "distal")


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, no usage dump
        raise UsageError(f"{message} (see {PROG} --help)")


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    return value


def _float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog=PROG,
        description="Plan a precision (fingertip) grasp for the five-fingered hand with APSO "
                    "(adaptive particle swarm + guided random generation) or the simple PSO, "
                    "without ROS. Prints the hand configuration and the grasp quality and "
                    "draws the grasp and the convergence of the swarm.",
        epilog="Units: the printed tables use mm and degrees; --json uses metres and radians. "
               "Exit status: 0 planned (see 'valid'), 2 bad input or ungraspable object, "
               "130 interrupted.",
    )
    src = parser.add_mutually_exclusive_group()
    src.add_argument("--object", metavar="NAME",
                     help=f"built-in object: {', '.join(builtin_objects.BUILTIN_OBJECTS)} (default: sphere)")
    src.add_argument("--mesh", metavar="FILE",
                     help=f"mesh file ({', '.join(objects.MESH_FORMATS).upper()}), coordinates in metres "
                          "(see --mesh-scale)")
    parser.add_argument("--mesh-scale", type=_float, default=1.0, metavar="S",
                        help="multiply the mesh coordinates by S, e.g. 0.001 for a file in mm (default 1)")
    parser.add_argument("--algorithm", default="apso", metavar="ALG",
                        help="apso (default), pso (simple PSO baseline), or both (same seed, compared)")
    parser.add_argument("--particles", type=_positive_int, default=60, metavar="N",
                        help="swarm size np, 2..1000 (default 60)")
    parser.add_argument("--iterations", type=_positive_int, default=50, metavar="N",
                        help="iterations nit, 1..10000 (default 50)")
    parser.add_argument("--seed", type=_positive_int, default=None, metavar="S",
                        help="random seed; the same seed gives the same grasp (default: random, printed)")
    parser.add_argument("--friction", type=_float, default=0.5, metavar="MU",
                        help="Coulomb friction coefficient for the fitness and epsilon, (0, 5] (default 0.5)")
    parser.add_argument("--hand", metavar="FILE", default=None,
                        help="hand description YAML (default: the shipped paper hand)")
    parser.add_argument("--out", metavar="DIR", default=None,
                        help=f"folder for the pictures (default ./{DEFAULT_OUT}/)")
    parser.add_argument("--no-plots", action="store_true", help="do not draw pictures")
    parser.add_argument("--quiet", action="store_true",
                        help="no progress and no tables: one summary line per run (and the file paths)")
    parser.add_argument("--json", metavar="FILE", default=None,
                        help="write a machine-readable summary (SI units) to FILE ('-': standard output, "
                             "the report then goes to standard error)")
    return parser


# ----------------------------------------------------------------------------- inputs
def _cli_message(exc: BaseException) -> str:
    """Error text with request-field prefixes renamed to the command line options."""
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    for old, new in (("mesh_uri:", "--mesh:"), ("object_name:", "--object:"), ("mesh:", "--mesh:"),
                     ("particles:", "--particles:"), ("iterations:", "--iterations:"),
                     ("friction:", "--friction:"), ("algorithm:", "--algorithm:")):
        if text.startswith(old):
            return new + text[len(old):]
    return text


def _load_object(args: argparse.Namespace):
    if args.mesh is not None:
        if args.mesh_scale <= 0:
            raise UsageError(f"--mesh-scale: expected a positive number, got {args.mesh_scale:g}")
        obj = mesh_files.from_file(args.mesh)
        if args.mesh_scale != 1.0:
            obj = objects.from_arrays(np.asarray(obj.mesh.vertices) * args.mesh_scale,
                                      np.asarray(obj.mesh.faces), name=obj.name)
        return obj, "mesh file " + args.mesh
    name = args.object if args.object is not None else "sphere"
    return builtin_objects.builtin(name.strip().lower()), "built-in"


def _algorithms(text: str) -> tuple[str, ...]:
    text = text.strip().lower()
    if text == "both":
        return ALGORITHMS
    if text in ALGORITHMS:
        return (text,)
    raise UsageError(f"--algorithm: unknown '{text}' (expected apso, pso or both)")


def _safe_name(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or "object"


# ----------------------------------------------------------------------------- progress
def _num(x: float) -> str:
    return f"{x:.3f}" if math.isfinite(x) else "-"


class _Progress:
    """Progress of one run on stderr: tqdm on a terminal, else a line every 10 iterations."""

    def __init__(self, label: str, total: int, stream, enabled: bool):
        self.label, self.total, self.stream, self.enabled = label, total, stream, enabled
        self.bar = None
        if enabled and hasattr(stream, "isatty") and stream.isatty():
            try:
                from tqdm import tqdm
            except ImportError:  # pragma: no cover - tqdm is a declared dependency
                tqdm = None
            if tqdm is not None:
                self.bar = tqdm(total=total, desc=label, unit="it", file=stream, leave=False,
                                dynamic_ncols=True)

    def __call__(self, stats) -> None:
        if not self.enabled:
            return
        if self.bar is not None:
            self.bar.set_postfix_str(
                f"best {stats.best_fitness:.3f}, mean {_num(stats.mean_fitness)}, "
                f"active {stats.active_particles}, contacts {stats.best_contacts}", refresh=False)
            self.bar.update(1)
        elif stats.iteration % 10 == 0 or stats.iteration in (1, stats.iterations):
            print(f"  {self.label} iteration {stats.iteration:>3}/{stats.iterations}: "
                  f"best fitness {stats.best_fitness:.3f}, mean of active {_num(stats.mean_fitness)}, "
                  f"{stats.active_particles} active particles, best has {stats.best_contacts} contacts, "
                  f"{stats.elapsed:.1f} s", file=self.stream, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


class _Interrupt:
    """First Ctrl-C: stop the swarm after the current iteration; second: abort."""

    def __init__(self):
        self.stop = False
        self._old = None

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            self._old = signal.signal(signal.SIGINT, self._handler)
        return self

    def _handler(self, signum, frame):
        if self.stop:
            raise KeyboardInterrupt
        self.stop = True
        print(f"\n{PROG}: interrupted: stopping after this iteration (Ctrl-C again to abort)",
              file=sys.stderr, flush=True)

    def __exit__(self, *exc):
        if self._old is not None:
            signal.signal(signal.SIGINT, self._old)
        return False


# ----------------------------------------------------------------------------- report
def _deg(x: float) -> float:
    return math.degrees(float(x))


def _yes(flag: bool) -> str:
    return "yes" if flag else "no"


def _vec(v, fmt: str = "{:7.1f}") -> str:
    return "(" + ", ".join(fmt.format(float(x)) for x in v) + ")"


def _fcl_text(result: GraspResult) -> str:
    report = result.fcl
    if report.legal:
        return (f"legal: no link penetrates the object beyond {FCL_TOLERANCE_MM:g} mm, "
                "no fingers collide")
    parts = []
    links = [f"{FINGER_NAMES[f]} {_LINK_NAMES[FINGER_NAMES[f]][k]}"
             for f, k in np.argwhere(np.asarray(report.link_penetrates))]
    if links:
        parts.append("links penetrating the object: " + ", ".join(links))
    if report.finger_pairs_colliding:
        parts.append("colliding fingers: " + ", ".join(f"{a}-{b}" for a, b in report.finger_pairs_colliding))
    return "NOT legal: " + "; ".join(parts)


def touching_links(result: GraspResult, tolerance: float = 1e-4) -> list[str]:
    """Links other than the contact fingertips that touch the object (python-fcl distance 0).

    The quality measures count fingertip contacts only; a link resting on the object makes
    the real grasp partly an enveloping one.
    """
    distance = np.asarray(result.fcl.link_distance, float)
    tips = {c.finger for c in result.contacts}
    out = []
    for f, k in np.argwhere(distance <= tolerance):
        finger = FINGER_NAMES[f]
        if k == 2 and finger in tips:
            continue
        out.append(f"{finger}_{_LINK_NAMES[finger][k]}")
    return out


def _verdict(result: GraspResult) -> str:
    if result.valid:
        text = "valid grasp, " + ("force closure" if result.force_closure else "NOT force closure")
    else:
        reasons = []
        if len(result.contacts) < 2:
            reasons.append(f"only {len(result.contacts)} fingertip contact(s)")
        if not result.fcl.legal:
            reasons.append("collision")
        if not reasons:
            reasons.append("a link penetrates the object")
        text = "NO valid grasp (" + ", ".join(reasons) + ")"
    if result.cancelled:
        text += f"; cancelled after {result.iterations_run} iterations"
    return text


def format_report(result: GraspResult, hand, friction: float,
                  pose_note: str = "object frame (= planning frame)") -> str:
    """The human-readable report of one plan (configuration, wrist, contacts, quality)."""
    lines = []
    algo = result.algorithm.upper()
    lines.append(f"{algo} result: {_verdict(result)}")
    lines.append("")
    lines.append("Hand configuration Cg, degrees, each value followed by its [Table 2 limits]:")
    lines.append(f"  {'finger':<8}" + "".join(f"{kind + ' (theta_i' + str(k + 1) + ')':>26}"
                                             for k, kind in enumerate(JOINT_KINDS)))
    lower, upper = np.degrees(hand.lower), np.degrees(hand.upper)
    q = np.degrees(np.asarray(result.joint_positions, float))

    def cell(j: int, prefix: str = "") -> str:
        at_limit = min(q[j] - lower[j], upper[j] - q[j]) < 0.05
        mark = "*" if at_limit else " "
        return f"{prefix}{q[j]:8.1f}{mark}[{lower[j]:5.0f}, {upper[j]:4.0f}]"

    for f, finger in enumerate(FINGER_NAMES):
        lines.append(f"  {finger:<8}" + "".join(f"{cell(3 * f + k):>26}" for k in range(3)))
    lines.append(f"  {'wrist':<8}" + "".join(f"{cell(15 + k, axis + ' '):>26}" for k, axis in enumerate("xyz")))
    lines.append("  (distal theta_i1 drives the last two joints, coupled 1.5:1; wrist: palm orientation "
                 "R = Rz Ry Rx; * = at a limit)")
    lines.append("")
    position, quat = poses.matrix_to_pose(result.wrist_pose)
    lines.append(f"Wrist pose (palm frame: origin at the wrist, +x fingers, +z palm normal) in the {pose_note}:")
    lines.append(f"  position     {_vec(np.asarray(position) * 1000)} mm")
    lines.append(f"  quaternion   {_vec(quat, '{:7.4f}')} (x, y, z, w)")
    lines.append(f"  standoff     {result.standoff * 1000:+.1f} mm added by the swarm to the computed "
                 "palm-object standoff")
    lines.append("")
    lines.append(f"Contacts: {len(result.contacts)} fingertip contact(s), positions in the {pose_note}:")
    if result.contacts:
        lines.append(f"  {'finger':<8}{'position (mm)':>28}   {'outward surface normal':>26}")
        for c in result.contacts:
            lines.append(f"  {c.finger:<8}{_vec(np.asarray(c.position) * 1000):>28}   "
                         f"{_vec(c.normal, '{:6.3f}'):>26}")
    else:
        lines.append("  (none)")
    lines.append("")
    fingers = ", ".join(c.finger for c in result.contacts) or "none"
    lines.append("Quality:")
    rows = [
        ("fitness", f"{result.fitness:.3f}",
         "maximised, in [0, 1] for a valid grasp (below 0: none found)"),
        ("epsilon", f"{result.epsilon:.4f}",
         f"Ferrari-Canny, friction mu {friction:g}; > 0 means force closure"),
        ("force closure", _yes(result.force_closure),
         "a runner-up: the global best was not force closure" if result.runner_up else ""),
        ("fingertip contacts", f"{len(result.contacts)}", fingers),
        ("max penetration", f"{result.max_penetration * 1000:.2f} mm",
         "deepest link into the object"),
        ("python-fcl check", _fcl_text(result), ""),
        ("other links touching",
         (", ".join(t.replace("_", " ") for t in touching_links(result)) + " (not counted as contacts)")
         if touching_links(result) else "none", ""),
        ("iterations", f"{result.iterations_run} of {result.history[-1].iterations if result.history else '?'}",
         "(cancelled)" if result.cancelled else ""),
        ("evaluations", f"{result.evaluations}", "particle decodes (GRG draws included)"),
        ("planning time", f"{result.planning_time:.2f} s", "swarm and verification"),
        ("preparation time", f"{result.preparation_time:.2f} s",
         "distance grid and shape class (cached per mesh)"),
    ]
    for name, value, note in rows:
        lines.append(f"  {name:<21}{value:<10}{('  ' + note) if note else ''}".rstrip())
    return "\n".join(lines)


def _fitness_at(result: GraspResult, iteration: int) -> float | None:
    for stats in result.history:
        if stats.iteration == iteration:
            return float(stats.best_fitness)
    return None


def format_comparison(results: dict[str, GraspResult], seed: int) -> str:
    """Side-by-side table of the runs (same object, same seed)."""
    names = list(results)
    width = 12
    lines = [f"Comparison ({', '.join(n.upper() for n in names)}; same object, seed {seed}, "
             "same fitness; higher fitness is better):"]
    lines.append(f"  {'':<24}" + "".join(f"{n.upper():>{width}}" for n in names))

    def row(label: str, values: Sequence[str]) -> None:
        lines.append(f"  {label:<24}" + "".join(f"{v:>{width}}" for v in values))

    row("final best fitness", [f"{r.fitness:.3f}" for r in results.values()])
    longest = max(r.iterations_run for r in results.values())
    for k in COMPARE_AT:
        if k <= longest:
            vals = [_fitness_at(r, k) for r in results.values()]
            row(f"best fitness at iter. {k}", ["-" if v is None else f"{v:.3f}" for v in vals])
    row("epsilon", [f"{r.epsilon:.4f}" for r in results.values()])
    row("force closure", [_yes(r.force_closure) for r in results.values()])
    row("fingertip contacts", [str(len(r.contacts)) for r in results.values()])
    row("valid grasp", [_yes(r.valid) for r in results.values()])
    row("planning time (s)", [f"{r.planning_time:.2f}" for r in results.values()])
    row("evaluations", [str(r.evaluations) for r in results.values()])
    if "apso" in results and "pso" in results:
        target = results["pso"].history[-1].best_fitness if results["pso"].history else None
        reached = None
        if target is not None:
            for stats in results["apso"].history:
                if stats.best_fitness >= target:
                    reached = stats.iteration
                    break
        if target is not None:
            if reached is not None:
                lines.append(f"  APSO reached the final PSO fitness ({target:.3f}) at iteration {reached} "
                             f"of {results['apso'].iterations_run}.")
            else:
                lines.append(f"  APSO did not reach the final PSO fitness ({target:.3f}).")
    return "\n".join(lines)


def summary_line(result: GraspResult, object_name: str) -> str:
    fingers = ",".join(c.finger for c in result.contacts) or "none"
    return (f"{object_name} {result.algorithm.upper()}: fitness {result.fitness:.3f}, "
            f"epsilon {result.epsilon:.4f}, force closure {_yes(result.force_closure)}, "
            f"valid {_yes(result.valid)}, contacts {len(result.contacts)} ({fingers}), "
            f"{result.iterations_run} iterations, {result.planning_time:.2f} s")


# ----------------------------------------------------------------------------- JSON
def result_to_dict(result: GraspResult, friction: float | None = None) -> dict[str, Any]:
    """JSON-ready summary of a plan (SI units: metres, radians, seconds)."""
    position, quat = poses.matrix_to_pose(result.wrist_pose)
    fcl = result.fcl
    return {
        "algorithm": result.algorithm,
        "valid": bool(result.valid),
        "cancelled": bool(result.cancelled),
        "joint_names": list(result.joint_names),
        "joint_positions": [float(x) for x in result.joint_positions],
        "configuration": np.asarray(result.configuration, float).tolist(),
        "wrist_pose": {
            "position": [float(x) for x in position],
            "orientation_xyzw": [float(x) for x in quat],
            "matrix": np.asarray(result.wrist_pose, float).tolist(),
        },
        "standoff": float(result.standoff),
        "fitness": float(result.fitness),
        "epsilon": float(result.epsilon),
        "friction": friction,
        "force_closure": bool(result.force_closure),
        "contacts": [
            {"finger": c.finger, "position": [float(x) for x in c.position],
             "normal": [float(x) for x in c.normal]}
            for c in result.contacts
        ],
        "n_contacts": len(result.contacts),
        "max_penetration": float(result.max_penetration),
        "fcl": {
            "legal": bool(fcl.legal),
            "penetrating_links": [
                f"{FINGER_NAMES[f]}_{_LINK_NAMES[FINGER_NAMES[f]][k]}"
                for f, k in np.argwhere(np.asarray(fcl.link_penetrates))
            ],
            "colliding_finger_pairs": [list(p) for p in fcl.finger_pairs_colliding],
            "link_distance": np.asarray(fcl.link_distance, float).tolist(),
            "touching_links": touching_links(result),
        },
        "shape_class": result.shape_class,
        "iterations_run": int(result.iterations_run),
        "evaluations": int(result.evaluations),
        "planning_time": float(result.planning_time),
        "preparation_time": float(result.preparation_time),
        "history": [
            {"iteration": int(s.iteration), "best_fitness": float(s.best_fitness),
             "mean_fitness": float(s.mean_fitness), "active_particles": int(s.active_particles),
             "best_contacts": int(s.best_contacts), "evaluations": int(s.evaluations),
             "elapsed": float(s.elapsed)}
            for s in result.history
        ],
    }


# ----------------------------------------------------------------------------- main
def _run(args: argparse.Namespace, out, err) -> int:
    algorithms = _algorithms(args.algorithm)
    options = {alg: PlanOptions(algorithm=alg, particles=args.particles, iterations=args.iterations,
                                friction=args.friction) for alg in algorithms}
    hand = load_hand(args.hand)
    obj, source = _load_object(args)
    seed = args.seed
    seed_note = ""
    if seed is None:
        seed = int(np.random.SeedSequence().entropy % (2 ** 31))
        seed_note = f" (random; --seed {seed} repeats this run)"
    elif seed < 0:
        raise UsageError(f"--seed: must be >= 0, got {seed}")

    from ..search.grg import classify_shape

    shape = classify_shape(obj)
    ext = " x ".join(f"{e * 1000:.0f}" for e in obj.principal_extents)
    show = not args.quiet
    if show:
        print(f"{PROG}: precision grasp planning (no ROS)", file=out)
        print(f"  object     {obj.name} ({source}): {len(obj.mesh.faces)} triangles, {ext} mm, "
              f"shape class {shape.name}", file=out)
        print(f"  algorithm  {' and '.join(a.upper() for a in algorithms)}: {args.particles} particles, "
              f"{args.iterations} iterations, seed {seed}{seed_note}, friction mu {args.friction:g}", file=out)
        print("", file=out)
        out.flush()

    warm_up()  # the compiled kernels' one-off load is not the planner's time
    results: dict[str, GraspResult] = {}
    with _Interrupt() as interrupt:
        for alg in algorithms:
            progress = _Progress(alg.upper(), args.iterations, err, enabled=show)
            try:
                result = plan(obj, options=options[alg], rng=np.random.default_rng(seed), hand=hand,
                              progress=progress, should_stop=lambda: interrupt.stop)
            finally:
                progress.close()
            results[alg] = result
            if show:
                print(format_report(result, hand, args.friction), file=out)
                print("", file=out)
                out.flush()
            if interrupt.stop:
                break

    if show and len(results) > 1:
        print(format_comparison(results, seed), file=out)
        print("", file=out)
    if args.quiet:
        for result in results.values():
            print(summary_line(result, obj.name), file=out)

    written: list[str] = []
    if not args.no_plots:
        from .plotting import plot_convergence, plot_grasp

        folder = args.out if args.out is not None else DEFAULT_OUT
        stem = _safe_name(obj.name)
        for alg, result in results.items():
            written.append(plot_grasp(result, obj, path=os.path.join(folder, f"{stem}_{alg}_grasp.png"),
                                      hand=hand))
        title = (f"{obj.name}: best and mean fitness per iteration "
                 f"({' vs '.join(a.upper() for a in results)}, {args.particles} particles, seed {seed})")
        written.append(plot_convergence({a.upper(): r for a, r in results.items()},
                                        path=os.path.join(folder, f"{stem}_convergence.png"), title=title))
    if args.json is not None:
        doc = {
            "units": "SI: metres, radians, seconds; poses in the object frame (= planning frame)",
            "object": {"name": obj.name, "source": source, "triangles": int(len(obj.mesh.faces)),
                       "principal_extents": [float(e) for e in obj.principal_extents],
                       "shape_class": shape.name},
            "options": {"particles": args.particles, "iterations": args.iterations, "seed": seed,
                        "friction": args.friction},
            "results": {alg: result_to_dict(r, args.friction) for alg, r in results.items()},
            "pictures": written,
        }
        text = json.dumps(doc, indent=2)
        if args.json == "-":
            sys.stdout.write(text + "\n")
        else:
            folder = os.path.dirname(os.path.abspath(args.json))
            os.makedirs(folder, exist_ok=True)
            with open(args.json, "w", encoding="utf-8") as fh:
                fh.write(text + "\n")
            written.append(args.json)
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
    except (GraspApsoError, ValueError) as exc:
        message = _cli_message(exc)
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
