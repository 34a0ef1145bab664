#!/usr/bin/env python3
"""Benchmark: plan time and plan quality of general hands against the paper hand, in one run.

Rerunnable, not a test::

    .venv/bin/python bench/bench_any_hand.py                 # defaults: 3 runs, 4 objects
    .venv/bin/python bench/bench_any_hand.py --runs 1 --objects cube   # quick look
    .venv/bin/python bench/bench_any_hand.py --runs 2 --objects all --hands /path/to/leap_hand_right.urdf  # 21 objects
    .venv/bin/python bench/bench_any_hand.py --hands shadow inspire allegro_like \\
        /path/to/allegro_hand_right.urdf /path/to/leap_hand_right.urdf   # other hands' files too

Hands: the paper hand always; ``--hands`` names of the test hands (``shadow``, ``inspire``,
``allegro_like``: :mod:`test.hand_files`) or paths of description files (URDF / MJCF,
named by their file stem). Each hand plans each object resting on a table
(``Scene.table_under``) with the planner's default options (``--grasps`` candidates,
default 5), seeds 0..runs-1. The plans are interleaved (object, seed, then every hand in
turn), so that a shared machine's load falls on every hand alike; hand loading, the
compiled kernels' warm-up and the object's grids are excluded (one untimed plan per hand
and object first). Object-major, so that no timed plan rebuilds an object's grids
however many objects are planned (the object caches hold ``CACHE_LIMITS``' count).

Reported per hand: the median wall time per object and over all plans, its ratio to the
paper hand's (target of issue 21: at most 2.5), the median process CPU time's ratio (less
sensitive to other processes on the machine), and the quality: the share of plans that
returned a grasp, candidates per plan, the share of candidates and of best grasps in force
closure. Prints a Markdown table, writes JSON (``--out``, default
``bench/results/any_hand.json``). Needs the test hands
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
from grasp_apso.model.builtin import BUILTIN_OBJECTS  # noqa: E402
from grasp_apso.model.hands.load import load_hand  # noqa: E402
from grasp_apso.model.scene import Scene  # noqa: E402
from grasp_apso.search.planner import PlanOptions, plan, warm_up  # noqa: E402
from hand_files import installed_hand, write_allegro_like  # noqa: E402
from held_rate import load as _object, mesh_names  # noqa: E402  (bench/, the script's folder)
from tables import markdown_table  # noqa: E402

TARGET_RATIO = 2.5
DEFAULT_HANDS = ["shadow", "inspire", "allegro_like"]


def _object_names(names: list[str]) -> list[str]:
    """``all``: the built-ins and every shipped mesh, as ``bench/held_rate.py`` plans them."""
    return list(BUILTIN_OBJECTS) + mesh_names() if names == ["all"] else names


def _hands(names: list[str]) -> dict:
    """name -> HandModel (None: the paper hand's own path)."""
    out = {"paper": None}
    for name in names:
        path = Path(name)
        if path.suffix in (".urdf", ".xml") and path.exists():
            out[path.stem] = load_hand(path)
        elif name in ("allegro", "allegro_like"):
            out["allegro_like"] = load_hand(write_allegro_like(Path(tempfile.mkdtemp()), "mixed"))
        else:
            out[name] = load_hand(installed_hand(name))
    return out


def _plan_once(obj, hand, options: PlanOptions, seed: int, table) -> tuple[float, float, object | None]:
    """(wall s, process CPU s, GraspResult or None when no grasp)."""
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        result = plan(obj, options=options, rng=np.random.default_rng(seed), hand=hand, scene=table)
    except PlanningError:
        result = None
    return time.perf_counter() - t0, time.process_time() - c0, result


def run(hands: dict, objects: dict, runs: int, grasps: int) -> dict:
    """Plan every (seed, object, hand) once; per hand the times and quality records."""
    options = PlanOptions(max_grasps=grasps)
    warm = PlanOptions(particles=4, iterations=1, neighborhood_size=2)
    tables = {name: Scene.table_under(np.asarray(obj.mesh.vertices)) for name, obj in objects.items()}
    rec = {h: {"wall": {o: [] for o in objects}, "cpu": [], "returned": [], "candidates": [], "fc": [],
               "best_fc": []} for h in hands}
    # Object-major: the object caches (signed-distance grid, BVH) are bounded
    # (grasp_apso.cache.CACHE_LIMITS), and a seed-major order over more objects than they
    # hold would time their rebuilds in every plan.
    for obj_name, obj in objects.items():
        for hand in hands.values():  # untimed: kernels, the hand's tables, the object's grids
            _plan_once(obj, hand, warm, 0, tables[obj_name])
        for seed in range(runs):
            for hand_name, hand in hands.items():
                wall, cpu, result = _plan_once(obj, hand, options, seed, tables[obj_name])
                r = rec[hand_name]
                r["wall"][obj_name].append(wall)
                r["cpu"].append(cpu)
                r["returned"].append(result is not None)
                cands = () if result is None else result.candidates
                r["candidates"].append(len(cands))
                r["fc"].extend(bool(c.force_closure) for c in cands)
                r["best_fc"].append(bool(cands) and bool(cands[0].force_closure))
    return rec


def summarise(rec: dict, objects: list[str]) -> list[dict]:
    """Per hand: medians, ratios to the paper hand, quality rates."""
    def wall_all(h):
        return [t for ts in rec[h]["wall"].values() for t in ts]

    paper_wall, paper_cpu = statistics.median(wall_all("paper")), statistics.median(rec["paper"]["cpu"])
    rows = []
    for h, r in rec.items():
        median = statistics.median(wall_all(h))
        cpu = statistics.median(r["cpu"])
        rows.append({
            "hand": h, "per_object": {o: statistics.median(r["wall"][o]) for o in objects}, "median": median,
            "mean": statistics.mean(wall_all(h)),
            "ratio": median / paper_wall, "cpu_median": cpu, "cpu_ratio": cpu / paper_cpu,
            "returned": float(np.mean(r["returned"])), "candidates_per_plan": float(np.mean(r["candidates"])),
            "candidate_fc": float(np.mean(r["fc"])) if r["fc"] else 0.0, "best_fc": float(np.mean(r["best_fc"])),
            "plans": len(r["cpu"]), "times": r["wall"], "cpu_times": r["cpu"]})
    return rows


def table(rows: list[dict], objects: list[str]) -> str:
    header = ["hand", *objects, "median (s)", "mean (s)", "/ paper", "CPU / paper", "returned", "cand./plan",
              "cand. FC", "best FC"]
    return markdown_table(header, [
        [r["hand"], *(f"{r['per_object'][o]:.2f}" for o in objects), f"{r['median']:.2f}", f"{r['mean']:.2f}",
         f"{r['ratio']:.1f}x", f"{r['cpu_ratio']:.1f}x", f"{r['returned'] * 100:.0f}%",
         f"{r['candidates_per_plan']:.1f}", f"{r['candidate_fc'] * 100:.0f}%", f"{r['best_fc'] * 100:.0f}%"]
        for r in rows])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=3, help="seeds per hand and object")
    parser.add_argument("--objects", nargs="+", default=["cube", "sphere", "barrel", "mug"],
                        help="built-in objects and shipped meshes by name; 'all': every one of them")
    parser.add_argument("--hands", nargs="+", default=DEFAULT_HANDS,
                        help="test hand names (shadow, inspire, allegro_like) or URDF / MJCF paths")
    parser.add_argument("--grasps", type=int, default=5)
    parser.add_argument("--out", default=str(REPO_ROOT / "bench" / "results" / "any_hand.json"))
    args = parser.parse_args(argv)
    if args.runs < 1:
        parser.error("--runs: at least 1")
    warm_up()
    hands = _hands(args.hands)
    objects = {name: _object(name) for name in _object_names(args.objects)}
    rows = summarise(run(hands, objects, args.runs, args.grasps), list(objects))
    print(table(rows, list(objects)))
    print(f"{args.runs} run(s) per hand and object; medians; target: each hand within {TARGET_RATIO}x of the paper hand")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"command": " ".join(sys.argv), "runs": args.runs, "grasps": args.grasps,
                               "objects": list(objects), "target_ratio": TARGET_RATIO, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
