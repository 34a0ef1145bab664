#!/usr/bin/env python3
"""Benchmark: plan time with a table and with a box obstacle against free space (issue 11).

Rerunnable, not a test::

    .venv/bin/python bench/bench_scene.py            # 15 runs per object and scene
    .venv/bin/python bench/bench_scene.py --runs 5

On each built-in object (its own frame): free space; a table (support plane under its
lowest point); a box obstacle (a 30 x 2 x 30 cm wall 1.5 cm beside the object, along
+y). Default options (np = 60, nit = 50, max_grasps = 1 so that the scene's cost is
measured, not the candidates'), seeds 0..runs-1, kernels warmed up first, the three
scenes interleaved per seed so that they share the machine's state. Prints a Markdown
table of the medians of the wall clock of ``plan``, the ratios of the medians scene /
free, and the medians of the per-seed ratios (each seed's scene plan against its free
one, run back to back: less disturbed by a shared machine whose speed drifts), and
writes ``bench/results/scene.json`` (also the CPU time of the planning thread).
Target: ratios <= 1.3.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
if str(REPO_ROOT) not in sys.path:
    sys.path.insert(0, str(REPO_ROOT))

import numpy as np  # noqa: E402

from grasp_apso.model.builtin import builtin  # noqa: E402
from grasp_apso.model.scene import BOX, Scene  # noqa: E402
from grasp_apso.search.planner import PlanOptions, plan, warm_up  # noqa: E402

OBJECTS = ("sphere", "cube", "barrel", "fish")


def scenes(obj) -> dict[str, Scene | None]:
    v = np.asarray(obj.mesh.vertices)
    wall = np.eye(4)
    wall[:3, 3] = [0.0, v[:, 1].max() + 0.015 + 0.01, 0.5 * (v[:, 2].min() + v[:, 2].max())]
    return {
        "free": None,
        "table": Scene.table_under(v),
        "box": Scene.from_primitives(obstacles=[(BOX, (0.3, 0.02, 0.3))], obstacle_poses=[wall]),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=15)
    parser.add_argument("--max-grasps", type=int, default=1)
    args = parser.parse_args()
    warm_up()
    options = PlanOptions(max_grasps=args.max_grasps)
    load_before = os.getloadavg()
    rows = {}
    for name in OBJECTS:
        obj = builtin(name)
        sc = scenes(obj)
        for s in sc.values():  # geometry and BVH prepared outside the timing
            plan(obj, options=PlanOptions(particles=4, iterations=1, neighborhood_size=2, max_grasps=1),
                 rng=np.random.default_rng(99), scene=s)
        times = {k: [] for k in sc}
        cpu = {k: [] for k in sc}
        found = {k: 0 for k in sc}
        for seed in range(args.runs):
            for key, s in sc.items():
                t0, c0 = time.perf_counter(), time.thread_time()
                try:
                    res = plan(obj, options=options, rng=np.random.default_rng(seed), scene=s)
                    found[key] += int(res.valid)
                except Exception as exc:  # noqa: BLE001 -- a failed plan is recorded, the bench goes on
                    print(f"{name} {key} seed {seed}: {exc}", file=sys.stderr)
                cpu[key].append(time.thread_time() - c0)
                times[key].append(time.perf_counter() - t0)
        med = {k: float(np.median(v)) for k, v in times.items()}
        med_cpu = {k: float(np.median(v)) for k, v in cpu.items()}
        free = np.array(times["free"])
        rows[name] = {"median_s": med, "median_cpu_s": med_cpu, "valid": found, "times_s": times, "cpu_s": cpu,
                      "ratio_table": med["table"] / med["free"], "ratio_box": med["box"] / med["free"],
                      "paired_ratio_table": float(np.median(np.array(times["table"]) / free)),
                      "paired_ratio_box": float(np.median(np.array(times["box"]) / free)),
                      "cpu_ratio_table": med_cpu["table"] / med_cpu["free"],
                      "cpu_ratio_box": med_cpu["box"] / med_cpu["free"]}
    print("| object | free (s) | table (s) | box (s) | table / free | box / free "
          "| per seed: table / free | per seed: box / free | valid free/table/box |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, r in rows.items():
        m, v = r["median_s"], r["valid"]
        print(f"| {name} | {m['free']:.3f} | {m['table']:.3f} | {m['box']:.3f} | {r['ratio_table']:.2f} | "
              f"{r['ratio_box']:.2f} | {r['paired_ratio_table']:.2f} | {r['paired_ratio_box']:.2f} "
              f"| {v['free']}/{v['table']}/{v['box']} of {args.runs} |")
    out = REPO_ROOT / "bench" / "results" / "scene.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"runs": args.runs, "max_grasps": args.max_grasps, "objects": rows,
                               "load_before": load_before, "load_after": os.getloadavg()}, indent=1))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
