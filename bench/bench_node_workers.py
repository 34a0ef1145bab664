"""Throughput of the grasp_apso node with ``workers`` 1 and 2 (issue 15): four concurrent
callers, each sending the same sequence of plans, against the node in its own process.

For each setting the node is started (queue_length 8 so that no request is answered
"busy"), warmed up, and then 4 callers (one client node and executor each) send
``--rounds`` requests each, one after the other, all four at once. Throughput = planned
requests / wall time. The whole measurement is repeated ``--repeats`` times per setting,
alternating the settings (1, 2, 1, 2, ...) so that load from elsewhere on the machine
hits both alike; the table quotes medians and the ratio of the medians.

Prints a table and writes ``bench/results/node_workers.json``.

    .venv/bin/python bench/bench_node_workers.py [--rounds 6] [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import statistics
import subprocess
import sys
import threading
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, 'test'))
os.environ.setdefault('ROS_DOMAIN_ID', str(os.getpid() % 30 + 140))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

import rclpy  # noqa: E402

from grasp_apso_interfaces.srv import PlanGrasp  # noqa: E402

from node_helpers import DISCOVERY_TIMEOUT, LineReader, SpinningNode, identity_pose, ros_env, wait_future  # noqa: E402

RESULTS = os.path.join(ROOT, 'bench', 'results', 'node_workers.json')
SERVICE = '/grasp_apso/plan_grasp'
OBJECTS = ('cube', 'sphere', 'barrel', 'fish')
CALLERS = 4


def _request(i: int) -> PlanGrasp.Request:
    req = PlanGrasp.Request()
    req.object_name = OBJECTS[i % len(OBJECTS)]
    req.object_pose = identity_pose('world')
    req.particles, req.iterations, req.seed, req.max_grasps = 60, 50, i, 1
    return req


def _caller(context, index: int, rounds: int, out: dict, start: threading.Barrier) -> None:
    with SpinningNode(context, f'bench_workers_caller_{os.getpid()}_{index}', num_threads=1) as spun:
        client = spun.node.create_client(PlanGrasp, SERVICE)
        found = client.wait_for_service(timeout_sec=DISCOVERY_TIMEOUT)
        start.wait(timeout=DISCOVERY_TIMEOUT + 60.0)  # every caller found the service: the clock starts
        if not found:
            out[index] = ('no service', 0)
            return
        ok = 0
        for r in range(rounds):
            res = wait_future(client.call_async(_request(100 * index + r)), 300.0)
            ok += bool(res is not None and res.success)
        out[index] = ('done', ok)


def measure(workers: int, rounds: int) -> dict:
    """Start a node with ``workers``, warm it up, run 4 callers x ``rounds``; requests/s."""
    node = subprocess.Popen(
        [sys.executable, '-m', 'grasp_apso.ros.node', '--ros-args',
         '-p', f'workers:={workers}', '-p', 'queue_length:=8'],
        cwd=ROOT, env=ros_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    out = LineReader(node.stdout)
    context = rclpy.context.Context()
    rclpy.init(context=context)
    warm = SpinningNode(context, 'bench_workers_warm', num_threads=1).start()
    try:
        client = warm.node.create_client(PlanGrasp, SERVICE)
        if not client.wait_for_service(timeout_sec=DISCOVERY_TIMEOUT):
            raise RuntimeError('node did not come up:\n' + out.text())
        for i in range(2):  # kernels loaded, every object's grid cached
            for name_index in range(len(OBJECTS)):
                wait_future(client.call_async(_request(name_index + i)), 300.0)
        results: dict = {}
        start = threading.Barrier(CALLERS + 1)
        threads = [threading.Thread(target=_caller, args=(context, i, rounds, results, start)) for i in range(CALLERS)]
        for t in threads:
            t.start()
        start.wait(timeout=DISCOVERY_TIMEOUT + 60.0)
        t0 = time.perf_counter()
        for t in threads:
            t.join(timeout=900.0)
        wall = time.perf_counter() - t0
        planned = sum(ok for status, ok in results.values() if status == 'done')
        return {'workers': workers, 'requests': CALLERS * rounds, 'planned': planned, 'wall_s': wall,
                'requests_per_s': planned / wall}
    finally:
        warm.close()
        rclpy.try_shutdown(context=context)
        node.send_signal(signal.SIGINT)
        try:
            node.wait(timeout=15.0)
        except subprocess.TimeoutExpired:
            node.kill()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--rounds', type=int, default=6, help='requests per caller (default 6)')
    parser.add_argument('--repeats', type=int, default=3, help='measurements per setting (default 3)')
    args = parser.parse_args(argv)
    runs: dict[int, list[dict]] = {1: [], 2: []}
    for _ in range(args.repeats):
        for workers in (1, 2):
            runs[workers].append(measure(workers, args.rounds))
            r = runs[workers][-1]
            print(f"  workers {workers}: {r['planned']}/{r['requests']} planned in {r['wall_s']:.1f} s "
                  f"({r['requests_per_s']:.2f} requests/s)", flush=True)
    med = {w: statistics.median(r['requests_per_s'] for r in rs) for w, rs in runs.items()}
    ratio = med[2] / med[1]
    print(f"grasp_apso node throughput, {CALLERS} concurrent callers, 60 particles x 50 iterations, "
          f"median of {args.repeats}")
    print(f"  workers 1: {med[1]:.2f} requests/s")
    print(f"  workers 2: {med[2]:.2f} requests/s")
    print(f"  ratio 2/1: {ratio:.2f} (target >= 1.7)")
    os.makedirs(os.path.dirname(RESULTS), exist_ok=True)
    with open(RESULTS, 'w', encoding='utf-8') as handle:
        json.dump({'machine': {'python': platform.python_version(), 'cpus': os.cpu_count(),
                               'load_average': os.getloadavg()},
                   'callers': CALLERS, 'rounds': args.rounds, 'runs': runs,
                   'median_requests_per_s': med, 'ratio': ratio}, handle, indent=2)
    print(f"written {os.path.relpath(RESULTS, ROOT)}")
    return 0


if __name__ == '__main__':
    sys.exit(main())
