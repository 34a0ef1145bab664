"""Benchmark: round trip of the node answering a stored object from a grasp database.

1. A database of the built-in cube and sphere (exported to STL) is written with the batch
   tool (``python -m grasp_apso.tools.batch_cli``, one local worker, 3 grasps each,
   20 particles x 10 iterations) in a temporary folder.
2. The node runs in its own process (``python -m grasp_apso.ros.node`` with
   ``grasp_database`` set; DDS domain of its own, discovery on localhost); this process is
   the client.
3. Requests with the stored meshes sent inline (packed, the mesh as the batch read it, at a
   non-identity pose), without a scene and with a table under the object (the scene check
   of every stored grasp, the approach included): the first one ("cold": the node
   validates the mesh) and then ``--calls`` round trips (median, p90; "node" is the
   ``planning_time`` the node reports). The node's very first request (it waits for the
   kernels to load) is timed apart. For comparison, the cube planned by a node without
   the database (default options, ``--planned`` calls).

Prints a table and writes ``bench/results/node_database.json``. Target: a stored object
answered in under 60 ms round trip (median). Run: ``.venv/bin/python
bench/bench_node_database.py`` (about a minute).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
os.environ.setdefault('ROS_DOMAIN_ID', str(os.getpid() % 30 + 150))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

import rclpy  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from shape_msgs.msg import Plane  # noqa: E402

from grasp_apso_interfaces.srv import PlanGrasp  # noqa: E402

from grasp_apso.model import builtin, mesh_files  # noqa: E402
from grasp_apso.ros.conversions import arrays_to_packed  # noqa: E402

RESULTS = os.path.join(ROOT, 'bench', 'results', 'node_database.json')
TARGET_MS = 60.0
OBJECTS = ('cube', 'sphere')
POSITION = (0.5, 0.0, 0.8)


class Client:
    """A client node spun by its own executor thread; ``call`` returns (response, seconds)."""

    def __init__(self, services):
        rclpy.init()
        self.node = rclpy.create_node('grasp_apso_bench_db_client')
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.clients = {name: self.node.create_client(PlanGrasp, f'/{name}/plan_grasp') for name in services}
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def call(self, service, request, timeout=300.0):
        done = threading.Event()
        t0 = time.perf_counter()
        future = self.clients[service].call_async(request)
        future.add_done_callback(lambda _f: done.set())
        if not done.wait(timeout):
            raise TimeoutError(f'{service}: no answer within {timeout} s')
        return future.result(), time.perf_counter() - t0

    def close(self):
        self.executor.shutdown(timeout_sec=2.0)
        self.thread.join(timeout=5.0)
        self.node.destroy_node()
        rclpy.try_shutdown()


def request_for(obj, table=False, **fields):
    """A packed-mesh request for ``obj`` at a rotated pose (optionally on a table)."""
    req = PlanGrasp.Request()
    req.mesh_vertices, req.mesh_triangles = arrays_to_packed(obj.mesh.vertices, obj.mesh.faces)
    req.object_pose.header.frame_id = 'base'
    p, q = req.object_pose.pose.position, req.object_pose.pose.orientation
    p.x, p.y, p.z = POSITION
    q.z, q.w = float(np.sin(0.2)), float(np.cos(0.2))  # 0.4 rad about z
    if table:
        bottom = POSITION[2] + float(np.min(np.asarray(obj.mesh.vertices)[:, 2]))
        req.support_planes = [Plane(coef=[0.0, 0.0, 1.0, -bottom])]
    for key, value in fields.items():
        setattr(req, key, value)
    return req


def _stats(seconds):
    ms = sorted(1000.0 * s for s in seconds)
    return {'median': statistics.median(ms), 'p90': ms[min(len(ms) - 1, int(0.9 * len(ms)))],
            'min': ms[0], 'max': ms[-1], 'n': len(ms)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--calls', type=int, default=20, help='timed round trips per case (default 20)')
    parser.add_argument('--planned', type=int, default=3, help='planned calls for comparison (default 3; 0 = none)')
    args = parser.parse_args(argv)

    work = tempfile.mkdtemp(prefix='grasp_apso_bench_db_')
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join([ROOT] + [p for p in env.get('PYTHONPATH', '').split(os.pathsep) if p])
    env['ROS_LOG_DIR'] = work
    objs = {}
    for name in OBJECTS:
        path = os.path.join(work, f'{name}.stl')
        builtin.builtin(name).mesh.export(path)
        objs[name] = mesh_files.from_file(path, allowed_dir=work)
    db = os.path.join(work, 'db')
    t0 = time.perf_counter()
    subprocess.run([sys.executable, '-m', 'grasp_apso.tools.batch_cli', *(os.path.join(work, f'{n}.stl') for n in OBJECTS),
                    '--out', db, '--grasps', '3', '--workers', '1', '--particles', '20', '--iterations', '10',
                    '--progress', 'none'], cwd=ROOT, env=env, check=True)
    batch_s = time.perf_counter() - t0

    log = open(os.path.join(work, 'nodes.log'), 'w')
    nodes = [subprocess.Popen([sys.executable, '-m', 'grasp_apso.ros.node', '--ros-args', '-r', '__node:=grasp_apso_db',
                               '-p', f'grasp_database:={db}'], cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT)]
    if args.planned:
        nodes.append(subprocess.Popen([sys.executable, '-m', 'grasp_apso.ros.node', '--ros-args', '-r',
                                       '__node:=grasp_apso_plain'], cwd=ROOT, env=env, stdout=log,
                                      stderr=subprocess.STDOUT))
    client = None
    cases = {}
    startup = float('nan')
    try:
        client = Client(['grasp_apso_db', 'grasp_apso_plain'])
        for name in ['grasp_apso_db'] + (['grasp_apso_plain'] if args.planned else []):
            if not client.clients[name].wait_for_service(timeout_sec=60.0):
                raise RuntimeError(f'{name}: service not available (see {log.name})')
        # The node's first request waits for the kernels to load (warm-up job): not timed below.
        _, startup = client.call('grasp_apso_db', request_for(objs['cube'], iterations=1))
        for name, obj in objs.items():
            for table in (False, True):
                req = request_for(obj, table=table)
                first, cold = client.call('grasp_apso_db', req)
                label = f'{name}{", on a table" if table else ""}'
                if first.grasp_source != 'database':
                    if not table:
                        raise RuntimeError(f'{name}: not answered from the database: {first.message}')
                    # Legitimate: the stored grasps (planned without a table) may all need
                    # the space under the object.
                    cases[label] = {'planned_instead': first.message, 'round_trip_ms': 1000.0 * cold,
                                    'triangles': len(obj.mesh.faces)}
                    continue
                rows = [client.call('grasp_apso_db', req) for _ in range(max(1, args.calls))]
                assert all(r.grasp_source == 'database' and r.success for r, _ in rows)
                cases[label] = {
                    'round_trip_ms': _stats([s for _, s in rows]), 'cold_round_trip_ms': 1000.0 * cold,
                    'planning_time_ms_median': statistics.median(1000.0 * r.planning_time for r, _ in rows),
                    'grasps': len(rows[0][0].grasps), 'triangles': len(obj.mesh.faces)}
        planned = None
        if args.planned:
            req = request_for(objs['cube'])
            runs = [client.call('grasp_apso_plain', req) for _ in range(args.planned)]
            assert all(r.grasp_source == 'planned' for r, _ in runs)
            planned = {'round_trip_ms': _stats([s for _, s in runs]), 'options': 'node defaults'}
    finally:
        if client is not None:
            client.close()
        for node in nodes:
            node.terminate()
        statuses = [node.wait(timeout=30) for node in nodes]
        log.close()

    headline = cases['cube']['round_trip_ms']['median']
    result = {
        'benchmark': 'node answering stored objects from a grasp database',
        'database': {'objects': list(OBJECTS), 'grasps_per_object': 3, 'batch_seconds': batch_s},
        'cases': cases, 'planned_cube': planned, 'target_round_trip_ms': TARGET_MS,
        'first_request_after_start_ms': 1000.0 * startup,
        'stored_cube_round_trip_ms_median': headline, 'node_exit_status': statuses,
        'machine': {'python': platform.python_version(), 'cpus': os.cpu_count(), 'platform': platform.platform()},
        'date': time.strftime('%Y-%m-%d %H:%M:%S'),
    }
    os.makedirs(os.path.dirname(RESULTS), exist_ok=True)
    with open(RESULTS, 'w', encoding='utf-8') as handle:
        json.dump(result, handle, indent=2)

    print(f'grasp_apso node + grasp database ({platform.python_version()}, {os.cpu_count()} CPUs, '
          f'{args.calls} calls per case)')
    print(f'{"request (packed mesh, rotated pose)":<28}{"tris":>6}{"median":>9}{"p90":>8}{"cold":>8}'
          f'{"node":>8}{"grasps":>8}')
    print('-' * 75)
    for name, c in cases.items():
        rt = c['round_trip_ms']
        if 'planned_instead' in c:
            print(f'{name:<28}{c["triangles"]:>6}  no stored grasp kept by the scene: planned in {rt:.0f} ms')
            continue
        print(f'{name:<28}{c["triangles"]:>6}{rt["median"]:>6.1f} ms{rt["p90"]:>5.1f} ms{c["cold_round_trip_ms"]:>5.1f} ms'
              f'{c["planning_time_ms_median"]:>5.1f} ms{c["grasps"]:>8}')
    print(f'{"first request after start-up":<34}{1000.0 * startup:>6.0f} ms (waits for the kernels to load)')
    if planned:
        print(f'{"cube planned (no database)":<28}{len(objs["cube"].mesh.faces):>6}'
              f'{planned["round_trip_ms"]["median"]:>6.0f} ms  (node defaults, {args.planned} calls)')
    ok = 'OK' if headline < TARGET_MS else 'OVER TARGET'
    print(f'stored cube round trip median {headline:.1f} ms [{ok}, target < {TARGET_MS:g} ms]; '
          f'"node" = planning_time reported (worker time); results: {os.path.relpath(RESULTS, ROOT)}')
    return 0 if headline < TARGET_MS else 1


if __name__ == '__main__':
    sys.exit(main())
