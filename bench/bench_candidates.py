#!/usr/bin/env python3
"""Benchmark: the cost of 5 ranked candidates against one grasp, and verified candidates
per second (issue 12).

Rerunnable, not a test::

    .venv/bin/python bench/bench_candidates.py             # 5 runs per object
    .venv/bin/python bench/bench_candidates.py --table     # the objects resting on a table

On each built-in object: default options with max_grasps = 1 and = 5, seeds
0..runs-1 interleaved, kernels warmed up first. Prints medians of the plan time, their
ratio (target <= 1.3), the median number of candidates, and verified candidates per
second (candidates returned / plan time; and of the verification alone: candidates /
the extra time over one grasp). Writes ``bench/results/candidates.json``.
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
from grasp_apso.model.scene import Scene  # noqa: E402
from grasp_apso.search.planner import PlanOptions, plan, warm_up  # noqa: E402

OBJECTS = ("sphere", "cube", "barrel", "fish")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--table", action="store_true", help="objects resting on a table")
    args = parser.parse_args()
    warm_up()
    load_before = os.getloadavg()
    rows = {}
    for name in OBJECTS:
        obj = builtin(name)
        scene = Scene.table_under(np.asarray(obj.mesh.vertices)) if args.table else None
        plan(obj, options=PlanOptions(particles=4, iterations=1, neighborhood_size=2, max_grasps=1),
             rng=np.random.default_rng(99), scene=scene)
        t1, t5, n5, fc5 = [], [], [], []
        for seed in range(args.runs):
            for k, times in ((1, t1), (5, t5)):
                t0 = time.perf_counter()
                res = plan(obj, options=PlanOptions(max_grasps=k), rng=np.random.default_rng(seed), scene=scene)
                times.append(time.perf_counter() - t0)
                if k == 5:
                    n5.append(len(res.candidates))
                    fc5.append(sum(c.force_closure for c in res.candidates))
        m1, m5 = float(np.median(t1)), float(np.median(t5))
        rows[name] = {"one_s": m1, "five_s": m5, "ratio": m5 / m1, "candidates": float(np.median(n5)),
                      "force_closure": float(np.median(fc5)),
                      "verified_per_s": float(np.median(np.array(n5) / np.array(t5))),
                      "extra_per_s": float(np.median(n5) - 1) / max(m5 - m1, 1e-9),
                      "times_one_s": t1, "times_five_s": t5}
    print(f"| object | 1 grasp (s) | 5 grasps (s) | ratio | candidates | force closure | verified/s | "
          f"extra candidates/s |  ({'table' if args.table else 'free space'})")
    print("|---|---|---|---|---|---|---|---|")
    for name, r in rows.items():
        print(f"| {name} | {r['one_s']:.3f} | {r['five_s']:.3f} | {r['ratio']:.2f} | {r['candidates']:.0f} | "
              f"{r['force_closure']:.0f} | {r['verified_per_s']:.1f} | {r['extra_per_s']:.1f} |")
    out = REPO_ROOT / "bench" / "results" / ("candidates_table.json" if args.table else "candidates.json")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"runs": args.runs, "table": args.table, "objects": rows,
                               "load_before": load_before, "load_after": os.getloadavg()}, indent=1))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
