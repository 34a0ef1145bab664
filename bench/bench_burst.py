"""Bursts against the node in its own process (issue 19.6): ``--clients`` client processes
each send ``--per-client`` requests at once, ``--runs`` times; every request must get a
reply (a plan or "busy").

Each run starts the node (``python -m grasp_apso.ros.node``), waits for "ready", then
starts the client processes together; each one creates its client, waits for the
service, releases all its requests at the same moment as the others (a shared start
time) and prints one line per reply. A request without a reply within ``--timeout`` s
is LOST. The node's output is searched for rmw's "client will not receive response" /
rclpy's "failed to send response" (a reply dropped by the middleware) and for the
node's own "response sent again" lines (the mitigation at work).

    .venv/bin/python bench/bench_burst.py [--runs 10] [--clients 10] [--per-client 3] [--in-process]

``--in-process``: the clients are nodes of the bench process (one executor each), as
test_node_process.py's burst test sends them.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'test'))
os.environ.setdefault('ROS_DOMAIN_ID', str(os.getpid() % 30 + 140))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from node_helpers import PYTHON, LineReader, ros_env  # noqa: E402

SERVICE = '/grasp_apso/plan_grasp'

CLIENT = r'''
import sys, time
import rclpy
from grasp_apso_interfaces.srv import PlanGrasp
service, index, n, start = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
timeout = float(sys.argv[5])
rclpy.init()
node = rclpy.create_node(f"burst_client_{index}")
client = node.create_client(PlanGrasp, service)
if not client.wait_for_service(timeout_sec=30.0):
    print("NOSERVICE", flush=True); sys.exit(2)
while time.time() < start:
    time.sleep(0.001)
futures = []
for r in range(n):
    req = PlanGrasp.Request()
    req.object_name = ("cube", "sphere", "barrel")[(index + r) % 3]
    req.object_pose.header.frame_id = "world"
    req.object_pose.pose.orientation.w = 1.0
    req.particles, req.iterations, req.seed = 30, 20, index
    futures.append(client.call_async(req))
deadline = time.monotonic() + timeout
while time.monotonic() < deadline and not all(f.done() for f in futures):
    rclpy.spin_once(node, timeout_sec=0.05)
for r, f in enumerate(futures):
    if f.done():
        res = f.result()
        kind = "busy" if res.message.startswith("busy") else ("ok" if res.success else "failed")
        print(f"REPLY {index} {r} {kind} {res.message[:60]!r}", flush=True)
    else:
        print(f"LOST {index} {r}", flush=True)
node.destroy_node()
rclpy.try_shutdown()
'''

DROPPED = ('client will not receive response', 'failed to send response')


def _in_process_answers(clients: int, per_client: int, timeout: float) -> list[str]:
    """The clients as the test does it: nodes of this process, each with its own executor."""
    import rclpy

    from grasp_apso_interfaces.srv import PlanGrasp
    from node_helpers import burst_calls, identity_pose

    batches = []
    for c in range(clients):
        batch = []
        for r in range(per_client):
            req = PlanGrasp.Request()
            req.object_name = ("cube", "sphere", "barrel")[(c + r) % 3]
            req.object_pose = identity_pose('world')
            req.particles, req.iterations, req.seed = 30, 20, c
            batch.append(req)
        batches.append(batch)
    context = rclpy.context.Context()
    rclpy.init(context=context)
    try:
        answers = burst_calls(context, SERVICE, batches, clients, timeout)
    finally:
        rclpy.shutdown(context=context)
    return [f"LOST {i}" if res is None else
            f"REPLY {i} 0 {'busy' if res.message.startswith('busy') else ('ok' if res.success else 'failed')} "
            for i, (res, _) in enumerate(answers)]


def one_run(clients: int, per_client: int, timeout: float, start_delay: float, in_process: bool = False) -> dict:
    node = subprocess.Popen([PYTHON, '-m', 'grasp_apso.ros.node'], cwd=ROOT, env=ros_env(),
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    node_out = LineReader(node.stdout)
    try:
        if not node_out.wait(lambda lines: any('ready' in l for l in lines), 120.0):
            raise RuntimeError('node not ready\n' + node_out.text())
        if in_process:
            outs = ['\n'.join(_in_process_answers(clients, per_client, timeout))]
            return _summary(outs, node, node_out)
        start = time.time() + start_delay  # 0: each client sends as soon as it sees the service
        procs = [subprocess.Popen([PYTHON, '-c', CLIENT, SERVICE, str(i), str(per_client), repr(start), str(timeout)],
                                  cwd=ROOT, env=ros_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                  text=True) for i in range(clients)]
        outs = [p.communicate(timeout=timeout + 60.0)[0] for p in procs]
        return _summary(outs, node, node_out)
    finally:
        if node.poll() is None:
            node.kill()


def _summary(outs: list[str], node: subprocess.Popen, node_out: LineReader) -> dict:
    node.send_signal(signal.SIGINT)
    try:
        node.wait(timeout=15.0)
    except subprocess.TimeoutExpired:
        node.kill()
    lines = [l for out in outs for l in out.splitlines()]
    node_text = node_out.text()
    return {
        'ok': sum(l.startswith('REPLY') and ' ok ' in l for l in lines),
        'busy': sum(l.startswith('REPLY') and ' busy ' in l for l in lines),
        'failed': sum(l.startswith('REPLY') and ' failed ' in l for l in lines),
        'lost': sum(l.startswith('LOST') for l in lines),
        'no_service': sum(l.startswith('NOSERVICE') for l in lines),
        'dropped_by_rmw': sum(any(d in l for d in DROPPED) for l in node_text.splitlines()),
        'resent': sum('response sent again' in l for l in node_text.splitlines()),
        'requests_logged': sum(' particles x ' in l or ': busy' in l for l in node_text.splitlines()),
        'notes': [l for l in node_text.splitlines() if 'sent again' in l or any(d in l for d in DROPPED)],
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--runs', type=int, default=10)
    parser.add_argument('--clients', type=int, default=10)
    parser.add_argument('--per-client', type=int, default=3)
    parser.add_argument('--timeout', type=float, default=45.0, help='s a client waits for its replies')
    parser.add_argument('--start-delay', type=float, default=0.0,
                        help='s after the clients start when all send (0: each as soon as it sees the service, '
                             'the race where a reply can be sent before the node matched the client)')
    parser.add_argument('--in-process', action='store_true',
                        help='the clients are nodes of this process, one executor each (as the test sends them)')
    args = parser.parse_args()
    total_lost = 0
    for run in range(1, args.runs + 1):
        result = one_run(args.clients, args.per_client, args.timeout, args.start_delay, args.in_process)
        total_lost += result['lost']
        notes = result.pop('notes')
        print(f'run {run}: ' + ', '.join(f'{k} {v}' for k, v in result.items()), flush=True)
        for line in notes:
            print('   node:', line, flush=True)
    print(f'lost replies in all: {total_lost} of {args.runs * args.clients * args.per_client}')
    return 1 if total_lost else 0


if __name__ == '__main__':
    sys.exit(main())
