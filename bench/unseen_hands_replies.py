#!/usr/bin/env python3
"""The replies of the node and the CLI for hands the tests have never seen, checked independently.

Issue 21 judges hands "planned through the node and the CLI on objects resting on a table".
``bench/unseen_hands.py`` checks the library's candidates; this script asks the real entry
points and checks what they answer, as a user of them receives it::

    .venv/bin/python bench/unseen_hands_replies.py --quick --hands my_hand.urdf
    .venv/bin/python bench/unseen_hands_replies.py --quick --via node --objects cube mug

- ``node``: ``python -m grasp_apso.ros.node`` in its own process (DDS domain of its own,
  discovery on localhost) with ``hand_description`` the file, ``allowed_mesh_dir`` the
  shipped meshes; this process calls ``~/plan_grasp`` with the object (a built-in by
  ``object_name``, a mesh by ``mesh_uri``) at the identity pose and the table as a
  ``support_planes`` entry under its lowest point, ``max_grasps`` 5, the seed. Each of the
  reply's ``grasps`` is read from the message alone: ``grasp_pose`` (the root link),
  ``grasp_posture`` and ``pre_grasp_posture`` (by joint name), ``contact_points`` and
  ``contact_fingers``, ``force_closure``.
- ``cli``: ``python -m grasp_apso.tools.cli --hand FILE --mesh M | --object NAME --table
  --grasps 5 --seed S --json OUT`` in a new process each; the candidates read from the JSON
  (``joint_names``, each candidate's ``joint_positions``, ``pre_grasp_positions``,
  ``wrist_pose.matrix``, ``contacts``), the table from its ``scene.support_planes``.

Every candidate then goes through the independent checks of ``bench/unseen_hands.py`` (the
URDF read again with yourdfpy, python-fcl on its collision geometry: ``table``, ``limits``,
``pads``, ``depth``, ``on_pad``, ``surface``) and one more, ``names``: the reply's joint names are the
movable joints of the URDF below the root link (the frame of ``grasp_pose``) that are not
mimic followers, each once. Prints per hand and
entry point the plans with a grasp and the candidates passing each check, and in how many
plans the node and the CLI answered the same grasps (the same seed, object and table, each
with its defaults: one planner behind both); writes
``bench/results/unseen_hands_replies.json``. URDFs only (the checks read the file with
yourdfpy); by default the seven dex-urdf right hands when ``/work/extern/dex-urdf`` holds
them.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from unseen_hands import (BUILTINS, CHECKS, DEX, INFO, MESH_DIR, OBJECTS, REPO, IndependentHand,  # noqa: E402
                          check_candidate, hand_files, load_object, object_collision, table_object,
                          write_results)

VIAS = ("node", "cli")
#: Bounds (s): the node's start (a new hand's covers are built on its first load) and one
#: reply; one CLI run (its start, the hand's load and the plan).
NODE_START = 600.0
REPLY = 300.0
CLI_RUN = 600.0


@dataclass(frozen=True)
class Contact:
    """A reply's contact: the finger's name, the point (3,) m, planning frame."""

    finger: str
    position: np.ndarray


@dataclass(frozen=True)
class Reply:
    """One grasp as an entry point answers it (the attributes ``check_candidate`` reads):
    joint positions over ``hand.actuated_joints`` (n,), the root link's pose (4, 4) in the
    planning frame, its contacts, its joint names as the reply gives them."""

    rank: int
    joint_positions: np.ndarray
    pre_grasp_positions: np.ndarray
    wrist_pose: np.ndarray
    contacts: tuple[Contact, ...]
    force_closure: bool
    names: tuple[str, ...]


def _tag(path: Path) -> str:
    """A file name part unique to the hand file (two files may share a stem)."""
    return f"{path.stem}_{hashlib.sha1(str(path).encode()).hexdigest()[:8]}"


def _by_name(names, values, order) -> np.ndarray:
    """values given for ``names`` -> (len(order),) in ``order`` (NaN where missing)."""
    given = dict(zip(names, map(float, values)))
    return np.array([given.get(j, np.nan) for j in order])


def names_check(ind: IndependentHand, names: tuple[str, ...], root: str) -> bool:
    """The reply's joint names are the URDF's movable joints below ``root`` (the link the
    reply's ``grasp_pose`` places) that are not mimic followers, each once (joints above the
    root, a wrist or an arm, are held and not the hand's)."""
    urdf = ind.urdf
    below, todo = {root}, [root]
    while todo:
        link = todo.pop()
        for joint in urdf.joint_map.values():
            if joint.parent == link and joint.child not in below:
                below.add(joint.child)
                todo.append(joint.child)
    below.discard(root)  # the joint that moves the root itself is above it
    own = {n for n, j in urdf.joint_map.items() if j.type != "fixed" and j.mimic is None and j.child in below}
    return len(names) == len(set(names)) and set(names) == own


# ---- the node -----------------------------------------------------------------------------

class NodeClient:
    """The node in its own process with ``hand_description`` = path, and a client here."""

    def __init__(self, path: Path, log_dir: str):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        from grasp_apso_interfaces.srv import PlanGrasp

        env = dict(os.environ)
        env.setdefault("ROS_DOMAIN_ID", str(os.getpid() % 30 + 170))
        env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        env["ROS_LOG_DIR"] = log_dir
        env["PYTHONPATH"] = os.pathsep.join([str(REPO)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
        os.environ.update({k: env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")})
        self.log = open(os.path.join(log_dir, f"node_{_tag(path)}.log"), "w")
        self.process = subprocess.Popen(
            [sys.executable, "-m", "grasp_apso.ros.node", "--ros-args", "-p", f"hand_description:={path}",
             "-p", f"allowed_mesh_dir:={MESH_DIR}"], cwd=REPO, env=env, stdout=self.log, stderr=subprocess.STDOUT)
        self.context = rclpy.context.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node("grasp_apso_unseen_hands_client", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.client = self.node.create_client(PlanGrasp, "/grasp_apso/plan_grasp")
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()
        deadline = time.monotonic() + NODE_START
        while not self.client.wait_for_service(timeout_sec=1.0):
            if self.process.poll() is not None:
                raise RuntimeError(f"the node exited ({self.process.returncode}); see {self.log.name}")
            if time.monotonic() > deadline:
                raise TimeoutError(f"no plan_grasp service after {NODE_START:.0f} s; see {self.log.name}")

    def plan(self, name: str, plane: np.ndarray, seed: int, swarm: dict):
        """The reply to one request (the object at the identity pose, the table ``plane``)."""
        from shape_msgs.msg import Plane

        from grasp_apso_interfaces.srv import PlanGrasp

        req = PlanGrasp.Request()
        if name in BUILTINS:
            req.object_name = name
        else:
            req.mesh_uri = str(MESH_DIR / f"{name}.stl")
        req.object_pose.header.frame_id = "world"
        req.object_pose.pose.orientation.w = 1.0
        req.support_planes = [Plane(coef=[float(v) for v in plane])]
        req.max_grasps, req.seed = 5, seed
        req.particles, req.iterations = swarm.get("particles", 0), swarm.get("iterations", 0)
        done = threading.Event()
        future = self.client.call_async(req)
        future.add_done_callback(lambda _f: done.set())
        if not done.wait(REPLY):
            raise TimeoutError(f"no reply in {REPLY:.0f} s")
        return future.result()

    def close(self) -> None:
        self.process.terminate()
        try:
            self.process.wait(timeout=30.0)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(timeout=10.0)
        self.executor.shutdown(timeout_sec=2.0)
        self.thread.join(timeout=5.0)
        self.node.destroy_node()
        self.context.try_shutdown()
        self.log.close()


def node_replies(response, order) -> list[Reply]:
    """The reply's grasps as :class:`Reply` (joints over ``order``, by name)."""
    from grasp_apso.model import poses

    out = []
    for rank, g in enumerate(response.grasps):
        p, o = g.grasp_pose.pose.position, g.grasp_pose.pose.orientation
        names = tuple(g.grasp_posture.name)
        out.append(Reply(
            rank=rank, joint_positions=_by_name(names, g.grasp_posture.position, order),
            pre_grasp_positions=_by_name(g.pre_grasp_posture.name, g.pre_grasp_posture.position, order),
            wrist_pose=poses.pose_to_matrix([p.x, p.y, p.z], [o.x, o.y, o.z, o.w]),
            contacts=tuple(Contact(f, np.array([c.x, c.y, c.z])) for f, c in zip(g.contact_fingers, g.contact_points)),
            force_closure=bool(g.force_closure), names=names))
    return out


# ---- the CLI ------------------------------------------------------------------------------

def cli_plan(path: Path, name: str, seed: int, swarm: dict, folder: str) -> tuple[list[Reply] | None, np.ndarray, str]:
    """The CLI's candidates for one object (None when it answered none), its table plane
    (4,) and its message."""
    out = os.path.join(folder, f"{_tag(path)}_{name}_{seed}.json")
    obj = ["--object", name] if name in BUILTINS else ["--mesh", str(MESH_DIR / f"{name}.stl")]
    extra = [a for k in ("particles", "iterations") if k in swarm for a in (f"--{k}", str(swarm[k]))]
    cmd = [sys.executable, "-m", "grasp_apso.tools.cli", "--hand", str(path), *obj, "--table", "--grasps", "5",
           "--seed", str(seed), "--no-plots", "--quiet", "--json", out, *extra]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO)] + [p for p in os.environ.get("PYTHONPATH", "").split(
        os.pathsep) if p]))
    run = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=CLI_RUN)
    if not os.path.exists(out):  # no reply: the last line it printed says why
        said = (run.stderr or run.stdout).strip().splitlines()
        return None, np.full(4, np.nan), said[-1] if said else f"exit {run.returncode}"
    data = json.loads(Path(out).read_text())
    plane = np.asarray(data["scene"]["support_planes"][0], float)
    result = next(iter(data["results"].values()))
    names = tuple(result["joint_names"])
    replies = [Reply(rank=int(c["rank"]), joint_positions=np.asarray(c["joint_positions"], float),
                     pre_grasp_positions=np.asarray(c["pre_grasp_positions"], float),
                     wrist_pose=np.asarray(c["wrist_pose"]["matrix"], float),
                     contacts=tuple(Contact(k["finger"], np.asarray(k["position"], float)) for k in c["contacts"]),
                     force_closure=bool(c["force_closure"]), names=names)
               for c in result["candidates"]]
    return replies, plane, result.get("candidates_message", "")


def _reorder(replies: list[Reply], order) -> list[Reply]:
    """The CLI's joint positions (in its ``joint_names``) over ``order``."""
    return [Reply(r.rank, _by_name(r.names, r.joint_positions, order), _by_name(r.names, r.pre_grasp_positions, order),
                  r.wrist_pose, r.contacts, r.force_closure, r.names) for r in replies]


# ---- the run --------------------------------------------------------------------------------

def labels(paths: list[Path]) -> list[str]:
    """A name per hand file: its stem, with as many parent folders as tell two files of one
    stem apart (dex-urdf's and leap_description's ``leap_hand_right.urdf``)."""
    out = []
    for path in paths:
        parts = path.parts
        for depth in range(1, len(parts) + 1):
            label = "/".join(parts[-depth:])[: -len(path.suffix) or None]
            if sum(q.parts[-depth:] == parts[-depth:] for q in paths) == 1 or depth == len(parts):
                break
        out.append(label)
    return out


def run_hand(path: Path, label: str, objects: list[str], seeds: int, swarm: dict, vias: tuple[str, ...],
             folder: str) -> list[dict]:
    from grasp_apso.model.hands.load import load_hand
    from grasp_apso.model.scene import Scene
    from grasp_apso.tunables import default

    hand = load_hand(str(path))
    ind = IndependentHand(path)
    order = list(hand.actuated_joints)
    clearance = float(default("clearance"))  # both entry points plan with the default
    rng = np.random.default_rng(0)
    node = NodeClient(path, folder) if "node" in vias else None
    rows = []
    try:
        for name in objects:
            obj_mesh = load_object(name).mesh.copy()
            obj_fcl = object_collision(obj_mesh)
            table_plane = np.asarray(Scene.table_under(np.asarray(obj_mesh.vertices)).planes[0], float)
            for seed in range(seeds):
                for via in vias:
                    row = {"hand": label, "file": str(path), "via": via, "object": name, "seed": seed,
                           "candidates": []}
                    t0 = time.perf_counter()
                    try:
                        if via == "node":
                            response = node.plan(name, table_plane, seed, swarm)
                            replies, plane, message = node_replies(response, order), table_plane, response.message
                        else:
                            replies, plane, message = cli_plan(path, name, seed, swarm, folder)
                            replies = None if replies is None else _reorder(replies, order)
                    except (TimeoutError, RuntimeError, subprocess.TimeoutExpired) as exc:
                        replies, plane, message = None, table_plane, f"{type(exc).__name__}: {exc}"
                    row.update(seconds=time.perf_counter() - t0, message=message)
                    row["joints"] = [r.joint_positions.tolist() for r in replies or []]
                    table = table_object(plane) if replies else None
                    for r in replies or []:
                        checked = check_candidate(ind, hand, r, obj_mesh, obj_fcl, table, clearance, rng)
                        checked["names"] = names_check(ind, r.names, hand.root_link)
                        row["candidates"].append(checked)
                    ok = {c: sum(x[c] for x in row["candidates"]) for c in ("names",) + CHECKS + INFO}
                    print(f"  {label:24s} {via:4s} {name:16s} seed {seed}: {len(row['candidates'])} cands "
                          f"{row['seconds']:6.1f} s  " + " ".join(f"{c} {ok[c]}" for c in ("names",) + CHECKS)
                          + ("" if row["candidates"] else f"  ({message[:80]})"), flush=True)
                    rows.append(row)
    finally:
        if node is not None:
            node.close()
    return rows


def same_replies(rows: list[dict]) -> dict[str, tuple[int, int]]:
    """Per hand: (plans whose node and CLI replies hold the same grasps, plans asked of
    both). The same seed, object and table, and the defaults of both: the same plan."""
    out: dict[str, list[int]] = {}
    by_plan: dict[tuple, dict[str, list]] = {}
    for r in rows:
        by_plan.setdefault((r["hand"], r["object"], r["seed"]), {})[r["via"]] = r["joints"]
    for (hand, _, _), vias in by_plan.items():
        if set(vias) != set(VIAS):
            continue
        a, b = (np.asarray(vias[v], float) for v in VIAS)
        count = out.setdefault(hand, [0, 0])
        count[1] += 1
        count[0] += int(a.shape == b.shape and (a.size == 0 or np.allclose(a, b, rtol=0.0, atol=1e-6)))
    return {h: (k, n) for h, (k, n) in out.items()}


def report(rows: list[dict]) -> dict:
    checks = ("names",) + CHECKS
    summary = {}
    print(f"\n{'hand':26s} {'via':5s} {'grasp/plans':>12s} {'cands':>6s} " + " ".join(f"{c:>7s}" for c in checks)
          + f" {'fc':>5s} {'median s':>9s}")
    for key in dict.fromkeys((r["hand"], r["via"]) for r in rows):
        group = [r for r in rows if (r["hand"], r["via"]) == key]
        cands = [c for r in group for c in r["candidates"]]
        s = {"plans": len(group), "with_grasp": sum(bool(r["candidates"]) for r in group),
             "candidates": len(cands), **{c: sum(x[c] for x in cands) for c in checks + INFO},
             "median_s": statistics.median(r["seconds"] for r in group)}
        summary[f"{key[0]} {key[1]}"] = s
        print(f"{key[0]:26s} {key[1]:5s} {s['with_grasp']:5d}/{s['plans']:<6d} {s['candidates']:6d} "
              + " ".join(f"{s[c]:7d}" for c in checks) + f" {s['fc']:5d} {s['median_s']:9.1f}")
    same = same_replies(rows)
    if same:
        print("\nThe node and the CLI answered the same grasps (joints within 1e-6): " + ", ".join(
            f"{h} {k} of {n} plans" for h, (k, n) in same.items()))
        for hand, (k, n) in same.items():
            for key in (f"{hand} node", f"{hand} cli"):
                summary[key]["same_as_other"] = k
    failing = [(r, c) for r in rows for c in r["candidates"] if not all(c[k] for k in checks)]
    print("\nFailing candidates:" + ("" if failing else " none"))
    for r, c in failing:
        print(f"  {r['hand']:24s} {r['via']:4s} {r['object']:16s} s{r['seed']} g{c['rank']}: "
              f"{','.join(k for k in checks if not c[k])}; table {c['table_mm']:.1f} mm, depth {c['depth_mm']:.1f} mm, "
              f"pad links {c['pads_mm']}, contacts {c['on_pad_mm']} mm {'; '.join(c['limit_violations'][:2])}")
    return summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--hands", nargs="+", type=Path, help="URDF files (default: the dex-urdf right hands)")
    parser.add_argument("--dex-urdf", type=Path, default=DEX, help="dex-urdf's robots/hands folder")
    parser.add_argument("--objects", nargs="+", default=list(OBJECTS))
    parser.add_argument("--seeds", type=int, default=1, help="seeds 0..N-1")
    parser.add_argument("--quick", action="store_true", help="particles 30, iterations 20")
    parser.add_argument("--via", nargs="+", choices=VIAS, default=list(VIAS))
    parser.add_argument("--out", type=Path, default=REPO / "bench" / "results" / "unseen_hands_replies.json")
    args = parser.parse_args(argv)
    hands = hand_files(args, parser)
    if unknown := [o for o in args.objects if o not in BUILTINS and not (MESH_DIR / f"{o}.stl").exists()]:
        parser.error(f"--objects: {', '.join(unknown)}: neither a built-in ({', '.join(BUILTINS)}) nor a mesh of "
                     f"{MESH_DIR}")
    swarm = {"particles": 30, "iterations": 20} if args.quick else {}
    t0 = time.perf_counter()
    rows = []
    with tempfile.TemporaryDirectory(prefix="grasp_apso_replies_") as folder:
        hands = [path.resolve() for path in hands]
        for path, label in zip(hands, labels(hands)):
            rows += run_hand(path, label, args.objects, args.seeds, swarm, tuple(args.via), folder)
    write_results(args.out, swarm, report(rows), rows, t0)
    return 0


if __name__ == "__main__":
    sys.exit(main())
