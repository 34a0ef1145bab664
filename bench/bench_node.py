"""Benchmark of the grasp_apso node: service overhead and a memory soak.

The node runs in its own process (``python -m grasp_apso.ros.node``, DDS domain of its own,
discovery on localhost); this process is the client.

1. Service overhead: the round trip of ``~/plan_grasp`` measured by the client, minus the
   ``planning_time`` the node reports (the worker's time: object validation + planning),
   for a 10,000-triangle mesh sent inline, packed in ``mesh_vertices`` / ``mesh_triangles``
   (the target applies to it) and as ``shape_msgs/Mesh`` (whose 15,000 Python objects
   rclpy alone needs ~30 ms to serialise and deserialise); median over ``--calls``
   calls after two warm-up calls, with small plans (particles 10, iterations 2). What
   remains is ROS: request/response (de)serialisation, DDS transport, conversion of the
   message to arrays, queueing and executor scheduling. The client-side serialisation
   and the deserialisation of the request (measured in this process; the node pays the
   same when it takes the request) are measured alone for the breakdown.
   The floor: the same requests to an rclpy server of the same type that answers at once
   (no node logic), which is what rclpy and DDS cost by themselves.
2. Soak: ``--soak`` sequential requests (built-in objects and the inline meshes in turn,
   small plans); RSS of the node process (/proc/<pid>/status VmRSS) after a warm-up pass
   over every object and then every 10 requests; growth = end - after warm-up.

Prints a table and writes ``bench/results/node.json``. Targets: overhead < 20 ms,
growth < 20 MB. Run: ``.venv/bin/python bench/bench_node.py`` (about a minute).
"""
from __future__ import annotations

import argparse
import gc
import json
import os
import platform
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
os.environ.setdefault('ROS_DOMAIN_ID', str(os.getpid() % 30 + 202))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

import rclpy  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402

from grasp_apso_interfaces.srv import PlanGrasp  # noqa: E402

from grasp_apso.ros.conversions import arrays_to_mesh, arrays_to_packed, mesh_to_arrays, packed_mesh_to_arrays  # noqa: E402

RESULTS = os.path.join(ROOT, 'bench', 'results', 'node.json')
TARGET_OVERHEAD_MS = 20.0
TARGET_GROWTH_MB = 20.0


# The floor: an rclpy server of the same service type that answers at once (no planning).
ECHO_SERVER = r'''
import rclpy
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from grasp_apso_interfaces.srv import PlanGrasp
rclpy.init()
node = rclpy.create_node("grasp_apso_echo")
def answer(request, response):
    response.success = True
    return response
node.create_service(PlanGrasp, "~/plan_grasp", answer)
executor = MultiThreadedExecutor(num_threads=4)
executor.add_node(node)
try:
    executor.spin()
except (KeyboardInterrupt, ExternalShutdownException):
    pass
'''


