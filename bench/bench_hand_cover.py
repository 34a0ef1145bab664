#!/usr/bin/env python3
"""Benchmark of the link covers (grasp_apso.model.hands.spheres.cover_link): how many
spheres (or spheres and capsules) each link takes with a 2 mm stray, how far they stray,
what they leave uncovered, and how long the cover takes.

Rerunnable, not a test::

    python bench/bench_hand_cover.py                 # the test shapes, spheres and capsules
    python bench/bench_hand_cover.py --hands         # also every link of the test hands

The shapes are those of ``test/test_hand_spheres.py`` (a 20 x 27 x 54 mm box, a sphere,
a cylinder, a capsule, a convex and an L-shaped mesh, a capsule with a box) and a
palm-sized 100 x 90 x 20 mm box, placed at a seeded random pose. ``--hands`` loads the
paper's hand, the Allegro-like URDF and the installed third-party hands
(``test/hand_files.py``) and covers every link. Times are wall clock, the best of
``--runs`` (other processes on the machine disturb them).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "test")]

from grasp_apso.model.hands.geometry import LinkGeometry  # noqa: E402
from grasp_apso.model.hands.spheres import cover_link  # noqa: E402


def _timed(geoms, capsules: bool, runs: int):
    best, cover = np.inf, None
    for _ in range(runs):
        start = time.perf_counter()
        cover = cover_link(geoms, rng=np.random.default_rng(0), capsules=capsules)
        best = min(best, time.perf_counter() - start)
    return cover, best


def _row(name: str, cover, seconds: float) -> str:
    capsules = int(cover.is_capsule.sum())
    return (f"{name:34s} {cover.count:5d} {capsules:5d} {cover.max_stray * 1e3:7.2f} {cover.uncovered:9.4f}"
            f" {seconds:7.2f}")


def _shapes() -> dict:
    import test_hand_spheres as shapes

    out = dict(shapes._shapes(shapes.PLACEMENTS["placed"]))
    out["palm_box_100x90x20"] = [LinkGeometry("box", (0.05, 0.045, 0.01), shapes.PLACEMENTS["placed"])]
    return out


def _hands() -> dict:
    from hand_files import HANDS, installed_hand, write_allegro_like
    from grasp_apso.model.hands.load import load_hand

    files = {"paper": None, "allegro_like": write_allegro_like(Path(tempfile.mkdtemp()))}
    for name in HANDS:
        try:
            files[name] = installed_hand(name)
        except FileNotFoundError as exc:
            print(f"# {name}: {exc}")
    out = {}
    for name, path in files.items():
        hand = load_hand(path) if path else load_hand()
        for link, geoms in hand.collision.items():
            out[f"{name}:{link}"] = geoms
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hands", action="store_true", help="also every link of the test hands")
    parser.add_argument("--runs", type=int, default=3, help="timed runs per cover (the best is shown)")
    args = parser.parse_args(argv)
    cover_link([LinkGeometry("sphere", (0.01,))])  # compile the kernels outside the timings
    cases = _shapes()
    if args.hands:
        cases.update(_hands())
    for capsules in (False, True):
        print(f"\n{'spheres and capsules' if capsules else 'spheres only'} (stray allowed 2 mm, at most 256)")
        print(f"{'link':34s} {'count':>5s} {'caps':>5s} {'stray':>7s} {'uncovered':>9s} {'seconds':>7s}")
        total = 0
        for name, geoms in cases.items():
            cover, seconds = _timed(geoms, capsules, args.runs)
            total += cover.count
            print(_row(name, cover, seconds))
        print(f"{'total':34s} {total:5d}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
