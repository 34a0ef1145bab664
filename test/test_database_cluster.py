"""``grasp_apso_batch --ray ADDRESS`` on a real two-node Ray cluster on this machine
(``ray start --head`` + ``ray start --address``, one CPU each): the tasks run on both nodes
and the database holds the same rows as the local process pool's (same seeds, same grasps;
only the timing columns differ). The cluster turns token authentication on by itself (a
token in its HOME, as on a machine where a local Ray ran before) and the batch joins it
without being told (grasp_apso.database.engines._token_auth_as_ray_start).

The reduced version (2 small objects, about a minute with the cluster's start) runs by
default; the fuller one (6 objects, a manifest with a table and a pose, a corrupt file) is
marked slow.
"""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from grasp_apso.database.batch import BatchConfig, run_batch
from grasp_apso.model.builtin import builtin
from grasp_apso.search.options import PlanOptions

from ray_cluster import two_node_cluster

pytest.importorskip("ray")

REPO = Path(__file__).resolve().parents[1]
SEED = 11
OPTIONS = PlanOptions(particles=20, iterations=10, max_grasps=2)
#: Columns that depend on when and how fast a row was made, not on what was planned.
TIMING = ("planning_time", "created")


@pytest.fixture(scope="module")
def cluster():
    with two_node_cluster(cpus=1) as running:
        yield running


def test_joining_a_cluster_uses_the_token_ray_start_found(tmp_path, monkeypatch):
    from grasp_apso.database import engines

    monkeypatch.delenv("RAY_AUTH_MODE", raising=False)
    monkeypatch.delenv("RAY_AUTH_TOKEN", raising=False)
    monkeypatch.delenv("RAY_AUTH_TOKEN_PATH", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path))
    engines._token_auth_as_ray_start()
    assert "RAY_AUTH_MODE" not in os.environ  # no token anywhere: Ray's default
    (tmp_path / ".ray").mkdir()
    (tmp_path / ".ray" / "auth_token").write_text("0" * 64)
    engines._token_auth_as_ray_start()
    assert os.environ["RAY_AUTH_MODE"] == "token"
    monkeypatch.setenv("RAY_AUTH_MODE", "disabled")  # an explicit choice is kept
    engines._token_auth_as_ray_start()
    assert os.environ["RAY_AUTH_MODE"] == "disabled"


def _inputs(folder: Path, full: bool) -> list[str]:
    folder.mkdir()
    if not full:
        for name in ("cube", "sphere"):
            builtin(name).mesh.export(folder / f"{name}.stl")
        return [str(folder)]
    for i, name in enumerate(("cube", "sphere", "barrel", "cube", "sphere")):
        mesh = builtin(name).mesh.copy()
        mesh.apply_scale(0.8 + 0.1 * i)
        mesh.export(folder / f"obj{i}.stl")
    (folder / "corrupt.stl").write_bytes(b"solid nothing\nnot an stl\n" * 4)
    manifest = folder.parent / "manifest.csv"
    manifest.write_text("id,path,scale,pose,table\n"
                        f"on_table,{folder / 'obj0.stl'},1.2,0 0 0.1 0 0 0.3826834 0.9238795,true\n")
    return [str(folder), str(manifest)]


def _sorted(table: pa.Table) -> pa.Table:
    keep = [c for c in table.column_names if c not in TIMING]
    return table.select(keep).sort_by([("object_id", "ascending"), ("rank", "ascending")])


def _exact(value):
    """``value`` with NaN made comparable (NaN == NaN), every other float compared exactly."""
    if isinstance(value, list):
        return [_exact(v) for v in value]
    return "NaN" if isinstance(value, float) and math.isnan(value) else value


def _failures(db: Path) -> list[tuple]:
    rows = pq.read_table(db / "_failures").to_pylist()
    return sorted((r["object_id"], r["error"], r["retry"]) for r in rows)


@pytest.mark.parametrize("full", [False, pytest.param(True, marks=pytest.mark.slow)], ids=["reduced", "full"])
def test_batch_on_two_nodes_writes_the_local_pools_rows(cluster, tmp_path, full):
    inputs = _inputs(tmp_path / "meshes", full)
    ray_db = tmp_path / "ray.db"
    cmd = [sys.executable, "-m", "grasp_apso.tools.batch_cli", *inputs, "--out", str(ray_db),
           "--ray", cluster.address, "--seed", str(SEED), "--particles", str(OPTIONS.particles),
           "--iterations", str(OPTIONS.iterations), "--grasps", str(OPTIONS.max_grasps),
           "--progress", "lines"]
    run = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=400, env=cluster.env)
    print(run.stderr[-3000:])
    assert run.returncode == (1 if full else 0), run.stderr  # 1: the corrupt file failed
    assert "(ray, 2 workers on 2 nodes" in run.stderr
    # Each object's progress line names the Ray node it ran on: both nodes worked.
    used = re.findall(r"grasps in [\d.]+ s on node ([0-9a-f]+)", run.stderr)
    planned = 6 if full else 2
    assert len(used) == planned
    assert set(used) == set(cluster.nodes.values()), (used, cluster.nodes)

    local_db = tmp_path / "local.db"
    summary = run_batch(inputs, BatchConfig(out=str(local_db), options=OPTIONS, seed=SEED, workers=2,
                                            progress="none"))
    assert summary.planned == planned and summary.nodes == {}
    # Read as a user would: the whole database folder, by pyarrow.
    remote, local = _sorted(pq.read_table(ray_db)), _sorted(pq.read_table(local_db))
    assert remote.num_rows == local.num_rows >= planned
    assert remote.column_names == local.column_names
    for name in remote.column_names:  # column by column, so that a failure names the column
        assert _exact(remote.column(name).to_pylist()) == _exact(local.column(name).to_pylist()), name
    assert _failures(ray_db) == _failures(local_db)
    assert len(_failures(ray_db)) == (1 if full else 0)
