#!/usr/bin/env python3
"""Benchmark of the batch engines of ``grasp_apso_batch``: objects per minute with 1 and 2 local
worker processes, and the Ray engine against the local pool.

Rerunnable, not a test::

    .venv/bin/python bench/bench_batch.py              # about 5 minutes on 2 cores
    .venv/bin/python bench/bench_batch.py --runs 1 --particles 20 --iterations 10   # quick look

Objects: the four built-ins, the meshes in ``grasp_apso/data/meshes/*.stl`` when present, and
scaled copies of built-ins up to ``--objects`` (default 8) distinct meshes, exported to STL in
a temporary folder. Each run plans all of them into a fresh database (nothing skipped), with
the planner's default swarm and ``--grasps`` (5) candidates, seed 0. Throughput = objects /
the time from the engine being ready (workers started and warmed up) to the last result;
the wall time including the start-up is reported too. Medians of ``--runs`` (3) runs per
engine. Targets (issue 15): 2 workers / 1 worker >= 1.8; Ray (2 CPUs) / local pool (2
workers) >= 0.85. Prints a Markdown table, writes ``bench/results/batch.json``.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO_ROOT = Path(__file__).resolve().parents[1]
if str(REPO_ROOT) not in sys.path:
    sys.path.insert(0, str(REPO_ROOT))
os.environ["PYTHONPATH"] = os.pathsep.join([str(REPO_ROOT)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p])

from grasp_apso.database.batch import BatchConfig, run_batch  # noqa: E402
from grasp_apso.database.engines import SINGLE_THREAD_ENV  # noqa: E402
from grasp_apso.model.builtin import BUILTIN_OBJECTS, builtin  # noqa: E402
from grasp_apso.search.options import PlanOptions  # noqa: E402


def export_objects(folder: Path, n: int) -> list[str]:
    """Write ``n`` distinct meshes as STL; returns their paths."""
    paths = []
    for name in BUILTIN_OBJECTS:
        path = folder / f"{name}.stl"
        builtin(name).mesh.export(path)
        paths.append(str(path))
    paths += [str(p) for p in sorted((REPO_ROOT / "grasp_apso" / "data" / "meshes").glob("*.stl"))]
    k = 0
    while len(paths) < n:
        name = ("cube", "sphere", "barrel")[k % 3]
        mesh = builtin(name).mesh.copy()
        mesh.apply_scale(0.85 + 0.1 * (k // 3))
        path = folder / f"{name}_scaled{k}.stl"
        mesh.export(path)
        paths.append(str(path))
        k += 1
    return paths[:n]


def one_run(paths: list[str], folder: Path, label: str, i: int, options: PlanOptions, **kw) -> dict:
    out = folder / f"{label}-{i}.db"
    t0 = time.perf_counter()
    s = run_batch(paths, BatchConfig(out=str(out), options=options, seed=0, progress="none", **kw),
                  stream=open(os.devnull, "w"))
    wall = time.perf_counter() - t0
    done = s.planned + s.failed_in_workers
    return {"engine": label, "run": i, "planned": s.planned, "failed": s.failed, "grasps": s.grasps,
            "startup_s": s.startup_seconds, "work_s": s.work_seconds, "wall_s": wall,
            "objects_per_min": 60.0 * done / s.work_seconds if s.work_seconds else 0.0,
            "objects_per_min_wall": 60.0 * done / wall, "load_average_1min_after": os.getloadavg()[0]}


def _spin(seconds_of_work: int) -> float:
    """A fixed pure-compute load (numpy in one thread and a Python loop), seconds taken."""
    t = time.perf_counter()
    a = np.random.default_rng(0).random((300, 300))
    for _ in range(60):
        a = (a @ a.T) / 300.0
    s = 0
    for i in range(3_000_000):
        s += i * i
    return time.perf_counter() - t


def machine_scaling(repeats: int = 3) -> float:
    """What this machine gives two processes: the median over ``repeats`` of the time of 4
    fixed compute jobs on 1 process over the time on 2 (2.0 on two free physical cores;
    lower where the two CPUs share a core or the host is busy). The batch's ratio is
    bounded by it."""
    ctx = multiprocessing.get_context("spawn")
    os.environ.update(SINGLE_THREAD_ENV)  # as the batch's workers: one BLAS thread each
    ratios = []
    for _ in range(repeats):
        times = []
        for n in (1, 2):
            with ctx.Pool(n) as pool:
                t = time.perf_counter()
                pool.map(_spin, range(4))
                times.append(time.perf_counter() - t)
        ratios.append(times[0] / times[1])
    return statistics.median(ratios)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--objects", type=int, default=8)
    p.add_argument("--grasps", type=int, default=5)
    p.add_argument("--particles", type=int, default=None)
    p.add_argument("--iterations", type=int, default=None)
    p.add_argument("--no-ray", action="store_true", help="skip the Ray engine")
    p.add_argument("--out", default=str(REPO_ROOT / "bench" / "results" / "batch.json"))
    args = p.parse_args(argv)
    kw = {"max_grasps": args.grasps}
    if args.particles:
        kw.update(particles=args.particles, neighborhood_size=min(5, args.particles))
    if args.iterations:
        kw["iterations"] = args.iterations
    options = PlanOptions(**kw)
    engines = [("local-1", {"workers": 1}), ("local-2", {"workers": 2})]
    if not args.no_ray:
        engines.append(("ray-2", {"engine": "ray", "workers": 2}))
    load_before = list(os.getloadavg())
    t0 = time.perf_counter()
    ceiling = machine_scaling()
    print(f"[bench_batch] this machine runs 2 compute processes {ceiling:.2f}x as fast as 1", file=sys.stderr)
    runs: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="bench_batch_") as tmp:
        folder = Path(tmp)
        paths = export_objects(folder, args.objects)
        for i in range(args.runs):  # interleaved, so that a load change hits every engine alike
            for label, ekw in engines:
                r = one_run(paths, folder, label, i, options, **ekw)
                runs.append(r)
                print(f"[bench_batch] run {i} {label}: {r['planned']} planned, {r['objects_per_min']:.1f} obj/min "
                      f"(work {r['work_s']:.1f} s, start-up {r['startup_s']:.1f} s)", file=sys.stderr, flush=True)
    med = {}
    for label, _ in engines:
        rs = [r for r in runs if r["engine"] == label]
        med[label] = {k: statistics.median(r[k] for r in rs)
                      for k in ("objects_per_min", "objects_per_min_wall", "work_s", "startup_s", "wall_s")}
    ratios = {"local2_over_local1": med["local-2"]["objects_per_min"] / med["local-1"]["objects_per_min"]}
    if "ray-2" in med:
        ratios["ray_over_local2"] = med["ray-2"]["objects_per_min"] / med["local-2"]["objects_per_min"]
    print(f"\n{len(paths)} objects, {args.runs} runs, swarm {options.particles}x{options.iterations}, "
          f"{options.max_grasps} grasps; medians\n")
    print("| engine | objects/min (after start-up) | objects/min (wall) | work s | start-up s |")
    print("|---|---:|---:|---:|---:|")
    for label, m in med.items():
        print(f"| {label} | {m['objects_per_min']:.1f} | {m['objects_per_min_wall']:.1f} | "
              f"{m['work_s']:.1f} | {m['startup_s']:.1f} |")
    print()
    print(f"2 workers / 1 worker: {ratios['local2_over_local1']:.2f} (target >= 1.8; this machine's ceiling: "
          f"{ceiling:.2f}, a pure-compute load on 2 processes vs 1)")
    if "ray_over_local2" in ratios:
        print(f"Ray / local pool:     {ratios['ray_over_local2']:.2f} (target >= 0.85)")
    result = {"objects": [Path(x).name for x in paths], "options": {"particles": options.particles,
              "iterations": options.iterations, "max_grasps": options.max_grasps}, "runs": runs,
              "medians": med, "ratios": ratios, "machine_scaling_2_over_1": ceiling,
              "meta": {"cpus": os.cpu_count(), "load_average_before": load_before,
                       "load_average_after": list(os.getloadavg()), "wall_time_s": time.perf_counter() - t0,
                       "command": "python bench/bench_batch.py " + " ".join(sys.argv[1:] if argv is None else argv)}}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=1))
    print(f"-> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