def bottle_mesh(rings: int = 50, around: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """A closed lofted bottle (8 cm tall, radius 1.5-2.5 cm) with 2*(rings-1)*around +
    2*around triangles: 10,000 for the defaults."""
    z = np.linspace(-0.04, 0.04, rings)
    radius = 0.02 + 0.005 * np.cos(np.pi * z / 0.04)
    theta = 2 * np.pi * np.arange(around) / around
    ring_pts = np.stack([radius[:, None] * np.cos(theta), radius[:, None] * np.sin(theta),
                         np.broadcast_to(z[:, None], (rings, around))], -1).reshape(-1, 3)
    n = len(ring_pts)
    vertices = np.vstack([ring_pts, [[0, 0, z[0]], [0, 0, z[-1]]]])
    j, k = np.meshgrid(np.arange(rings - 1), np.arange(around), indexing='ij')
    j, k = j.ravel(), k.ravel()
    k1 = (k + 1) % around
    a, b = j * around + k, j * around + k1
    c, d = a + around, b + around
    side = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    first, last = np.arange(around), np.arange(around) + n - around
    bottom = np.stack([np.full(around, n), np.roll(first, -1), first], 1)
    top = np.stack([np.full(around, n + 1), last, np.roll(last, -1)], 1)
    return vertices, np.vstack([side, bottom, top])


def _median_ms(func, n: int = 11) -> float:
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        func()
        times.append((time.perf_counter() - t0) * 1000)
    return statistics.median(times)


def rss_mb(pid: int) -> float:
    with open(f'/proc/{pid}/status', encoding='ascii') as handle:
        for line in handle:
            if line.startswith('VmRSS:'):
                return int(line.split()[1]) / 1024.0
    raise RuntimeError('no VmRSS')


class Client:
    def __init__(self):
        rclpy.init()
        self.node = rclpy.create_node('grasp_apso_bench_client')
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.client = self.node.create_client(PlanGrasp, '/grasp_apso/plan_grasp')
        self.echo = self.node.create_client(PlanGrasp, '/grasp_apso_echo/plan_grasp')
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def call(self, request, timeout=120.0, client=None):
        done = threading.Event()
        t0 = time.perf_counter()
        future = (client or self.client).call_async(request)
        future.add_done_callback(lambda _f: done.set())
        if not done.wait(timeout):
            raise TimeoutError('no answer')
        return future.result(), time.perf_counter() - t0

    def close(self):
        self.executor.shutdown(timeout_sec=2.0)
        self.thread.join(timeout=5.0)
        self.node.destroy_node()
        rclpy.try_shutdown()


def request_for(mesh=None, name='', particles=10, iterations=2, seed=1, packed=None):
    req = PlanGrasp.Request()
    if mesh is not None:
        req.mesh = mesh
    if packed is not None:
        req.mesh_vertices, req.mesh_triangles = packed
    req.object_name = name
    req.object_pose.header.frame_id = 'world'
    req.object_pose.pose.orientation.w = 1.0
    req.particles, req.iterations, req.seed = particles, iterations, seed
    return req


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--calls', type=int, default=15, help='timed calls for the overhead (>= 10)')
    parser.add_argument('--soak', type=int, default=100, help='sequential requests of the soak')
    args = parser.parse_args(argv)

    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join([ROOT] + [p for p in env.get('PYTHONPATH', '').split(os.pathsep) if p])
    log_dir = tempfile.mkdtemp(prefix='grasp_apso_bench_')
    env['ROS_LOG_DIR'] = log_dir
    node_log = open(os.path.join(log_dir, 'node.log'), 'w')
    node = subprocess.Popen([sys.executable, '-m', 'grasp_apso.ros.node'], cwd=ROOT, env=env,
                            stdout=node_log, stderr=subprocess.STDOUT)
    client = None
    try:
        client = Client()
        gc.freeze()  # as the node does: no full-collection pauses from the imported libraries
        if not client.client.wait_for_service(timeout_sec=30.0):
            raise RuntimeError('service not available')
        rss_idle = rss_mb(node.pid)

        vertices, triangles = bottle_mesh()
        t = time.perf_counter()
        mesh = arrays_to_mesh(vertices, triangles)
        build_ms = (time.perf_counter() - t) * 1000
        assert len(mesh.triangles) == 10_000
        mesh_req = request_for(mesh)
        data = serialize_message(mesh_req)
        serialize_ms = _median_ms(lambda: serialize_message(mesh_req))
        deserialize_ms = _median_ms(lambda: deserialize_message(data, PlanGrasp.Request))
        message = deserialize_message(data, PlanGrasp.Request)
        to_arrays_ms = _median_ms(lambda: mesh_to_arrays(message.mesh))
        t = time.perf_counter()
        packed = arrays_to_packed(vertices, triangles)
        build_packed_ms = (time.perf_counter() - t) * 1000
        packed_req = request_for(packed=packed)
        packed_data = serialize_message(packed_req)
        serialize_packed_ms = _median_ms(lambda: serialize_message(packed_req))
        deserialize_packed_ms = _median_ms(lambda: deserialize_message(packed_data, PlanGrasp.Request))
        packed_message = deserialize_message(packed_data, PlanGrasp.Request)
        packed_to_arrays_ms = _median_ms(
            lambda: packed_mesh_to_arrays(packed_message.mesh_vertices, packed_message.mesh_triangles))

        # --- overhead ---------------------------------------------------------------------
        cold, cold_rt = client.call(mesh_req)
        if not cold.configuration.name:
            raise RuntimeError(f'mesh request failed: {cold.message}')
        client.call(mesh_req)
        rows = []
        for _ in range(max(10, args.calls)):
            res, rt = client.call(mesh_req)
            rows.append((rt, res.planning_time, rt - res.planning_time, res.success))
        overhead = [r[2] * 1000 for r in rows]
        # The same mesh packed (mesh_vertices / mesh_triangles): the object cache is keyed
        # by the arrays, so the packed request reuses the validated object and its grid.
        first_packed, _ = client.call(packed_req)
        if not first_packed.configuration.name:
            raise RuntimeError(f'packed mesh request failed: {first_packed.message}')
        packed_rows = []
        for _ in range(max(10, args.calls)):
            res, rt = client.call(packed_req)
            packed_rows.append((rt, res.planning_time, rt - res.planning_time, res.success))
        packed_overhead = [r[2] * 1000 for r in packed_rows]
        small, _ = client.call(request_for(name='sphere'))
        small_rows = []
        for _ in range(max(10, args.calls)):
            res, rt = client.call(request_for(name='sphere'))
            small_rows.append((rt - res.planning_time) * 1000)

        # --- the rclpy floor: the same requests to a server that answers at once ---------
        echo = subprocess.Popen([sys.executable, '-c', ECHO_SERVER], cwd=ROOT, env=env,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            if not client.echo.wait_for_service(timeout_sec=30.0):
                raise RuntimeError('echo service not available')
            floor_mesh, floor_small, floor_packed = [], [], []
            for _ in range(max(10, args.calls) + 2):
                floor_mesh.append(client.call(mesh_req, client=client.echo)[1] * 1000)
                floor_packed.append(client.call(packed_req, client=client.echo)[1] * 1000)
                floor_small.append(client.call(request_for(name='sphere'), client=client.echo)[1] * 1000)
            floor_mesh, floor_small, floor_packed = floor_mesh[2:], floor_small[2:], floor_packed[2:]
        finally:
            echo.send_signal(signal.SIGINT)
            try:
                echo.wait(timeout=10.0)
            except subprocess.TimeoutExpired:
                echo.kill()

        # --- soak -------------------------------------------------------------------------
        requests = [request_for(name=n, seed=i) for i, n in enumerate(('sphere', 'cube', 'barrel', 'fish'))]
        requests += [mesh_req, packed_req]
        for req in requests:  # warm-up: every object once (caches of objects and SDF grids)
            client.call(req)
        rss_start = rss_mb(node.pid)
        trend = [(0, rss_start)]
        soak_ok = 0
        t_soak = time.perf_counter()
        for i in range(args.soak):
            req = requests[i % len(requests)]
            req.seed = i
            res, _ = client.call(req)
            soak_ok += bool(res.success)
            # Sampled after whole passes over the requests: RSS rises and falls with the
            # request in flight (the 15,000-object Mesh), so samples at different points
            # of the rotation would show that swing as growth.
            if (i + 1) % len(requests) == 0:
                trend.append((i + 1, rss_mb(node.pid)))
        soak_s = time.perf_counter() - t_soak
        rss_end = trend[-1][1]
        rss_peak = max(max(m for _, m in trend), rss_mb(node.pid))
    finally:
        if client is not None:
            client.close()
        if node.poll() is None:
            node.send_signal(signal.SIGINT)
        try:
            node_status = node.wait(timeout=15.0)
        except subprocess.TimeoutExpired:
            node.kill()
            node_status = None
        node_log.close()

    med = statistics.median(overhead)
    med_packed = statistics.median(packed_overhead)
    growth = rss_end - rss_start
    result = {
        'mesh_triangles': 10_000,
        'mesh_vertices': int(len(vertices)),
        'calls': len(rows),
        'overhead_ms': {'median': med, 'p90': float(np.percentile(overhead, 90)),
                        'min': min(overhead), 'max': max(overhead)},
        'round_trip_ms_median': statistics.median(r[0] for r in rows) * 1000,
        'planning_time_ms_median': statistics.median(r[1] for r in rows) * 1000,
        'cold_first_call': {'round_trip_ms': cold_rt * 1000, 'planning_time_ms': cold.planning_time * 1000},
        'request_bytes': len(data),
        'client_build_mesh_msg_ms': build_ms,
        'serialize_request_ms': serialize_ms,
        'deserialize_request_ms': deserialize_ms,
        'mesh_to_arrays_ms': to_arrays_ms,
        'packed': {'overhead_ms': {'median': med_packed, 'p90': float(np.percentile(packed_overhead, 90)),
                                   'min': min(packed_overhead), 'max': max(packed_overhead)},
                   'round_trip_ms_median': statistics.median(r[0] for r in packed_rows) * 1000,
                   'planning_time_ms_median': statistics.median(r[1] for r in packed_rows) * 1000,
                   'request_bytes': len(packed_data), 'client_build_ms': build_packed_ms,
                   'serialize_request_ms': serialize_packed_ms, 'deserialize_request_ms': deserialize_packed_ms,
                   'packed_to_arrays_ms': packed_to_arrays_ms,
                   'rclpy_floor_round_trip_ms_median': statistics.median(floor_packed)},

        'builtin_object_overhead_ms_median': statistics.median(small_rows),
        'rclpy_floor_ms_median': {'mesh_10k_round_trip': statistics.median(floor_mesh),
                                  'builtin_round_trip': statistics.median(floor_small)},
        'soak': {'requests': args.soak, 'succeeded': soak_ok, 'seconds': soak_s,
                 'rss_idle_mb': rss_idle, 'rss_after_warmup_mb': rss_start, 'rss_end_mb': rss_end,
                 'rss_peak_mb': rss_peak, 'sampled_every_requests': len(requests),
                 'growth_mb': growth, 'trend_mb': trend},
        'node_exit_status': node_status,
        'targets': {'overhead_ms': TARGET_OVERHEAD_MS, 'growth_mb': TARGET_GROWTH_MB},
        'machine': {'python': platform.python_version(), 'cpus': os.cpu_count(),
                    'platform': platform.platform()},
        'date': time.strftime('%Y-%m-%d %H:%M:%S'),
    }
    os.makedirs(os.path.dirname(RESULTS), exist_ok=True)
    with open(RESULTS, 'w', encoding='utf-8') as handle:
        json.dump(result, handle, indent=2)

    ok_o = 'OK' if med_packed < TARGET_OVERHEAD_MS else 'OVER TARGET'
    pk = result['packed']
    ok_g = 'OK' if growth < TARGET_GROWTH_MB else 'OVER TARGET'
    print(f'grasp_apso node benchmark ({platform.python_version()}, {os.cpu_count()} CPUs)')
    print(f'{"measure":<58}{"value":>14}')
    print('-' * 72)
    print(f'{"service overhead, 10,000-triangle mesh inline packed, median":<58}{med_packed:>11.1f} ms  [{ok_o}, target < {TARGET_OVERHEAD_MS:g} ms]')
    print(f'{"  p90 / min / max":<58}{pk["overhead_ms"]["p90"]:>6.1f} / {min(packed_overhead):.1f} / {max(packed_overhead):.1f} ms')
    print(f'{"  round trip median (planning_time median)":<58}{pk["round_trip_ms_median"]:>11.1f} ms  ({pk["planning_time_ms_median"]:.1f} ms)')
    print(f'{"  request size":<58}{len(packed_data) / 1024:>11.0f} KiB')
    print(f'{"  of which rclpy serialise (client) / deserialise (node)":<58}{serialize_packed_ms:>6.1f} / {deserialize_packed_ms:.1f} ms')
    print(f'{"  node: packed fields -> numpy arrays":<58}{packed_to_arrays_ms:>11.2f} ms')
    print(f'{"service overhead, the same mesh as shape_msgs/Mesh, median":<58}{med:>11.1f} ms  (information)')
    print(f'{"  p90 / min / max":<58}{result["overhead_ms"]["p90"]:>6.1f} / {min(overhead):.1f} / {max(overhead):.1f} ms')
    print(f'{"  round trip median (planning_time median)":<58}{result["round_trip_ms_median"]:>11.1f} ms  ({result["planning_time_ms_median"]:.1f} ms)')
    print(f'{"  request size":<58}{len(data) / 1024:>11.0f} KiB')
    print(f'{"  of which rclpy serialise (client) / deserialise (node)":<58}{serialize_ms:>6.1f} / {deserialize_ms:.1f} ms')
    print(f'{"  node: Mesh message -> numpy arrays":<58}{to_arrays_ms:>11.1f} ms')
    print(f'{"  first call (validation + SDF grid): round trip":<58}{cold_rt * 1000:>11.1f} ms')
    print(f'{"service overhead, built-in object (no mesh), median":<58}{result["builtin_object_overhead_ms_median"]:>11.1f} ms')
    print(f'{"rclpy floor: round trip to a server answering at once":<58}')
    print(f'{"  packed mesh / shape_msgs/Mesh / built-in object, median":<58}{statistics.median(floor_packed):>6.1f} / '
          f'{statistics.median(floor_mesh):.1f} / {statistics.median(floor_small):.1f} ms')
    print(f'{"node overhead above the floor: packed / Mesh / built-in":<58}{med_packed - statistics.median(floor_packed):>6.1f} / '
          f'{med - statistics.median(floor_mesh):.1f} / '
          f'{result["builtin_object_overhead_ms_median"] - statistics.median(floor_small):.1f} ms')
    print(f'{f"soak: {args.soak} sequential requests ({soak_ok} succeeded)":<58}{soak_s:>11.1f} s')
    print(f'{"  node RSS idle / after warm-up / end / peak":<58}{rss_idle:>6.1f} / {rss_start:.1f} / {rss_end:.1f} / {rss_peak:.1f} MB')
    print(f'{"  RSS growth over the soak":<58}{growth:>11.1f} MB  [{ok_g}, target < {TARGET_GROWTH_MB:g} MB]')
    print(f'  RSS after every pass over the {len(requests)} requests (requests: MB): '
          + ', '.join(f'{n}: {m:.1f}' for n, m in trend))
    print(f'node exit status after SIGINT: {node_status}')
    print(f'written: {os.path.relpath(RESULTS, ROOT)}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
