"""A real two-node Ray cluster on this machine, for tests: ``ray start --head`` and a second
``ray start --address`` (each ``--block``, one CPU, its own temporary folder and ports).

Token authentication with a token of its own: the processes get a private ``HOME`` (in the
cluster's temporary folder) whose ``.ray/auth_token`` holds a fresh token, and no
``RAY_AUTH_MODE``. ``ray start --head`` then turns token authentication on by itself, as
it does on a machine where any local ``ray.init()`` has written ``~/.ray/auth_token`` (the
second node is told ``RAY_AUTH_MODE=token``: it would not find out by itself); a client
given :attr:`Cluster.env` finds the token there and must turn the mode on itself (as
``grasp_apso_batch --ray ADDRESS`` does). No other process can submit work to it.

Stopped by process id, never with ``ray stop`` (that would end every Ray on the machine,
other test runs' included): SIGTERM to each ``ray start --block`` process (which stops the
node's processes), then SIGKILL to whatever of the node's process tree is left.
"""

from __future__ import annotations

import contextlib
import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

RAY = str(Path(sys.executable).with_name("ray"))
STARTED = "Ray runtime started"


@dataclass(frozen=True)
class Cluster:
    """A running cluster: ``address`` (host:port of the head), ``nodes`` (role -> node id),
    ``env`` (the environment a client process needs: this environment + the token)."""

    address: str
    nodes: dict[str, str]
    env: dict[str, str]


class _Node:
    """One ``ray start --block`` process whose output is read by a thread."""

    def __init__(self, role: str, args: list[str], temp_dir: Path, env: dict[str, str]):
        self.role = role
        self.lines: list[str] = []
        self.started = threading.Event()
        self.proc = subprocess.Popen([RAY, "start", "--block", *args, "--temp-dir", str(temp_dir)],
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                     env=env, start_new_session=True)
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.lines.append(line.rstrip())
            if STARTED in line:
                self.started.set()
        self.started.set()  # the process ended: wake the waiter (who sees it is not running)

    def wait_started(self, timeout: float) -> None:
        if not self.started.wait(timeout) or self.proc.poll() is not None:
            raise RuntimeError(f"ray start ({self.role}) did not start within {timeout:.0f} s:\n"
                               + "\n".join(self.lines[-30:]))

    def stop(self, timeout: float = 30.0) -> None:
        tree = _descendants(self.proc.pid)
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                pass
        for pid in tree:  # whatever the graceful stop left behind, by pid
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pid, signal.SIGKILL)
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.proc.wait(10)
        self.reader.join(10)


def _descendants(pid: int) -> list[int]:
    """``pid`` and every process below it (from /proc), children first."""
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", encoding="utf-8") as handle:
                ppid = int(handle.read().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue
        children.setdefault(ppid, []).append(int(entry))
    out, stack = [], [pid]
    while stack and len(out) < 10_000:
        p = stack.pop()
        out.append(p)
        stack.extend(children.get(p, []))
    return out[::-1]


def free_ports(n: int) -> list[int]:
    """``n`` distinct TCP ports free right now on 127.0.0.1."""
    socks = [socket.socket() for _ in range(n)]
    try:
        for s in socks:
            s.bind(("127.0.0.1", 0))
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


def _node_ports(ports: list[int]) -> list[str]:
    agent, agent_grpc, runtime_env, metrics, manager, objects = ports
    return ["--dashboard-agent-listen-port", str(agent), "--dashboard-agent-grpc-port", str(agent_grpc),
            "--runtime-env-agent-port", str(runtime_env), "--metrics-export-port", str(metrics),
            "--node-manager-port", str(manager), "--object-manager-port", str(objects),
            "--min-worker-port", "0", "--max-worker-port", "0"]


def _node_ids(address: str, temp_dirs: dict[str, Path], env: dict[str, str]) -> dict[str, str]:
    """role -> node id, asked of the cluster (each node's raylet socket lies in its temp dir)."""
    code = ("import json, ray; ray.init(address=%r, log_to_driver=False); "
            "print(json.dumps([(n['NodeID'], n['RayletSocketName']) for n in ray.nodes() if n['Alive']]))"
            % address)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env)
    if out.returncode != 0:
        raise RuntimeError(f"cannot list the cluster's nodes: {out.stderr[-2000:]}")
    nodes = json.loads(out.stdout.strip().splitlines()[-1])
    return {role: node for role, folder in temp_dirs.items()
            for node, sock in nodes if sock.startswith(str(folder))}


@contextlib.contextmanager
def two_node_cluster(cpus: int = 1, timeout: float = 120.0) -> Iterator[Cluster]:
    """Start a head and a second node (``cpus`` CPUs each) on 127.0.0.1; stop both after."""
    # Short folder names: Ray's unix socket paths (under the temp dir) must stay < 108 bytes.
    base = Path(tempfile.mkdtemp(prefix="gar"))
    temp_dirs = {"head": base / "h", "worker": base / "w"}
    token = base / "home" / ".ray" / "auth_token"
    token.parent.mkdir(parents=True)
    token.touch(mode=0o600)  # readable by this user only, before the token goes in
    token.write_text(secrets.token_hex(32))
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_AUTH")}
    env.update({"HOME": str(base / "home"), "RAY_USAGE_STATS_ENABLED": "0"})
    ports = free_ports(14)
    address = f"127.0.0.1:{ports[0]}"
    common = ["--node-ip-address", "127.0.0.1", "--num-cpus", str(cpus),
              "--object-store-memory", str(100 * 1024 * 1024), "--disable-usage-stats"]
    nodes: list[_Node] = []
    try:
        nodes.append(_Node("head", ["--head", "--port", str(ports[0]), "--include-dashboard", "false",
                                    "--dashboard-port", str(ports[1]), *common, *_node_ports(ports[2:8])],
                           temp_dirs["head"], env))
        nodes[0].wait_started(timeout)
        nodes.append(_Node("worker", ["--address", address, *common, *_node_ports(ports[8:14])],
                           temp_dirs["worker"], {**env, "RAY_AUTH_MODE": "token"}))
        nodes[1].wait_started(timeout)
        ids = _node_ids(address, temp_dirs, {**env, "RAY_AUTH_MODE": "token"})
        if len(set(ids.values())) != 2:
            raise RuntimeError(f"expected 2 live nodes, found {ids}")
        yield Cluster(address, ids, env)
    finally:
        for node in reversed(nodes):
            node.stop()
        shutil.rmtree(base, ignore_errors=True)
