"""Load benchmark of the grasp_apso node (issue 14): a burst and a long sequential run.

The node runs in its own process (``python -m grasp_apso.ros.node`` with the shipped
parameter file, a DDS domain of its own); clients run here, each burst client with an
executor of its own. Measured:

1. a burst: 30 simultaneous requests (10 clients x 3, built-in objects, 30 particles x
   20 iterations): how many were planned, answered "busy" and never answered, latency
   percentiles;
2. 200 sequential requests from one client: latency percentiles (round trip and the
   node's ``planning_time``), answer counts;
3. the node's resident memory (VmRSS) after start-up and one warm-up request, after 50
   and after 200 sequential requests.

Prints a table and writes ``bench/results/load.json``.

    .venv/bin/python bench/bench_load.py [--sequential 200] [--queue-length 4] [--workers 1]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import subprocess
import sys
import threading
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, 'test'))
os.environ.setdefault('ROS_DOMAIN_ID', str(os.getpid() % 30 + 170))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

import rclpy  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402

from grasp_apso_interfaces.srv import PlanGrasp  # noqa: E402

from node_helpers import DISCOVERY_TIMEOUT, LineReader, burst_calls, identity_pose, ros_env, wait_future  # noqa: E402

RESULTS = os.path.join(ROOT, 'bench', 'results', 'load.json')
PARAMS_FILE = os.path.join(ROOT, 'config', 'grasp_apso.yaml')
SERVICE = '/grasp_apso/plan_grasp'
OBJECTS = ('cube', 'sphere', 'barrel', 'fish')


def _request(i: int) -> PlanGrasp.Request:
    req = PlanGrasp.Request()
    req.object_name = OBJECTS[i % len(OBJECTS)]
    req.object_pose = identity_pose('world')
    req.particles, req.iterations, req.seed = 30, 20, i
    return req


def rss_mb(pid: int) -> float:
    """Resident memory of a process, MB (VmRSS)."""
    with open(f'/proc/{pid}/status', encoding='ascii') as handle:
        for line in handle:
            if line.startswith('VmRSS:'):
                return int(line.split()[1]) / 1024.0
    return float('nan')


def percentiles(values: list[float]) -> dict[str, float]:
    if not values:
        return {'p50': float('nan'), 'p90': float('nan'), 'p99': float('nan')}
    a = np.asarray(values) * 1000.0
    return {k: float(np.percentile(a, q)) for k, q in (('p50', 50), ('p90', 90), ('p99', 99))}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--sequential', type=int, default=200)
    parser.add_argument('--queue-length', type=int, default=4)
    parser.add_argument('--workers', type=int, default=1)
    args = parser.parse_args(argv)

    node = subprocess.Popen(
        [sys.executable, '-m', 'grasp_apso.ros.node', '--ros-args', '--params-file', PARAMS_FILE,
         '-p', f'queue_length:={args.queue_length}', '-p', f'workers:={args.workers}'],
        cwd=ROOT, env=ros_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    out = LineReader(node.stdout)
    context = rclpy.context.Context()
    rclpy.init(context=context)
    client_node = rclpy.create_node('bench_load_client', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(client_node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    report: dict = {'machine': {'python': platform.python_version(), 'cpus': os.cpu_count()},
                    'queue_length': args.queue_length, 'workers': args.workers}
    try:
        client = client_node.create_client(PlanGrasp, SERVICE)
        if not client.wait_for_service(timeout_sec=DISCOVERY_TIMEOUT):
            print(out.text(), file=sys.stderr)
            return 1
        wait_future(client.call_async(_request(0)), 120.0)  # warm-up (kernels loaded)
        report['rss_mb_before'] = rss_mb(node.pid)

        # 1. The burst.
        batches = [[_request(10 * c + r) for r in range(3)] for c in range(10)]
        answers = burst_calls(context, SERVICE, batches, 10, timeout=180.0)
        planned = [lat for res, lat in answers if res is not None and not res.message.startswith('busy')]
        busy = [lat for res, lat in answers if res is not None and res.message.startswith('busy')]
        report['burst'] = {
            'requests': len(answers), 'planned': len(planned), 'busy': len(busy),
            'lost': sum(1 for res, _ in answers if res is None),
            'succeeded': sum(1 for res, _ in answers if res is not None and res.success),
            'latency_ms_all': percentiles(planned + busy), 'latency_ms_planned': percentiles(planned),
            'latency_ms_busy': percentiles(busy)}

        # 2. Sequential requests.
        trips, worker, failed = [], [], 0
        for i in range(args.sequential):
            t0 = time.perf_counter()
            res = wait_future(client.call_async(_request(i)), 120.0)
            trips.append(time.perf_counter() - t0)
            worker.append(res.planning_time)
            failed += not res.success
            if i + 1 == 50:
                report['rss_mb_after_50'] = rss_mb(node.pid)
        report['rss_mb_after_200' if args.sequential == 200 else f'rss_mb_after_{args.sequential}'] = rss_mb(node.pid)
        report['sequential'] = {'requests': args.sequential, 'answered': len(trips), 'failed': failed,
                                'round_trip_ms': percentiles(trips), 'planning_time_ms': percentiles(worker)}
    finally:
        executor.shutdown(timeout_sec=5.0)
        spinner.join(timeout=5.0)
        client_node.destroy_node()
        rclpy.try_shutdown(context=context)
        node.send_signal(signal.SIGINT)
        try:
            report['node_exit_status'] = node.wait(timeout=15.0)
        except subprocess.TimeoutExpired:
            node.kill()
            report['node_exit_status'] = None

    b, s = report['burst'], report['sequential']
    rows = [
        ('burst: requests / planned / busy / lost', f"{b['requests']} / {b['planned']} / {b['busy']} / {b['lost']}"),
        ('burst latency p50 / p90 / p99, ms (all answers)',
         ' / '.join(f"{b['latency_ms_all'][k]:.0f}" for k in ('p50', 'p90', 'p99'))),
        ('burst latency of planned answers p50 / p90 / p99, ms',
         ' / '.join(f"{b['latency_ms_planned'][k]:.0f}" for k in ('p50', 'p90', 'p99'))),
        (f"sequential: answered / failed of {s['requests']}", f"{s['answered']} / {s['failed']}"),
        ('sequential round trip p50 / p90 / p99, ms', ' / '.join(f"{s['round_trip_ms'][k]:.1f}" for k in ('p50', 'p90', 'p99'))),
        ('sequential planning_time p50 / p90 / p99, ms',
         ' / '.join(f"{s['planning_time_ms'][k]:.1f}" for k in ('p50', 'p90', 'p99'))),
        ('node RSS before / after 50 / after 200, MB', ' / '.join(
            f"{report.get(k, float('nan')):.1f}" for k in ('rss_mb_before', 'rss_mb_after_50', 'rss_mb_after_200'))),
    ]
    width = max(len(r[0]) for r in rows)
    print(f"grasp_apso load benchmark (queue_length {args.queue_length}, workers {args.workers})")
    for name, value in rows:
        print(f"  {name:<{width}}  {value}")
    os.makedirs(os.path.dirname(RESULTS), exist_ok=True)
    with open(RESULTS, 'w', encoding='utf-8') as handle:
        json.dump(report, handle, indent=2)
    print(f"written {os.path.relpath(RESULTS, ROOT)}")
    return 0 if b['lost'] == 0 else 1


if __name__ == '__main__':
    sys.exit(main())
