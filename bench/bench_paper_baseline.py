#!/usr/bin/env python3
"""Benchmark: the paper hand's plan time on this code against the code before issue 21, in one run.

Rerunnable, not a test::

    .venv/bin/python bench/bench_paper_baseline.py                      # 5 runs, 4 objects
    .venv/bin/python bench/bench_paper_baseline.py --runs 3 --objects all
    .venv/bin/python bench/bench_paper_baseline.py --baseline <rev>     # another reference
    .venv/bin/python bench/bench_paper_baseline.py --general-baseline <rev>  # + <rev>'s general path

Issue 21 holds the paper hand's plans (5 candidates, on a table) within 1.2x of their time
before the issue, measured against a worktree of that code. The reference is ``--baseline``
(default :data:`ISSUE_21_BASE`, the merge of issue 20 on which issue 21's work began),
checked out as a detached ``git worktree`` in a temporary folder and removed at the end.

Worker processes plan on request, each on one tree (``PYTHONPATH`` the tree, the same
interpreter and packages): the paper hand's own path on the reference, its own path on this
code, and (unless ``--own-path-only``) its URDF, ``urdf/apso_paper_hand.urdf``, on this
code's general path, the one search path issue 21 asks for; with ``--general-baseline
REV`` also REV's URDF on REV's general path (a second worktree), so that a change of the
general path is measured against an earlier one in the same run (the ratio and the plans
with the same best grasp printed below the table). The driver sends every
(object, seed) to each in turn, rotating which goes first, so that a shared machine's load
falls on all alike. Each plan: the object resting on a table (``Scene.table_under``), the
planner's default options with ``--grasps`` candidates, ``np.random.default_rng(seed)``.
Untimed first: the compiled kernels (the reference tree compiles its own on its first run)
and one small plan per object (its grids). Object-major, as ``bench/bench_any_hand.py``.

Reported per worker: the median wall time per object and over all plans, the ratios of the
median wall and process-CPU times to the reference's (target at most :data:`TARGET_RATIO`),
candidates per plan, and in how many plans the best grasp is the reference's (the same
number of candidates, fitness and epsilon equal to 1e-9). Prints a Markdown table, writes
JSON (``--out``, default ``bench/results/paper_baseline.json``).
"""

from __future__ import annotations

import argparse
import json
import select
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from held_rate import BUILTINS, MESH_DIR, mesh_names  # noqa: E402  (bench/, the script's folder)
from tables import markdown_table  # noqa: E402

#: The code before issue 21: issue 20 (any hand from its file) merged, issue 21 not begun.
ISSUE_21_BASE = "31f510a"
TARGET_RATIO = 1.2

#: Runs in each tree: reads one JSON request per line, answers one JSON line.
WORKER = r"""
import json, sys, time
import numpy as np
from grasp_apso.model.builtin import builtin
from grasp_apso.model.mesh_files import from_file
from grasp_apso.model.scene import Scene
from grasp_apso.search.planner import PlanOptions, plan, warm_up
from grasp_apso.errors import PlanningError

warm_up()
hand = None
if len(sys.argv) > 1:  # a description file planned on the general path
    from grasp_apso.model.hands.load import load_hand
    hand = load_hand(sys.argv[1])
objects = {}
print(json.dumps({"ready": True}), flush=True)
for line in sys.stdin:
    req = json.loads(line)
    name = req["object"]
    if name not in objects:
        obj = builtin(name) if req["builtin"] else from_file(req["path"])
        objects[name] = (obj, Scene.table_under(np.asarray(obj.mesh.vertices)))
    obj, table = objects[name]
    if req.get("warm"):
        options = PlanOptions(particles=4, iterations=1, neighborhood_size=2)
    else:
        options = PlanOptions(max_grasps=req["grasps"])
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        result = plan(obj, options=options, rng=np.random.default_rng(req["seed"]), scene=table, hand=hand)
        cands = result.candidates
    except PlanningError:
        cands = ()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    best = cands[0] if cands else None
    print(json.dumps({"wall": wall, "cpu": cpu, "candidates": len(cands),
                      "fitness": None if best is None else float(best.fitness),
                      "epsilon": None if best is None else float(best.epsilon)}), flush=True)
"""


#: Bounds on a worker's replies (s): its start (a tree's first run compiles its kernels)
#: and one plan.
START_TIMEOUT = 900.0
PLAN_TIMEOUT = 300.0


