#!/usr/bin/env python3
"""Benchmark of the geometric core: object preparation (signed-distance grid, cold) and
particle decoding (``grasp_apso.geometry.decoder.decode``) on 60-particle batches.

Rerunnable, not a test::

    python bench/bench_decode.py                      # all built-in objects + a 10k-triangle capsule
    python bench/bench_decode.py --repetitions 50 --objects sphere cube

For each object:

* prep: ``make_grasp_model(hand, obj)`` with the grid cache cleared
  (the named cache ``"sdf_grid"`` of ``grasp_apso.cache``), i.e. the cold grid build a first plan on a new mesh pays;
  the best of ``--prep-runs`` runs (least disturbed by other processes);
* decode: ``decode(model, x)`` on GRG-like batches (random wrist angles and pivots, flexion
  pre-shapes in the lower third of their range, standoff offset 0..2 cm; seeded), after
  ``--warmup`` untimed calls, ``--repetitions`` timed calls, each on its own batch.

Prints a table and writes JSON (default ``bench/results/decode.json``). Timings are wall
clock (``time.perf_counter``); other processes on the machine disturb them, so the JSON
records the load average before and after the run.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
if str(REPO_ROOT) not in sys.path:
    sys.path.insert(0, str(REPO_ROOT))

import numpy as np  # noqa: E402
import trimesh  # noqa: E402

from grasp_apso.cache import clear_caches  # noqa: E402
from grasp_apso.geometry.decoder import N_DIMS, STANDOFF_INDEX, decode, make_grasp_model  # noqa: E402
from grasp_apso.model.hand import load_hand  # noqa: E402
from grasp_apso.model.objects import from_arrays
from grasp_apso.model.builtin import BUILTIN_OBJECTS, builtin# noqa: E402

FLEXION_COLUMNS = [3 * f + j for f in range(5) for j in (0, 1)]
CAPSULE_NAME = "capsule_10k"


def capsule_10k():
    """A closed capsule of exactly 10,000 triangles (radius 2 cm, length 12 cm)."""
    mesh = trimesh.creation.capsule(height=0.08, radius=0.02, count=[100, 50])
    return from_arrays(np.asarray(mesh.vertices), np.asarray(mesh.faces), name=CAPSULE_NAME)


def grg_like_batch(model, n: int, rng: np.random.Generator) -> np.ndarray:
    lo, hi = np.asarray(model.lower), np.asarray(model.upper)
    x = rng.uniform(lo, hi, size=(n, N_DIMS))
    for k in FLEXION_COLUMNS:
        x[:, k] = rng.uniform(lo[k], lo[k] + (hi[k] - lo[k]) / 3.0, size=n)
    x[:, STANDOFF_INDEX] = rng.uniform(0.0, 0.02, size=n)
    return x


def time_prep(hand, obj, runs: int):
    times = []
    model = None
    for _ in range(runs):
        clear_caches("sdf_grid")
        t0 = time.perf_counter()
        model = make_grasp_model(hand, obj)
        times.append(time.perf_counter() - t0)
    return model, min(times), times


def time_decode(model, batch: int, warmup: int, repetitions: int, seed: int) -> tuple[np.ndarray, dict]:
    rng = np.random.default_rng(seed)
    batches = [grg_like_batch(model, batch, rng) for _ in range(warmup + repetitions)]
    for x in batches[:warmup]:
        decode(model, x)
    times = np.empty(repetitions)
    contacts = 0
    legal = 0
    for r, x in enumerate(batches[warmup:]):
        t0 = time.perf_counter()
        decoded = decode(model, x)
        times[r] = time.perf_counter() - t0
        contacts += int(decoded.n_contacts.sum())
        legal += int(decoded.legal(model.settings.max_penetration).sum())
    n = repetitions * batch
    return times, {"mean_contacts": contacts / n, "legal_fraction": legal / n}


def git_commit() -> str | None:
    try:
        out = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=REPO_ROOT, capture_output=True, text=True, timeout=10
        )
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--", "grasp_apso"], cwd=REPO_ROOT, capture_output=True, text=True,
            timeout=10,
        )
        return out.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "") if out.returncode == 0 else None
    except (OSError, subprocess.SubprocessError):
        return None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--objects", nargs="+", default=[*BUILTIN_OBJECTS, CAPSULE_NAME],
                        choices=[*BUILTIN_OBJECTS, CAPSULE_NAME])
    parser.add_argument("--batch", type=int, default=60, help="particles per decode call (default 60)")
    parser.add_argument("--repetitions", type=int, default=200, help="timed decode calls per object")
    parser.add_argument("--warmup", type=int, default=10, help="untimed decode calls first")
    parser.add_argument("--prep-runs", type=int, default=3, help="cold preparations per object (best kept)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--output", type=Path, default=REPO_ROOT / "bench" / "results" / "decode.json")
    args = parser.parse_args(argv)
    if args.batch < 1 or args.repetitions < 1 or args.warmup < 0 or args.prep_runs < 1:
        parser.error("batch, repetitions and prep-runs must be >= 1, warmup >= 0")

    hand = load_hand()
    load_before = os.getloadavg()
    rows = []
    header = (f"{'object':<12} {'triangles':>9} {'grid shape':>14} {'spacing mm':>10} {'prep ms':>8} "
              f"{'decode med ms':>13} {'p90 ms':>7} {'particles/s':>11} {'contacts':>8} {'legal':>6}")
    print(f"decode benchmark: batch {args.batch}, {args.repetitions} repetitions after {args.warmup} "
          f"warm-up, seed {args.seed}; load average {load_before[0]:.2f}")
    print(header)
    print("-" * len(header))
    for i, name in enumerate(args.objects):
        obj = capsule_10k() if name == CAPSULE_NAME else builtin(name)
        model, prep, prep_all = time_prep(hand, obj, args.prep_runs)
        times, stats = time_decode(model, args.batch, args.warmup, args.repetitions, args.seed + i)
        median, p90 = float(np.median(times)), float(np.percentile(times, 90))
        row = {
            "object": name,
            "triangles": int(len(obj.mesh.faces)),
            "grid_shape": list(model.sdf.shape),
            "grid_nodes": int(np.prod(model.sdf.shape)),
            "spacing_mm": 1e3 * model.sdf.spacing,
            "prep_ms": 1e3 * prep,
            "prep_runs_ms": [1e3 * t for t in prep_all],
            "decode_median_ms": 1e3 * median,
            "decode_p90_ms": 1e3 * p90,
            "decode_min_ms": 1e3 * float(times.min()),
            "decode_mean_ms": 1e3 * float(times.mean()),
            "particles_per_s": args.batch / median,
            **stats,
        }
        rows.append(row)
        shape = "x".join(str(s) for s in row["grid_shape"])
        print(f"{name:<12} {row['triangles']:>9} {shape:>14} {row['spacing_mm']:>10.2f} {row['prep_ms']:>8.0f} "
              f"{row['decode_median_ms']:>13.2f} {row['decode_p90_ms']:>7.2f} {row['particles_per_s']:>11.0f} "
              f"{row['mean_contacts']:>8.2f} {row['legal_fraction']:>6.2f}")
    load_after = os.getloadavg()
    print(f"load average after: {load_after[0]:.2f} (other processes share the {os.cpu_count()} cores)")

    result = {
        "benchmark": "grasp_apso.geometry.decoder.decode",
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "git_commit": git_commit(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "machine": platform.machine(),
        "cpu_count": os.cpu_count(),
        "load_average_before": load_before,
        "load_average_after": load_after,
        "settings": {"batch": args.batch, "repetitions": args.repetitions, "warmup": args.warmup,
                     "prep_runs": args.prep_runs, "seed": args.seed},
        "rows": rows,
    }
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
