#!/usr/bin/env python3
"""Benchmark: plan time of general hands (Shadow, Inspire, Allegro-like) against the paper hand.

Rerunnable, not a test::

    .venv/bin/python bench/bench_any_hand.py                 # defaults: 3 runs, 4 objects
    .venv/bin/python bench/bench_any_hand.py --runs 1 --objects cube   # quick look

Each hand plans each object resting on a table (``Scene.table_under``) with the planner's
default options (``--grasps`` candidates, default 5), seeds 0..runs-1, in one process and one
run (so the ratios compare like with like on a shared machine). Hand loading and the
compiled kernels' warm-up are excluded (one plan per hand first, untimed). Reported: the
median plan time per hand and object, the median over all, and its ratio to the paper hand's
(target of issue 21: at most 2.5), plus the share of plans that returned a grasp. Prints a
Markdown table, writes ``bench/results/any_hand.json``. Needs the test hands
(``pip install --no-deps -r requirements-hands.txt``).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO_ROOT = Path(__file__).resolve().parents[1]
for p in (REPO_ROOT, REPO_ROOT / "test"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

from grasp_apso.errors import PlanningError  # noqa: E402
from grasp_apso.model.builtin import builtin  # noqa: E402
from grasp_apso.model.hands.load import load_hand  # noqa: E402
from grasp_apso.model.mesh_files import from_file  # noqa: E402
from grasp_apso.model.scene import Scene  # noqa: E402
from grasp_apso.search.planner import PlanOptions, plan, warm_up  # noqa: E402
from hand_files import installed_hand, write_allegro_like  # noqa: E402

TARGET_RATIO = 2.5


def _object(name: str):
    if name == "mug":
        return from_file(str(REPO_ROOT / "grasp_apso" / "data" / "meshes" / "mug.stl"))
    return builtin(name)


def _hands(names: list[str]) -> dict:
    out = {"paper": None}
    for name in names:
        if name == "allegro":
            out[name] = load_hand(write_allegro_like(Path(tempfile.mkdtemp()), "mixed"))
        else:
            out[name] = load_hand(installed_hand(name))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--objects", nargs="+", default=["cube", "sphere", "barrel", "mug"])
    parser.add_argument("--hands", nargs="+", default=["shadow", "inspire", "allegro"])
    parser.add_argument("--grasps", type=int, default=5)
    parser.add_argument("--out", default=str(REPO_ROOT / "bench" / "results" / "any_hand.json"))
    args = parser.parse_args(argv)
    warm_up()
    hands = _hands(args.hands)
    options = PlanOptions(max_grasps=args.grasps)
    objects = {name: _object(name) for name in args.objects}
    times: dict[str, dict[str, list[float]]] = {h: {o: [] for o in objects} for h in hands}
    returned: dict[str, list[bool]] = {h: [] for h in hands}
    for hand_name, hand in hands.items():
        cube = objects[args.objects[0]]
        table = Scene.table_under(np.asarray(cube.mesh.vertices))
        try:  # untimed: compiles or loads the kernels and the hand's tables
            plan(cube, options=PlanOptions(particles=4, iterations=1, neighborhood_size=2), hand=hand,
                 rng=np.random.default_rng(0), scene=table)
        except PlanningError:
            pass
        for obj_name, obj in objects.items():
            table = Scene.table_under(np.asarray(obj.mesh.vertices))
            for seed in range(args.runs):
                t0 = time.perf_counter()
                try:
                    plan(obj, options=options, rng=np.random.default_rng(seed), hand=hand, scene=table)
                    returned[hand_name].append(True)
                except PlanningError:
                    returned[hand_name].append(False)
                times[hand_name][obj_name].append(time.perf_counter() - t0)
    medians = {h: statistics.median([t for ts in times[h].values() for t in ts]) for h in hands}
    paper = medians["paper"]
    rows = []
    print("| hand | " + " | ".join(objects) + " | median (s) | / paper | returned |")
    print("|---|" + "---|" * (len(objects) + 3))
    for h in hands:
        per = [statistics.median(times[h][o]) for o in objects]
        ratio = medians[h] / paper
        rate = float(np.mean(returned[h]))
        rows.append({"hand": h, "per_object": dict(zip(objects, per)), "median": medians[h], "ratio": ratio,
                     "returned": rate, "times": times[h]})
        print(f"| {h} | " + " | ".join(f"{t:.2f}" for t in per) + f" | {medians[h]:.2f} | {ratio:.1f}x | "
              f"{rate * 100:.0f}% |")
    print(f"target: each hand within {TARGET_RATIO}x of the paper hand")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"runs": args.runs, "grasps": args.grasps, "target_ratio": TARGET_RATIO,
                               "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
