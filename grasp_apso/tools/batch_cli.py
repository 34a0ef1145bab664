"""Command line ``grasp_apso_batch``: plan many objects into a grasp database (Parquet).

Examples::

    grasp_apso_batch meshes/ --out grasps.db                       # all cores, local processes
    grasp_apso_batch parts.csv --out grasps.db --grasps 10 --workers 2
    grasp_apso_batch meshes/ --out grasps.db --ray                 # a private local Ray
    grasp_apso_batch meshes/ --out grasps.db --ray auto            # join a running Ray cluster

INPUT: mesh files (STL/OBJ/PLY/OFF), folders of them (recursive), or manifests (``.csv``
with a header, or ``.jsonl``: ``id, path, scale, pose, table``; see
:mod:`grasp_apso.database.inputs`). The database layout and schema:
:mod:`grasp_apso.database`. A rerun skips the objects already stored with the same mesh
file, scale, hand and options; Ctrl-C stops after writing what has arrived.

Exit status: 0 every object planned or skipped; 1 some objects failed (recorded in the
database's failures table, listed on stderr); 2 bad usage or an unusable database (for
instance locked by another batch); 130 interrupted (the database stays valid).
"""

from __future__ import annotations

import argparse
import sys
from typing import Sequence

from ..errors import GraspApsoError, UsageError
from ..search.options import PlanOptions

PROG = "grasp_apso_batch"


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, no usage dump
        raise UsageError(f"{message} (see {PROG} --help)")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog=PROG, description="Plan K ranked grasps for every object of a mesh collection "
                "into a Parquet grasp database, on local worker processes or a Ray cluster.",
                epilog="Exit status: 0 done, 1 some objects failed (recorded), 2 bad usage or "
                       "database, 130 interrupted.")
    p.add_argument("inputs", nargs="+", metavar="INPUT", help="mesh files, folders of them, or manifests "
                   "(.csv / .jsonl: id, path, scale, pose, table)")
    p.add_argument("--out", required=True, metavar="DB", help="grasp database directory (created if missing)")
    p.add_argument("--grasps", type=int, default=5, metavar="K", help="ranked grasps per object (default 5)")
    eng = p.add_mutually_exclusive_group()
    eng.add_argument("--workers", type=int, default=None, metavar="N",
                     help="local worker processes (default: all cores)")
    eng.add_argument("--ray", nargs="?", const="", default=None, metavar="ADDRESS",
                     help="run on Ray: without ADDRESS a private local Ray, else join that cluster "
                          "(auto, host:port, ray://host:port)")
    p.add_argument("--ray-cpus", type=int, default=None, metavar="N",
                   help="CPUs of the private local Ray (default: all cores)")
    p.add_argument("--simulate", action="store_true", help="check every grasp in the MuJoCo simulation")
    p.add_argument("--particles", type=int, default=None, metavar="N", help="swarm size (default: the planner's)")
    p.add_argument("--iterations", type=int, default=None, metavar="N",
                   help="iterations (default: the planner's)")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="base random seed (default 0)")
    p.add_argument("--table", action="store_true",
                   help="a support plane under every object (a manifest's table column overrides it)")
    p.add_argument("--hand", metavar="FILE", default=None,
                   help="the hand to plan with: a URDF (.urdf), MJCF (.xml) or the project's YAML (.yaml) "
                        "description (default: the shipped paper hand); rows carry its hand_name and hand_hash")
    p.add_argument("--hand-config", metavar="FILE", default=None,
                   help="YAML overriding what is derived from the --hand description")
    p.add_argument("--retry-failed", action="store_true",
                   help="plan again objects whose earlier failure was deterministic (bad mesh ...)")
    p.add_argument("--flush-seconds", type=float, default=5.0, metavar="S",
                   help="write buffered rows at least this often (default 5; 0 = after every object)")
    p.add_argument("--progress", choices=("auto", "bar", "lines", "none"), default="auto",
                   help="progress display (default auto: a bar on a terminal, lines otherwise)")
    return p


def _config(args: argparse.Namespace):
    from ..database.batch import BatchConfig

    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers: expected at least 1, got {args.workers}")
    if args.grasps < 1:
        raise UsageError(f"--grasps: expected at least 1, got {args.grasps}")
    if args.flush_seconds < 0:
        raise UsageError(f"--flush-seconds: expected 0 or more, got {args.flush_seconds:g}")
    kwargs = {"max_grasps": args.grasps, "simulate": bool(args.simulate)}
    if args.particles is not None:
        kwargs["particles"] = args.particles
        kwargs["neighborhood_size"] = min(PlanOptions().neighborhood_size, args.particles)
    if args.iterations is not None:
        kwargs["iterations"] = args.iterations
    options = PlanOptions(**kwargs)  # InputError names the field
    use_ray = args.ray is not None
    return BatchConfig(
        out=args.out, options=options, seed=args.seed, table=args.table, hand_path=args.hand,
        hand_config=args.hand_config,
        engine="ray" if use_ray else "local",
        workers=args.ray_cpus if use_ray else args.workers,
        ray_address=(args.ray or None) if use_ray else None, retry_failed=args.retry_failed,
        flush_seconds=args.flush_seconds, flush_objects=1 if args.flush_seconds == 0 else 32,
        progress=args.progress,
    )


def main(argv: Sequence[str] | None = None) -> int:
    from ..database.batch import run_batch

    err = sys.stderr
    try:
        args = build_parser().parse_args(argv)
        config = _config(args)
        summary = run_batch(args.inputs, config, stream=err)
    except GraspApsoError as exc:
        print(f"{PROG}: error: {exc}", file=err)
        return 2
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=err)
        return 130
    rate = f", {summary.objects_per_minute:.1f} objects/min" if summary.planned else ""
    nodes = f" on {len(summary.nodes)} nodes" if len(summary.nodes) > 1 else ""
    print(f"[{PROG}] planned {summary.planned}, skipped {summary.skipped}, failed {summary.failed}; "
          f"{summary.grasps} grasps in {summary.seconds:.1f} s ({summary.engine}, {summary.workers} "
          f"workers{nodes}{rate}) -> {summary.out}", file=err)
    for object_id, error in summary.failures[:20]:
        print(f"  failed: {object_id}: {error}", file=err)
    if len(summary.failures) > 20:
        print(f"  ... and {len(summary.failures) - 20} more (see the failures table)", file=err)
    if summary.interrupted:
        print(f"{PROG}: interrupted; the database is valid, rerun to continue", file=err)
        return 130
    return 1 if summary.failed else 0


if __name__ == "__main__":
    sys.exit(main())
