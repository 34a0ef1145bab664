#!/usr/bin/env python3
"""Benchmark of the MuJoCo grasp check (``grasp_apso.simulation.simulate_grasp``).

Rerunnable, not a test::

    python bench/bench_simulation.py                    # 5 grasps on each built-in object
    python bench/bench_simulation.py --grasps 8 --objects sphere fish

For each object, ``--grasps`` grasps are planned (seeds 0, 1, ...; particles 30,
iterations 20; not timed), the convex decomposition is computed once beforehand (CoACD,
timed separately as ``decomposition_s``: a first check on a new mesh pays it once, later
ones hit the cache), then each grasp is checked once with the default
:class:`SimulationSettings` (pre-grasp = the grasp opened by 0.4 rad on every flexion).
The time per grasp is :attr:`SimResult.sim_time` (wall clock: model building, closing,
squeeze, six disturbance directions). Prints a table (median / min / max ms per grasp,
held count) and writes JSON (default ``bench/results/simulation.json``) with the load
average before and after the run: other processes on the machine disturb the timings.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
if str(REPO_ROOT) not in sys.path:
    sys.path.insert(0, str(REPO_ROOT))

import numpy as np  # noqa: E402

from grasp_apso.model.hand import load_hand  # noqa: E402
from grasp_apso.search.planner import PlanOptions, plan  # noqa: E402
from grasp_apso.simulation import SimulationSettings, convex_parts, simulate_grasp  # noqa: E402
from grasp_apso.simulation import convex as convex_module  # noqa: E402

try:
    from grasp_apso.model.objects import builtin
except ImportError:  # the built-in objects moved to grasp_apso.model.builtin
    from grasp_apso.model.builtin import builtin

OBJECTS = ("sphere", "cube", "barrel", "fish")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--objects", nargs="+", default=list(OBJECTS), choices=OBJECTS)
    parser.add_argument("--grasps", type=int, default=5, help="grasps per object (>= 1)")
    parser.add_argument("--out", default=str(REPO_ROOT / "bench" / "results" / "simulation.json"))
    args = parser.parse_args(argv)
    if args.grasps < 1:
        parser.error("--grasps must be >= 1")

    hand = load_hand()
    settings = SimulationSettings()
    load_before = os.getloadavg()
    rows = []
    for name in args.objects:
        obj = builtin(name)
        convex_module.clear_memory_cache()
        t0 = time.perf_counter()
        parts = convex_parts(obj, settings.decomposition, use_disk=False)
        decomposition = time.perf_counter() - t0
        times, held, contacts = [], 0, []
        for seed in range(args.grasps):
            result = plan(obj, options=PlanOptions(particles=30, iterations=20), rng=np.random.default_rng(seed))
            grasp = result.joint_positions[:15]
            pre = grasp.copy()
            pre[0::3] -= 0.4
            pre[1::3] -= 0.4
            pre = np.clip(pre, hand.lower[:15], hand.upper[:15])
            res = simulate_grasp(hand, obj, np.eye(4), result.wrist_pose, pre, grasp, settings=settings)
            times.append(res.sim_time * 1000.0)
            held += int(res.held)
            contacts.append(len(result.contacts))
        rows.append({
            "object": name, "grasps": args.grasps, "convex_parts": len(parts),
            "decomposition_s": round(decomposition, 3),
            "median_ms": round(statistics.median(times), 1), "min_ms": round(min(times), 1),
            "max_ms": round(max(times), 1), "held": held, "times_ms": [round(t, 1) for t in times],
            "contacts": contacts,
        })
    load_after = os.getloadavg()

    print(f"{'object':8s} {'parts':>5s} {'CoACD s':>8s} {'median ms':>10s} {'min ms':>7s} {'max ms':>7s} {'held':>6s}")
    for r in rows:
        print(f"{r['object']:8s} {r['convex_parts']:5d} {r['decomposition_s']:8.2f} {r['median_ms']:10.1f} "
              f"{r['min_ms']:7.1f} {r['max_ms']:7.1f} {r['held']:>3d}/{r['grasps']}")
    all_times = [t for r in rows for t in r["times_ms"]]
    print(f"all: median {statistics.median(all_times):.1f} ms per grasp over {len(all_times)} grasps "
          f"(load average {load_before[0]:.2f} -> {load_after[0]:.2f}, {os.cpu_count()} cores)")

    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    import mujoco

    out.write_text(json.dumps({
        "benchmark": "simulation", "settings": {k: (list(v) if isinstance(v, tuple) else v)
                                                for k, v in vars(settings).items() if k != "decomposition"},
        "mujoco": mujoco.__version__, "python": platform.python_version(), "machine": platform.machine(),
        "cpu_count": os.cpu_count(), "load_before": load_before, "load_after": load_after,
        "median_ms_all": round(statistics.median(all_times), 1), "objects": rows,
    }, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