class Worker:
    """One planning process on one source tree; every wait for a reply is bounded."""

    def __init__(self, tree: Path, hand_file: Path | None = None):
        env = {"PYTHONPATH": str(tree), "PATH": "/usr/bin:/bin", "HOME": str(Path.home()),
               "NUMBA_NUM_THREADS": "1"}
        argv = [sys.executable, "-c", WORKER] + ([str(hand_file)] if hand_file else [])
        self.proc = subprocess.Popen(argv, cwd=tree, env=env, text=True,
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE)
        self._read(START_TIMEOUT)  # ready: the kernels loaded (compiled on a tree's first run)

    def _read(self, timeout: float) -> dict:
        ready, _, _ = select.select([self.proc.stdout], [], [], timeout)
        if not ready:
            self.proc.kill()
            raise RuntimeError(f"worker gave no reply within {timeout:.0f} s")
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError(f"worker exited with status {self.proc.wait()}")
        return json.loads(line)

    def plan(self, request: dict) -> dict:
        self.proc.stdin.write(json.dumps(request) + "\n")
        self.proc.stdin.flush()
        return self._read(PLAN_TIMEOUT)

    def close(self) -> None:
        try:
            self.proc.stdin.close()  # the worker ends at the end of its input
        except OSError:  # it has exited already
            pass
        try:
            self.proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def _requests(names: list[str]) -> dict:
    return {n: {"object": n, "builtin": n in BUILTINS, "path": str(MESH_DIR / f"{n}.stl")} for n in names}


def run(trees: dict[str, tuple], objects: list[str], runs: int, grasps: int) -> dict:
    """Every (object, seed) planned once by each worker (label -> (tree, hand file or
    None)); per worker the replies."""
    workers = {}
    try:
        for label, (tree, hand_file) in trees.items():
            workers[label] = Worker(tree, hand_file)
        requests = _requests(objects)
        rec = {label: {o: [] for o in objects} for label in trees}
        order = list(workers)
        for name in objects:
            for w in workers.values():
                w.plan(dict(requests[name], seed=0, warm=True, grasps=grasps))
            for seed in range(runs):
                for label in order:
                    rec[label][name].append(workers[label].plan(dict(requests[name], seed=seed, grasps=grasps)))
                order = order[1:] + order[:1]  # rotate which worker plans first
        return rec
    finally:
        for w in workers.values():
            w.close()


#: The workers' labels: the paper hand's own path on the reference, on this code, and its
#: URDF (``urdf/apso_paper_hand.urdf``) on this code's general path (issue 21's one path).
BASE, OWN, GENERAL = "baseline", "this code", "this code, general path"
#: With ``--general-baseline``: the URDF on the general path of an earlier revision too.
GENERAL_BASE = "general baseline"
NAMES = {BASE: "before issue 21 ({rev}), own path", OWN: "this code, own path",
         GENERAL: "this code, its URDF on the general path", GENERAL_BASE: "{grev}, its URDF on the general path"}


def _same_best(a: dict, b: dict) -> bool:
    """The same number of candidates and the same best grasp (fitness and epsilon to 1e-9)."""
    if a["candidates"] != b["candidates"] or (a["fitness"] is None) != (b["fitness"] is None):
        return False
    return a["fitness"] is None or (abs(a["fitness"] - b["fitness"]) < 1e-9 and abs(a["epsilon"] - b["epsilon"]) < 1e-9)


def summarise(rec: dict, objects: list[str]) -> dict:
    """Per worker: medians per object and over all plans, ratios to the reference."""
    def walls(label):
        return [r["wall"] for o in objects for r in rec[label][o]]

    def cpus(label):
        return [r["cpu"] for o in objects for r in rec[label][o]]

    base_wall, base_cpu = statistics.median(walls(BASE)), statistics.median(cpus(BASE))
    out = {"plans": len(walls(BASE)), "workers": {}}
    for label in rec:
        out["workers"][label] = {
            "per_object": {o: statistics.median(r["wall"] for r in rec[label][o]) for o in objects},
            "median": statistics.median(walls(label)), "cpu_median": statistics.median(cpus(label)),
            "ratio": statistics.median(walls(label)) / base_wall, "cpu_ratio": statistics.median(cpus(label)) / base_cpu,
            "candidates_per_plan": statistics.mean(r["candidates"] for o in objects for r in rec[label][o]),
            "same_best": sum(_same_best(a, b) for o in objects for a, b in zip(rec[label][o], rec[BASE][o])),
        }
    if GENERAL_BASE in rec and GENERAL in rec:
        g, gb = out["workers"][GENERAL], out["workers"][GENERAL_BASE]
        out["general_vs_general_baseline"] = {
            "ratio": g["median"] / gb["median"], "cpu_ratio": g["cpu_median"] / gb["cpu_median"],
            "same_best": sum(_same_best(a, b) for o in objects for a, b in zip(rec[GENERAL][o], rec[GENERAL_BASE][o]))}
    return out


