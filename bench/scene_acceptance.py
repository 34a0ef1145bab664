#!/usr/bin/env python3
"""Issue 11's acceptance matrix as a rerunnable script: grasps of objects resting on a table.

Rerunnable, not a test::

    .venv/bin/python bench/scene_acceptance.py            # full: every object x 3 poses, default swarm
    .venv/bin/python bench/scene_acceptance.py --quick    # CI's reduced set (4 built-ins + 4 meshes)

The same code as ``test/test_scene_acceptance.py`` (imported from it): each object (the
four built-ins and every mesh in ``grasp_apso/data/meshes``) in the identity pose and
seeded random rotations, on a table under its lowest point, planned with
``plan(..., scene=...)``; every returned candidate is measured with python-fcl against
the whole hand built from its URDF (grasp, pre-grasp and the approach path). Then each
object once more with a box wall 2 cm beside it.

Prints a table (object, pose, valid, least table and obstacle distance in mm, plan time)
and writes ``bench/results/scene_acceptance.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import statistics
import sys
import time
from dataclasses import asdict
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE.parent / "test"))

import numpy as np  # noqa: E402

import test_scene_acceptance as acceptance  # noqa: E402
from grasp_apso.search.options import PlanOptions  # noqa: E402


def _mm(x: float) -> str:
    return "—" if not math.isfinite(x) else f"{x:8.2f}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="CI's reduced set and swarm")
    parser.add_argument("--poses", type=int, default=3, help="poses per object (full run; default 3)")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "scene_acceptance.json")
    args = parser.parse_args(argv)
    if not 1 <= args.poses <= 20:
        parser.error("--poses: expected 1..20")

    if args.quick:
        options = PlanOptions(**acceptance.CI_OPTIONS)
        objects = list(acceptance.BUILTIN_OBJECTS) + acceptance.ci_meshes()
        pose_list = acceptance.poses(1)
    else:
        options = PlanOptions(max_grasps=5)
        objects = list(acceptance.BUILTIN_OBJECTS) + acceptance.mesh_names()
        pose_list = acceptance.poses(args.poses)

    t0 = time.perf_counter()
    rows = []
    print(f"{'object':22s} {'pose':>4s} {'valid':>5s} {'cand':>4s} {'table mm':>8s} {'obst mm':>8s} {'plan s':>6s}")
    for i, name in enumerate(objects):
        for k, pose in enumerate(pose_list):
            rows.append(acceptance.run_case(name, k, pose, options, seed=100 * i + k))
            _print(rows[-1])
    wall_rows = []
    for i, name in enumerate(objects):
        wall_rows.append(acceptance.run_case(name, 0, np.eye(4), options, seed=i, obstacle=True))
        _print(wall_rows[-1], suffix=" + wall")

    clearance_mm = 1000 * options.clearance
    summary = {}
    for label, group in (("table", rows), ("table_and_wall", wall_rows)):
        valid = sum(r.valid for r in group)
        violations = [f"{r.object}#{r.pose}" for r in group
                      if r.min_table_mm < clearance_mm - 1e-3 or r.min_obstacle_mm < clearance_mm - 1e-3]
        times = [r.plan_time for r in group if math.isfinite(r.plan_time)]
        summary[label] = {
            "plans": len(group), "valid": valid, "valid_rate": valid / max(len(group), 1),
            "clearance_violations": violations,
            "min_table_mm": min((r.min_table_mm for r in group if math.isfinite(r.min_table_mm)), default=None),
            "median_plan_s": statistics.median(times) if times else None,
        }
        print(f"{label}: {valid}/{len(group)} valid ({100 * valid / max(len(group), 1):.1f} %), "
              f"clearance violations: {violations or 'none'}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(_finite({
        "quick": args.quick,
        "options": {"particles": options.particles, "iterations": options.iterations,
                    "max_grasps": options.max_grasps, "clearance": options.clearance,
                    "approach_distance": options.approach_distance},
        "summary": summary,
        "rows": [asdict(r) for r in rows],
        "wall_rows": [asdict(r) for r in wall_rows],
        "seconds": time.perf_counter() - t0,
        "machine": platform.platform(),
    }), indent=1, allow_nan=False))
    print(f"wrote {args.out}")
    ok = all(s["valid_rate"] >= acceptance.SUCCESS_RATE and not s["clearance_violations"] for s in summary.values())
    return 0 if ok else 1


def _finite(x):
    """JSON-safe copy: non-finite floats (no plan, no obstacle) become null."""
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_finite(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def _print(r, suffix: str = "") -> None:
    print(f"{(r.object + suffix)[:22]:22s} {r.pose:4d} {str(r.valid):>5s} {r.candidates:4d} "
          f"{_mm(r.min_table_mm)} {_mm(r.min_obstacle_mm)} {r.plan_time:6.2f}"
          + (f"  ({r.error})" if r.error else ""), flush=True)


if __name__ == "__main__":
    sys.exit(main())
