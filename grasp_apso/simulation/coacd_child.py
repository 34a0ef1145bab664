"""CoACD on one mesh, in a process of its own, so that the decomposition can be stopped.

Started by :mod:`grasp_apso.simulation.convex` as ``python coacd_child.py MESH.npz OUT.npz
PARAMS_JSON CPU_SECONDS``: limits its own CPU time to ``CPU_SECONDS`` and asks the kernel
to kill it when its parent dies (so an orphan cannot run on); then reads the vertices and faces from ``MESH.npz``, runs ``coacd.run_coacd``
with the keyword arguments in ``PARAMS_JSON`` and writes the parts' vertices to
``OUT.npz`` (``n``, ``p0`` ... ``p{n-1}``; written to a temporary file first, then
renamed, so a reader never sees half a file). Exit status 0 on success, 1 on a CoACD
error (its message on stderr). Imports only numpy and coacd (not this package): the
parent may run from a source tree that the child's interpreter does not see.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile

import numpy as np


def _bound_self(cpu_seconds: int) -> None:
    """CPU-time limit (the kernel kills past it) and death with the parent (Linux)."""
    import resource

    resource.setrlimit(resource.RLIMIT_CPU, (cpu_seconds, cpu_seconds + 5))
    try:
        import ctypes
        import signal

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGKILL))  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # not Linux: the CPU limit still bounds it
        pass


def main(argv: list[str]) -> int:
    """Decompose the mesh of ``argv[1]`` into ``argv[2]`` with the parameters ``argv[3]``."""
    mesh_path, out_path, params, cpu_seconds = argv[1], argv[2], json.loads(argv[3]), int(argv[4])
    _bound_self(cpu_seconds)
    import coacd

    coacd.set_log_level("error")
    with np.load(mesh_path, allow_pickle=False) as data:
        vertices = np.asarray(data["vertices"], dtype=float)
        faces = np.asarray(data["faces"], dtype=np.int32)
    try:
        raw = coacd.run_coacd(coacd.Mesh(vertices, faces), **params)
    except Exception as exc:  # CoACD raises plain RuntimeErrors from C++
        print(f"CoACD failed: {exc}", file=sys.stderr)
        return 1
    parts = {f"p{i}": np.asarray(v, dtype=float) for i, (v, _f) in enumerate(raw)}
    fd, tmp = tempfile.mkstemp(dir=os.path.dirname(out_path) or ".", suffix=".part.tmp")
    with os.fdopen(fd, "wb") as handle:
        np.savez(handle, n=np.array(len(parts)), **parts)
    os.replace(tmp, out_path)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
