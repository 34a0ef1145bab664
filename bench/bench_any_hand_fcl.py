#!/usr/bin/env python3
"""Benchmark: the python-fcl checks of any hand (grasp_apso.geometry.any_hand_fcl, issue 21).

Rerunnable, not a test::

    .venv/bin/python bench/bench_any_hand_fcl.py              # Shadow and Allegro-like hands
    .venv/bin/python bench/bench_any_hand_fcl.py --hands shadow --rounds 9

Per hand, the open hand with its palm facing an 8 cm ball (convex) or the mug (non-convex,
2,838 triangles), 1 cm away and pressing 0.5 mm in: ``object_report``; a table under the
hand: ``scene_distance``; an 8 cm approach (17 poses) with the table and the object:
``approach_report``; and the forward kinematics alone. Prints a Markdown table of the best
and the median microseconds per call over ``--rounds`` rounds of ``--reps`` calls (the
best is the least disturbed by a shared machine). Caches warmed first.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import trimesh

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO_ROOT), str(REPO_ROOT / "test")]

from grasp_apso.geometry.any_hand_fcl import HandCollision, approach_report, object_report, scene_distance  # noqa: E402
from grasp_apso.model.hands.load import load_hand  # noqa: E402
from grasp_apso.model.objects import from_arrays  # noqa: E402
from grasp_apso.model.scene import Scene  # noqa: E402
from hand_files import installed_hand, write_allegro_like  # noqa: E402


def _time(fn, reps: int, rounds: int) -> tuple[float, float]:
    fn()
    out = []
    for _ in range(rounds):
        start = time.perf_counter()
        for _ in range(reps):
            fn()
        out.append((time.perf_counter() - start) / reps * 1e6)
    return float(min(out)), float(np.median(out))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hands", nargs="+", default=["shadow", "allegro"])
    parser.add_argument("--reps", type=int, default=10)
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args(argv)
    mug = trimesh.load(REPO_ROOT / "grasp_apso" / "data" / "meshes" / "mug.stl")
    ball = trimesh.creation.icosphere(subdivisions=4, radius=0.04)
    objects = {"ball": from_arrays(ball.vertices, ball.faces, "ball"), "mug": from_arrays(mug.vertices, mug.faces, "mug")}
    print("| hand | call | best us | median us |\n| --- | --- | ---: | ---: |")
    with tempfile.TemporaryDirectory() as folder:
        for name in args.hands:
            path = write_allegro_like(folder, "mixed") if name == "allegro" else installed_hand(name)
            hand = load_hand(path, spheres=False)
            hc = HandCollision(hand)
            q = hand.open_configuration()
            normal = np.asarray(hand.palm_normal, dtype=float)
            palm = np.vstack([g.to_trimesh().vertices for g in hand.collision[hand.root_link]])
            front = palm[np.argmax(palm @ normal)]
            rows = [("forward kinematics + part poses", lambda: hc.part_poses(q, np.eye(4)))]
            for oname, obj in objects.items():
                mesh = obj.mesh
                centre = 0.5 * (mesh.bounds[0] + mesh.bounds[1])
                half = float(np.abs((mesh.vertices - centre) @ normal).max())  # the object's reach along the normal
                for gap in (0.01, -0.0005):
                    root = np.eye(4)
                    root[:3, 3] = centre - (front + normal * (half + gap))
                    rows.append((f"object_report, {oname} {gap * 1000:+.1f} mm",
                                 lambda r=root, o=obj: object_report(hc, q, r, o)))
                obj_pose = np.linalg.inv(root)
                table = Scene.from_primitives(planes=[(0.0, 0.0, 1.0, 0.3)])
                rows.append((f"approach_report 8 cm, table + {oname}",
                             lambda p=obj_pose, o=obj, t=table: approach_report(hc, q, np.eye(4), normal, 0.08, t, o, p,
                                                                                clearance=0.005)))
            table = Scene.from_primitives(planes=[(0.0, 0.0, 1.0, 0.3)])
            rows.append(("scene_distance, table", lambda: scene_distance(hc, q, np.eye(4), table)))
            for label, fn in rows:
                reps = max(1, args.reps // 4) if label.startswith("approach") else args.reps
                best, median = _time(fn, reps, args.rounds)
                print(f"| {name} | {label} | {best:.0f} | {median:.0f} |")


if __name__ == "__main__":
    main()