def table(s: dict, objects: list[str], rev: str, grev: str = "") -> str:
    header = ["paper hand", *objects, "median (s)", "/ before", "CPU / before", "cand./plan", "same best grasp as before"]
    return markdown_table(header, [
        [NAMES[label].format(rev=rev, grev=grev), *(f"{w['per_object'][o]:.3f}" for o in objects), f"{w['median']:.3f}",
         f"{w['ratio']:.2f}x", f"{w['cpu_ratio']:.2f}x", f"{w['candidates_per_plan']:.1f}", f"{w['same_best']}/{s['plans']}"]
        for label, w in s["workers"].items()])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--baseline", default=ISSUE_21_BASE, help=f"git revision to compare with (default {ISSUE_21_BASE})")
    parser.add_argument("--runs", type=int, default=5, help="seeds per object")
    parser.add_argument("--objects", nargs="+", default=["cube", "sphere", "barrel", "mug"],
                        help="built-in objects and shipped meshes by name; 'all': every one of them")
    parser.add_argument("--grasps", type=int, default=5)
    parser.add_argument("--own-path-only", action="store_true",
                        help="leave out the paper hand's URDF on the general path")
    parser.add_argument("--general-baseline", metavar="REV",
                        help="also plan the URDF on the general path of this earlier revision (one that has it), "
                             "to measure a change of the general path in the same run")
    parser.add_argument("--out", default=str(REPO_ROOT / "bench" / "results" / "paper_baseline.json"))
    args = parser.parse_args(argv)
    if args.runs < 1:
        parser.error("--runs: at least 1")
    objects = args.objects
    if objects == ["all"]:
        objects = list(BUILTINS) + mesh_names()
    if args.general_baseline and args.own_path_only:
        parser.error("--general-baseline: the general path is left out by --own-path-only")

    def short(revision: str) -> str:
        return subprocess.run(["git", "-C", str(REPO_ROOT), "rev-parse", "--short", revision], check=True,
                              capture_output=True, text=True).stdout.strip()

    rev = short(args.baseline)
    grev = short(args.general_baseline) if args.general_baseline else ""
    urdf = REPO_ROOT / "urdf" / "apso_paper_hand.urdf"
    with tempfile.TemporaryDirectory(prefix="grasp_apso_baseline_") as tmp:
        trees = {rev: Path(tmp) / "tree", **({grev: Path(tmp) / "general"} if grev else {})}
        try:
            for revision, tree in trees.items():
                subprocess.run(["git", "-C", str(REPO_ROOT), "worktree", "add", "--detach", str(tree), revision],
                               check=True, capture_output=True)
            workers = {BASE: (trees[rev], None), OWN: (REPO_ROOT, None)}
            if not args.own_path_only:
                workers[GENERAL] = (REPO_ROOT, urdf)
            if grev:
                workers[GENERAL_BASE] = (trees[grev], trees[grev] / "urdf" / "apso_paper_hand.urdf")
            rec = run(workers, objects, args.runs, args.grasps)
        finally:
            for tree in trees.values():
                subprocess.run(["git", "-C", str(REPO_ROOT), "worktree", "remove", "--force", str(tree)],
                               capture_output=True)
    s = summarise(rec, objects)
    print(table(s, objects, rev, grev))
    if "general_vs_general_baseline" in s:
        g = s["general_vs_general_baseline"]
        print(f"the general path against {grev}'s: {g['ratio']:.3f}x wall, {g['cpu_ratio']:.3f}x CPU (medians), "
              f"the same best grasp in {g['same_best']} of {s['plans']} plans")
    print(f"{args.runs} run(s) per object, {s['plans']} plans per worker, medians; target: the paper hand "
          f"within {TARGET_RATIO}x of its time before issue 21 ({rev})")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"command": " ".join(sys.argv), "baseline": rev, "general_baseline": grev or None,
                               "runs": args.runs,
                               "grasps": args.grasps, "objects": objects, "target_ratio": TARGET_RATIO,
                               "summary": s, "plans": rec}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
