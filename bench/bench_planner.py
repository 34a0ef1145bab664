#!/usr/bin/env python3
"""Benchmark of the planner's speed: plan time per built-in object and how it grows with the
number of particles, iterations and mesh triangles.

Rerunnable, not a test::

    .venv/bin/python bench/bench_planner.py               # full (about 2-3 minutes)
    .venv/bin/python bench/bench_planner.py --quick       # a few seconds, small sweeps

Measures (all with ``grasp_apso.search.planner.plan``, ``GraspResult.planning_time`` and
``preparation_time``; seeds 0..N-1):

* per object: APSO and the simple PSO, np = 60, nit = 50, geometry prepared beforehand;
  median of ``--runs`` plans (default 5), evaluations per second;
* particles 15, 30, 60, 120 (nit = 50) and iterations 10, 25, 50, 100 (np = 60) on the
  sphere, median of ``--repeats`` plans;
* mesh triangles, 1k to 100k: spheres of 5 cm diameter (trimesh icospheres with 3..6
  subdivisions and a 9,600-triangle UV sphere); object construction (validation),
  preparation (signed-distance grid, the named cache ``"sdf_grid"`` of ``grasp_apso.cache`` cleared first), the first
  plan (includes the python-fcl BVH build) and later plans, timed separately.

Prints the tables (Markdown) and writes ``bench/results/planner.json`` and
``bench/results/planner.png``. The same code makes the speed section of
``python -m grasp_apso.experiment`` (``grasp_apso.experiment.run_speed``). Timings are wall
clock; other processes disturb them: the JSON records the load average before and after.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
if str(REPO_ROOT) not in sys.path:
    sys.path.insert(0, str(REPO_ROOT))

from grasp_apso.experiment import (  # noqa: E402
    SpeedConfig, _compact_json, _machine, format_speed_tables, plot_speed, run_speed,
)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=int, default=5, help="plans per object and algorithm (default 5)")
    p.add_argument("--repeats", type=int, default=5, help="plans per sweep point (default 5)")
    p.add_argument("--quick", action="store_true", help="small sweeps, one run each")
    p.add_argument("--out", default=str(REPO_ROOT / "bench" / "results" / "planner.json"))
    args = p.parse_args(argv)
    speed = SpeedConfig.quick() if args.quick else replace(SpeedConfig(), per_object_runs=args.runs,
                                                           repeats=args.repeats)
    t0 = time.perf_counter()
    load_before = list(os.getloadavg())
    result = run_speed(speed, log=lambda m: print(f"[bench_planner] {m}", file=sys.stderr, flush=True))
    result["meta"] = {"machine": _machine(), "load_average_before": load_before,
                      "load_average_after": list(os.getloadavg()), "wall_time_s": time.perf_counter() - t0,
                      "command": "python bench/bench_planner.py " + " ".join(sys.argv[1:] if argv is None else argv)}
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    with open(args.out, "w") as f:
        f.write(_compact_json(result))
    picture = os.path.splitext(args.out)[0] + ".png"
    plot_speed(result, picture)
    print(format_speed_tables(result))
    print(f"\nwrote {args.out} and {picture} in {result['meta']['wall_time_s']:.0f} s "
          f"(load average before {load_before[0]:.1f}, after {result['meta']['load_average_after'][0]:.1f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
