"""Demo client of the ``grasp_apso`` node (``python -m grasp_apso.ros.demo_client [object]``).

Waits for the node's ``~/plan_grasp`` service, subscribes to its ``~/progress`` topic,
plans a grasp of a built-in object (fish by default) or of a mesh file (``--mesh``, sent
inline), then prints the result readably: the hand's joints in degrees (the paper hand's 18
as a table of fingers), the wrist pose, fitness, epsilon, force closure, contacts per
finger, iterations, planning time, and how many progress messages arrived on which topic.
``scripts/demo.sh`` (``make demo``) starts the node, runs this and stops the node.

Exit status: 0 when the node found a valid grasp, 2 when it answered success = false,
1 when the service did not answer (not found, timeout).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import threading
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from shape_msgs.msg import Plane

from grasp_apso_interfaces.msg import GraspProgress
from grasp_apso_interfaces.srv import PlanGrasp

from ..model.hand import FINGER_NAMES, JOINT_KINDS
from ..model.builtin import BUILTIN_OBJECTS, builtin


def _parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="python -m grasp_apso.ros.demo_client",
        description="Plan a grasp of a built-in object through the grasp_apso node and print it.")
    parser.add_argument("object", nargs="?", default="fish", choices=BUILTIN_OBJECTS,
                        help="built-in object (default: fish); see also --mesh")
    parser.add_argument("--mesh", default="", metavar="FILE",
                        help="plan for this mesh file instead (STL/OBJ/PLY/OFF, metres), sent inline "
                             "(mesh_vertices / mesh_triangles), e.g. grasp_apso/data/meshes/mug.stl")
    parser.add_argument("--node", default="/grasp_apso",
                        help="node name: the service is <node>/plan_grasp (default: /grasp_apso)")
    parser.add_argument("--algorithm", default="", help="apso or pso (default: node parameter)")
    parser.add_argument("--particles", type=int, default=0, help="0 = node parameter")
    parser.add_argument("--iterations", type=int, default=0, help="0 = node parameter")
    parser.add_argument("--seed", type=int, default=-1, help="-1 = node parameter")
    parser.add_argument("--frame", default="world", help="planning frame (default: world)")
    parser.add_argument("--position", type=float, nargs=3, default=(0.5, 0.0, 0.1),
                        metavar=("X", "Y", "Z"), help="object position in the frame, m")
    parser.add_argument("--table", action=argparse.BooleanOptionalAction, default=True,
                        help="the object rests on a table: one support plane (normal +z) under its lowest "
                             "point (default: on; --no-table plans in free space)")
    parser.add_argument("--grasps", type=int, default=5, help="max_grasps: ranked candidates wanted (default 5)")
    parser.add_argument("--wait", type=float, default=30.0, help="seconds to wait for the service")
    parser.add_argument("--timeout", type=float, default=300.0, help="seconds to wait for the answer")
    args = parser.parse_args(argv)
    if args.mesh and not os.path.isfile(args.mesh):
        parser.error(f"--mesh: no such file: {args.mesh}")
    return args


def _print_result(res: PlanGrasp.Response, round_trip: float) -> None:
    print(f"success        : {res.success}")
    print(f"message        : {res.message}")
    print(f"request id     : {res.request_id}")
    if not res.configuration.name:
        return
    positions = dict(zip(res.configuration.name, res.configuration.position))
    print("")
    print(f"configuration (sensor_msgs/JointState, frame '{res.configuration.header.frame_id}'), degrees:")
    paper_names = [f"{f}_{k}" for f in FINGER_NAMES for k in JOINT_KINDS]
    if all(n in positions for n in paper_names):  # the paper's hand: a table of fingers x joints
        print("  finger  " + "".join(f"{kind:>10}" for kind in JOINT_KINDS))
        for finger in FINGER_NAMES:
            row = "".join(f"{math.degrees(positions[f'{finger}_{kind}']):10.1f}" for kind in JOINT_KINDS)
            print(f"  {finger:<8}{row}")
        wrist = "".join(f"{math.degrees(positions[n]):10.1f}" for n in ("wrist_x", "wrist_y", "wrist_z"))
        print(f"  {'wrist':<8}{wrist}    (wrist_x, wrist_y, wrist_z)")
    else:  # any other hand: its actuated joints, in the reply's order
        for name, value in positions.items():
            print(f"  {name:<32}{math.degrees(value):8.1f}")
    p, q = res.wrist_pose.pose.position, res.wrist_pose.pose.orientation
    rpy = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_euler("xyz", degrees=True)
    print("")
    print(f"wrist pose     : frame '{res.wrist_pose.header.frame_id}', position "
          f"({p.x:.4f}, {p.y:.4f}, {p.z:.4f}) m, quaternion (x y z w) "
          f"({q.x:.4f}, {q.y:.4f}, {q.z:.4f}, {q.w:.4f}), rpy ({rpy[0]:.1f}, {rpy[1]:.1f}, {rpy[2]:.1f}) deg")
    print(f"fitness        : {res.fitness:.4f}")
    print(f"epsilon quality: {res.epsilon_quality:.5f}")
    print(f"force closure  : {'yes' if res.force_closure else 'no'}")
    counts = {f: res.contact_fingers.count(f) for f in dict.fromkeys(res.contact_fingers)}
    print(f"contacts       : {len(res.contact_fingers)}  ("
          + ", ".join(f"{f} {n}" for f, n in counts.items()) + ")")
    for finger, point, normal in zip(res.contact_fingers, res.contact_points, res.contact_normals):
        print(f"    {finger:<7} at ({point.x:.4f}, {point.y:.4f}, {point.z:.4f}) m, normal "
              f"({normal.x:.2f}, {normal.y:.2f}, {normal.z:.2f})")
    print(f"iterations run : {res.iterations_run}")
    print(f"planning time  : {res.planning_time:.3f} s (round trip {round_trip:.3f} s)")
    if res.grasps:
        print("")
        print(f"candidates     : {len(res.grasps)}, best first (wrist position mm, approach direction unit)")
        sim = {-1: "", 0: "  dropped", 1: "  held"}
        for rank, g in enumerate(res.grasps, 1):
            p, a = g.grasp_pose.pose.position, g.approach_direction.vector
            print(f"  {rank}. {g.id:<4} quality {g.grasp_quality:.3f}  epsilon {g.epsilon_quality:.4f}  "
                  f"FC {'yes' if g.force_closure else 'no '}  {len(g.contact_fingers)} contacts  wrist "
                  f"({p.x * 1000:.0f}, {p.y * 1000:.0f}, {p.z * 1000:.0f})  approach "
                  f"({a.x:.2f}, {a.y:.2f}, {a.z:.2f}){sim.get(g.sim_result, '')}")


def main(argv: list[str] | None = None) -> int:
    args = _parse_args(argv)
    rclpy.init()
    node = rclpy.create_node("grasp_apso_demo_client")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    service = f"{args.node.rstrip('/')}/plan_grasp"
    topic = f"{args.node.rstrip('/')}/progress"
    received: dict[str, int] = {}
    lock = threading.Lock()
    progress_changed = threading.Event()
    last: dict[str, GraspProgress] = {}

    def on_progress(msg: GraspProgress) -> None:
        with lock:
            received[msg.request_id] = received.get(msg.request_id, 0) + 1
            last[msg.request_id] = msg
        progress_changed.set()

    subscription = node.create_subscription(
        GraspProgress, topic, on_progress, QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
    client = node.create_client(PlanGrasp, service)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        print(f"[demo] waiting for the service {service} (up to {args.wait:.0f} s) ...", flush=True)
        if not client.wait_for_service(timeout_sec=args.wait):
            print(f"[demo] error: service {service} not available", file=sys.stderr)
            return 1
        # The progress subscription must be matched before the plan starts publishing.
        deadline = time.monotonic() + 10.0
        while subscription.get_publisher_count() < 1 and time.monotonic() < deadline:
            time.sleep(0.02)
        request = PlanGrasp.Request()
        request.object_pose.header.frame_id = args.frame
        request.object_pose.header.stamp = node.get_clock().now().to_msg()
        request.object_pose.pose.position.x, request.object_pose.pose.position.y, \
            request.object_pose.pose.position.z = (float(v) for v in args.position)
        request.object_pose.pose.orientation.w = 1.0
        request.algorithm = args.algorithm
        request.particles = max(0, args.particles)
        request.iterations = max(0, args.iterations)
        request.seed = args.seed
        request.max_grasps = max(0, args.grasps)
        if args.mesh:
            mesh = trimesh.load(args.mesh, force="mesh")
            request.mesh_vertices = np.asarray(mesh.vertices, dtype=np.float64).ravel().tolist()
            request.mesh_triangles = np.asarray(mesh.faces, dtype=np.uint32).ravel().tolist()
            vertices = np.asarray(mesh.vertices)
        else:
            request.object_name = args.object
            vertices = builtin(args.object).mesh.vertices
        if args.table:  # a support plane under the object's lowest point (identity orientation)
            lowest = float(args.position[2]) + float(vertices[:, 2].min())
            plane = Plane()
            plane.coef = [0.0, 0.0, 1.0, -lowest]
            request.support_planes = [plane]
        what = f"the mesh {args.mesh}" if args.mesh else f"the built-in '{args.object}'"
        print(f"[demo] planning up to {request.max_grasps or 'the default number of'} grasps of {what} at ({args.position[0]}, {args.position[1]}, {args.position[2]}) m in frame "
              f"'{args.frame}'" + (f", resting on a table at z = {-request.support_planes[0].coef[3]:.3f} m"
                                   if args.table else "") + " ...", flush=True)
        t0 = time.perf_counter()
        done = threading.Event()
        future = client.call_async(request)
        future.add_done_callback(lambda _f: done.set())
        if not done.wait(args.timeout):
            print(f"[demo] error: no answer within {args.timeout:.0f} s", file=sys.stderr)
            return 1
        round_trip = time.perf_counter() - t0
        response = future.result()
        # Progress messages and the answer travel separately: wait (briefly) for the last ones.
        deadline = time.monotonic() + 3.0
        while time.monotonic() < deadline:
            with lock:
                count = received.get(response.request_id, 0)
            if count >= response.iterations_run:
                break
            progress_changed.clear()
            progress_changed.wait(0.1)
        with lock:
            count = received.get(response.request_id, 0)
            final = last.get(response.request_id)
        print("")
        _print_result(response, round_trip)
        print("")
        print(f"progress       : {count} GraspProgress messages for this request on {topic} "
              f"(one per iteration; watch them live with `ros2 topic echo {topic}`)")
        if final is not None:
            print(f"                 last: iteration {final.iteration}/{final.iterations}, best fitness "
                  f"{final.best_fitness:.4f}, mean {final.mean_fitness:.4f}, "
                  f"{final.active_particles} active particles, {final.elapsed:.2f} s")
        return 0 if response.success else 2
    finally:
        executor.shutdown(timeout_sec=2.0)
        spinner.join(timeout=5.0)
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
