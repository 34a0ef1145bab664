"""The command line: ``python -m grasp_apso.experiment [--seeds N] [--out DIR] [--quick]
[--objects ...] [--no-peers] [--no-speed]``."""

from __future__ import annotations

import argparse
import sys
from typing import Any, Sequence

from .config import DEFAULT_OUT, ExperimentConfig
from .pipeline import run_experiment


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m grasp_apso.experiment",
        description="APSO vs simple PSO on the paper's four objects (Table 3), pyswarms peers and speed; "
                    "writes report.md, results.json and pictures.")
    p.add_argument("--seeds", type=int, default=None, help="seeds 0..N-1 (default 20; quick: 2)")
    p.add_argument("--out", default=DEFAULT_OUT, help=f"output folder (default {DEFAULT_OUT})")
    p.add_argument("--quick", action="store_true",
                   help="CI mode: 2 seeds, sphere and cube, np = 20, nit = 10, small speed sweeps")
    p.add_argument("--objects", default=None, help="comma-separated subset of sphere,cube,barrel,fish")
    p.add_argument("--no-peers", action="store_true", help="skip pyswarms")
    p.add_argument("--no-speed", action="store_true", help="skip the speed measurements")
    p.add_argument("--no-part2", action="store_true",
                   help="skip the table scenario, the ranked candidates and the simulation check")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    given = list(sys.argv[1:] if argv is None else argv)
    kw: dict[str, Any] = {"command": " ".join(["python -m grasp_apso.experiment", *given])}
    if args.seeds is not None:
        kw["seeds"] = args.seeds
    if args.objects:
        kw["objects"] = tuple(o.strip() for o in args.objects.split(",") if o.strip())
    if args.no_peers:
        kw["peers"] = False
    if args.no_speed:
        kw["speed"] = None
    if args.no_part2:
        kw["part2"] = None
    try:
        cfg = ExperimentConfig.quick_config(**kw) if args.quick else ExperimentConfig(**kw)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    run_experiment(cfg, args.out)
    return 0
