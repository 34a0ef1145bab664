"""Grasp database: the batch (local processes and a real local Ray), resume, lock, Ctrl-C,
the reader's lookup (grasp_apso.database), the folder opened by pyarrow, pandas and DuckDB
as it is (and the README's example doing so), databases of the previous layout.

Small swarms (20 particles, 10 iterations, 2 grasps) over three built-in shapes exported to
STL, plus a missing path and a corrupt file. Everything runs for real: worker processes,
Ray with 2 CPUs, a subprocess interrupted with SIGINT.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from readme_blocks import run_readme_example

from grasp_apso.database.batch import BatchConfig, run_batch
from grasp_apso.database.inputs import expand_inputs
from grasp_apso.database.lookup import GraspDatabase
from grasp_apso.database.schema import GRASP_SCHEMA
from grasp_apso.database.store import LEGACY_MARKER, MARKER, GraspStore
from grasp_apso.errors import DatabaseError, InputError
from grasp_apso.model.builtin import builtin
from grasp_apso.model.hand import load_hand, wrist_rotation
from grasp_apso.model.mesh_files import from_file
from grasp_apso.model.scene import BOX, Scene
from grasp_apso.search.candidates import pre_grasp_pose
from grasp_apso.search.options import PlanOptions
from grasp_apso.search.planner import plan

REPO = Path(__file__).resolve().parents[1]
SHAPES = ("cube", "sphere", "barrel")
OPTIONS = PlanOptions(particles=20, iterations=10, max_grasps=2)
SEED = 7


def _config(out: Path, **kw) -> BatchConfig:
    base = dict(out=str(out), options=OPTIONS, seed=SEED, workers=2, progress="none")
    base.update(kw)
    return BatchConfig(**base)


@pytest.fixture(scope="module")
def meshes(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("meshes")
    paths = {}
    for name in SHAPES:
        paths[name] = folder / f"{name}.stl"
        builtin(name).mesh.export(paths[name])
    paths["corrupt"] = folder / "corrupt.stl"
    paths["corrupt"].write_bytes(b"solid nothing\nthis is not an stl file\n" * 4)
    paths["missing"] = folder / "missing.stl"
    return paths


@pytest.fixture(scope="module")
def first_run(meshes, tmp_path_factory):
    """The batch over 3 objects + a missing path + a corrupt file, 2 local workers."""
    out = tmp_path_factory.mktemp("db") / "grasps.db"
    inputs = [str(meshes[k]) for k in (*SHAPES, "missing", "corrupt")]
    t0 = time.perf_counter()
    summary = run_batch(inputs, _config(out))
    return out, inputs, summary, time.perf_counter() - t0


def test_batch_writes_rows_and_records_failures(first_run):
    out, _, summary, seconds = first_run
    print(f"\nfirst run: {seconds:.1f} s (engine start {summary.startup_seconds:.1f} s, "
          f"{summary.objects_per_minute:.1f} objects/min)")
    assert (summary.planned, summary.failed, summary.skipped) == (3, 2, 0)
    grasps = pq.ParquetDataset(out / "grasps").read()
    assert grasps.schema.remove_metadata() == GRASP_SCHEMA.remove_metadata()
    ids = grasps.column("object_id").to_pylist()
    assert set(ids) == set(SHAPES)
    assert all(1 <= ids.count(s) <= OPTIONS.max_grasps for s in SHAPES)
    # Every stored grasp: object-frame wrist with a unit quaternion, 18 + 18 joints, contacts.
    rows = grasps.to_pylist()
    for row in rows:
        assert abs(np.linalg.norm(row["wrist_quaternion"]) - 1.0) < 1e-9
        assert len(row["joint_positions"]) == 18 and len(row["pre_grasp_positions"]) == 18
        assert len(row["contact_points"]) == len(row["contact_fingers"]) >= 2
        assert row["hand_name"] == load_hand().name
        assert json.loads(row["options"])["plan"]["particles"] == 20
        assert row["package_version"]
    cube = from_file(str(Path(rows[0]["source_path"]).with_name("cube.stl")))
    assert cube.mesh_hash in {r["mesh_hash"] for r in rows}
    failures = pq.read_table(out / "_failures").to_pylist()
    by_id = {f["object_id"]: f for f in failures}
    assert set(by_id) == {"missing", "corrupt"}
    assert "file not found" in by_id["missing"]["error"] and by_id["missing"]["retry"]
    assert by_id["corrupt"]["error"].startswith("mesh_uri:") and not by_id["corrupt"]["retry"]
    assert not (out / "_LOCK").exists()


def test_rerun_skips_done_objects_and_is_fast(first_run):
    out, inputs, first, first_seconds = first_run
    rows_before = pq.ParquetDataset(out / "grasps").read().num_rows
    t0 = time.perf_counter()
    again = run_batch(inputs, _config(out))
    seconds = time.perf_counter() - t0
    print(f"\nrerun: {seconds:.2f} s vs first run {first_seconds:.1f} s (ratio {seconds / first_seconds:.3f})")
    # 3 done + the corrupt file (a deterministic failure) skipped; the missing one is retried.
    assert (again.planned, again.skipped, again.failed) == (0, 4, 1)
    assert again.workers == 0  # no engine was started
    assert pq.ParquetDataset(out / "grasps").read().num_rows == rows_before
    assert seconds <= first_seconds / 4


def test_ray_engine_writes_the_same_rows(first_run, meshes, tmp_path):
    pytest.importorskip("ray")
    out, _, _, _ = first_run
    ray_out = tmp_path / "ray.db"
    summary = run_batch([str(meshes[k]) for k in SHAPES], _config(ray_out, engine="ray", workers=2))
    import ray

    assert not ray.is_initialized()  # the engine shut its local Ray down
    assert summary.engine == "ray" and summary.workers == 2
    assert (summary.planned, summary.failed) == (3, 0)
    local = pq.ParquetDataset(out / "grasps").read().sort_by([("object_id", "ascending"), ("rank", "ascending")])
    remote = pq.ParquetDataset(ray_out / "grasps").read().sort_by([("object_id", "ascending"), ("rank", "ascending")])
    assert remote.schema == local.schema
    assert remote.num_rows == local.num_rows
    # Same seeds: the same grasps, whatever the engine.
    assert remote.column("seed").to_pylist() == local.column("seed").to_pylist()
    np.testing.assert_allclose(np.array(remote.column("wrist_position").to_pylist()),
                               np.array(local.column("wrist_position").to_pylist()), atol=1e-9)


def test_lock_held_by_live_process_refused_and_stale_lock_taken_over(meshes, tmp_path):
    out = tmp_path / "locked.db"
    store = GraspStore(out)
    store.create()
    holder = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        (out / "_LOCK").write_text(json.dumps({"pid": holder.pid, "host": os.uname().nodename,
                                              "started": "then"}))
        with pytest.raises(DatabaseError) as info:
            run_batch([str(meshes["missing"])], _config(out))
        assert info.value.field == "--out"
        assert f"pid {holder.pid}" in str(info.value) and "locked" in str(info.value)
    finally:
        holder.kill()
        holder.wait(timeout=10)
    # The holder is gone: its lock is stale and the next batch takes it over.
    summary = run_batch([str(meshes["missing"])], _config(out))
    assert summary.failed == 1
    assert not (out / "_LOCK").exists()


#: grasp_apso_batch with SIGINT's default handler, as in a terminal. A process started with
#: SIGINT ignored (a test run launched as a background job of a non-interactive shell)
#: passes that on to its children, and Python then keeps ignoring it: Ctrl-C would never
#: reach the batch (two fresh-clone runs started with ``(nohup bash -c ... &)`` failed so).
BATCH_AS_IN_A_TERMINAL = ("import signal, sys\n"
                          "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
                          "from grasp_apso.tools.batch_cli import main\n"
                          "sys.exit(main(sys.argv[1:]))")


def test_ctrl_c_leaves_a_readable_database(meshes, tmp_path):
    out = tmp_path / "interrupted.db"
    folder = tmp_path / "many"
    folder.mkdir()
    for i in range(6):  # 6 distinct meshes (scaled cubes and spheres)
        mesh = builtin(SHAPES[i % 2]).mesh.copy()
        mesh.apply_scale(0.8 + 0.05 * i)
        mesh.export(folder / f"obj{i}.stl")
    cmd = [sys.executable, "-c", BATCH_AS_IN_A_TERMINAL, str(folder), "--out", str(out),
           "--workers", "1", "--particles", "20", "--iterations", "10", "--grasps", "2",
           "--flush-seconds", "0", "--progress", "lines"]
    proc = subprocess.Popen(cmd, cwd=REPO, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 180
        while not list((out / "grasps").glob("part-*.parquet")):
            assert proc.poll() is None, proc.stderr.read()
            assert time.monotonic() < deadline, "no part file written within 180 s"
            time.sleep(0.2)
        proc.send_signal(signal.SIGINT)
        rc = proc.wait(timeout=60)
        err = proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    print(err[-600:])
    assert rc == 130, err
    db = GraspDatabase.open(out)
    assert 1 <= len(db) < 6
    assert not (out / "_LOCK").exists()
    assert not list(out.rglob(".*.tmp"))


def _rotation(axis, angle: float) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return Rotation.from_rotvec(axis * angle).as_matrix()


def test_lookup_moves_a_stored_grasp_to_a_rotated_pose(first_run, meshes):
    out, _, _, _ = first_run
    db = GraspDatabase.open(out)
    hand = load_hand()
    obj = from_file(meshes["cube"], name="cube")
    stored = [r for r in pq.ParquetDataset(out / "grasps").read().to_pylist() if r["object_id"] == "cube"]
    # The same plan in this process, at the identity pose, with the object's stored seed.
    result = plan(obj, np.eye(4), OPTIONS, rng=np.random.default_rng(stored[0]["seed"]), hand=hand)
    best = result.candidates[0]
    at_identity = db.lookup(obj.mesh_hash, hand.name, np.eye(4), None, 0.005, 0.08, 5)
    np.testing.assert_allclose(at_identity[0].wrist_pose, best.wrist_pose, atol=1e-9)
    np.testing.assert_allclose(at_identity[0].joint_positions, best.joint_positions, atol=1e-9)

    pose = np.eye(4)
    pose[:3, :3] = _rotation([1.0, -2.0, 0.5], 2.1)
    pose[:3, 3] = [0.4, -0.1, 0.25]
    moved = db.lookup(obj.mesh_hash, hand.name, pose, None, 0.005, 0.06, 5)
    assert len(moved) == len(at_identity) >= 1
    g = moved[0]
    expected = pose @ best.wrist_pose
    np.testing.assert_allclose(g.wrist_pose, expected, atol=1e-9)
    np.testing.assert_allclose(g.pre_grasp_pose, pre_grasp_pose(expected, 0.06), atol=1e-9)
    np.testing.assert_allclose(g.approach, pose[:3, :3] @ best.approach, atol=1e-9)
    # Fingers unchanged; the wrist angles are the palm orientation in the new planning frame.
    np.testing.assert_allclose(g.joint_positions[:15], best.joint_positions[:15], atol=1e-12)
    np.testing.assert_allclose(wrist_rotation(g.joint_positions[15:18][None])[0], expected[:3, :3], atol=1e-9)
    np.testing.assert_allclose(wrist_rotation(g.pre_grasp_positions[15:18][None])[0], expected[:3, :3], atol=1e-9)
    for c, c0 in zip(g.contacts, best.contacts):
        assert c.finger == c0.finger
        np.testing.assert_allclose(c.position, pose[:3, :3] @ c0.position + pose[:3, 3], atol=1e-9)
        np.testing.assert_allclose(c.normal, pose[:3, :3] @ c0.normal, atol=1e-9)
    np.testing.assert_allclose(g.joints, best.joints @ pose[:3, :3].T + pose[:3, 3], atol=1e-9)
    np.testing.assert_allclose(g.wrist_in_object, best.wrist_pose, atol=1e-9)
    assert g.force_closure == best.force_closure and g.epsilon == pytest.approx(best.epsilon)


def test_lookup_filters_by_scene_and_is_fast(first_run, meshes):
    out, _, _, _ = first_run
    db = GraspDatabase.open(out)
    print(f"\nopen: {db.load_seconds * 1000:.1f} ms for {db.rows} rows")
    hand = load_hand()
    obj = from_file(meshes["sphere"])
    pose = np.eye(4)
    pose[:3, 3] = [0.5, 0.0, 0.3]
    times = []
    for _ in range(50):
        t0 = time.perf_counter()
        found = db.lookup(obj.mesh_hash, hand.name, pose, None, 0.005, 0.08, 5)
        times.append(time.perf_counter() - t0)
    print(f"lookup without scene: median {np.median(times) * 1000:.2f} ms")
    assert found and np.median(times) < 0.005
    assert db.lookup("0" * 64, hand.name, pose, None, 0.005, 0.08, 5) == []
    assert db.lookup(obj.mesh_hash, "another_hand", pose, None, 0.005, 0.08, 5) == []
    # A table 1 cm beyond the far side of the cube, the hand coming from above: the best
    # grasp survives, with the table's distance re-measured at the request pose.
    cube = from_file(meshes["cube"])
    found = db.lookup(cube.mesh_hash, hand.name, pose, None, 0.005, 0.08, 5)
    n = -found[0].approach
    vertices = cube.mesh.vertices + pose[:3, 3]
    table = Scene.from_primitives(planes=[(*n, -float((vertices @ n).min()) + 0.01)])
    t0 = time.perf_counter()
    on_table = db.lookup(cube.mesh_hash, hand.name, pose, table, 0.005, 0.08, 5)
    print(f"lookup with a table: {(time.perf_counter() - t0) * 1000:.1f} ms, {len(on_table)}/{len(found)} kept")
    assert on_table and np.allclose(on_table[0].wrist_pose, found[0].wrist_pose)
    assert all(0.005 <= c.scene_distance < 0.2 for c in on_table)
    # A box around the object and the hand: nothing survives.
    box = Scene.from_primitives(obstacles=[(BOX, [1.0, 1.0, 1.0])], obstacle_poses=[pose])
    assert db.lookup(cube.mesh_hash, hand.name, pose, box, 0.005, 0.08, 5) == []
    with pytest.raises(InputError, match="^pose:"):
        db.lookup(obj.mesh_hash, hand.name, np.ones((4, 4)), None, 0.005, 0.08, 5)


def test_corrupt_database_names_the_parameter(first_run, tmp_path):
    out, _, _, _ = first_run
    broken = tmp_path / "broken.db"
    shutil.copytree(out, broken)
    part = sorted((broken / "grasps").glob("part-*.parquet"))[0]
    part.write_bytes(b"PAR1" + b"\x00garbage" * 50)
    for path in (broken, part, tmp_path / "nowhere", tmp_path):
        with pytest.raises(DatabaseError) as info:
            GraspDatabase.open(path)
        assert info.value.field == "grasp_database"
        assert str(info.value).startswith("grasp_database:")
    # A single Parquet file with the grasps columns is a database too.
    single = tmp_path / "single.parquet"
    pq.write_table(pq.ParquetDataset(out / "grasps").read(), single)
    assert len(GraspDatabase.open(single)) == len(SHAPES)


def test_manifests_and_bad_rows(tmp_path, meshes):
    (tmp_path / "m.csv").write_text(
        "id,path,scale,pose,table\n"
        f"a,{meshes['cube']},0.5,,true\n"
        f"b,{meshes['sphere']},,0 0 0.1 0 0 0 1,\n"
        f"c,{meshes['sphere']},-1,,\n"
        f"d,{meshes['sphere']},1,0 0 0 0 0 0 2,\n")
    (tmp_path / "m.jsonl").write_text(
        json.dumps({"id": "e", "path": str(meshes["barrel"]), "pose": [0, 0, 0, 0, 0, 0, 1]}) + "\n"
        + "{not json\n")
    specs = {s.object_id: s for s in expand_inputs([str(tmp_path / "m.csv"), str(tmp_path / "m.jsonl")])}
    assert specs["a"].scale == 0.5 and specs["a"].table is True and not specs["a"].error
    assert specs["b"].pose == (0, 0, 0.1, 0, 0, 0, 1) and specs["b"].table is None
    assert "scale" in specs["c"].error and "pose" in specs["d"].error
    assert specs["e"].pose == (0, 0, 0, 0, 0, 0, 1)
    assert specs["m.jsonl:2"].error.startswith("manifest:")


def _grasp_rows(out: Path) -> list[dict]:
    """The grasps, read part file by part file (independent of directory discovery)."""
    rows = []
    for part in sorted((out / "grasps").glob("part-*.parquet")):
        rows += pq.ParquetFile(part).read().to_pylist()
    return rows


def test_parquet_readers_open_the_folder_as_it_is(first_run, tmp_path):
    import duckdb
    import pandas as pd

    out, _, _, _ = first_run
    db = tmp_path / "grasps.db"
    shutil.copytree(out, db)
    # As during a batch: its lock and a part being written are there too.
    (db / "_LOCK").write_text(json.dumps({"pid": 1, "host": "elsewhere", "started": "now"}))
    (db / "grasps" / ".part-00000000000000000000-1-00001.parquet.tmp").write_bytes(b"PAR1 half")
    expected = sorted((r["object_id"], r["rank"], r["grasp_quality"]) for r in _grasp_rows(db))
    assert len(expected) >= len(SHAPES)
    table = pq.read_table(db)
    assert table.schema.remove_metadata() == GRASP_SCHEMA.remove_metadata()
    assert sorted(zip(*(table.column(c).to_pylist() for c in ("object_id", "rank", "grasp_quality")))) == expected
    df = pd.read_parquet(db)
    assert sorted(zip(df["object_id"], df["rank"], df["grasp_quality"])) == expected
    assert list(df["wrist_position"].iloc[0]) == table.column("wrist_position")[0].as_py()
    rows = duckdb.sql(f"SELECT object_id, rank, grasp_quality FROM read_parquet('{db}/**/*.parquet')").fetchall()
    assert sorted(rows) == expected
    failures = pq.read_table(db / "_failures")
    assert {"missing", "corrupt"} <= set(failures.column("object_id").to_pylist())


def test_readme_database_example_runs(first_run, tmp_path, monkeypatch, capsys):
    out, _, _, _ = first_run
    (tmp_path / "grasps.db").symlink_to(out, target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    ns = run_readme_example("database")
    rows = _grasp_rows(out)
    assert ns["table"].num_rows == len(ns["df"]) == len(rows)
    per_object = {}
    for r in rows:
        n, best = per_object.get(r["object_id"], (0, -1.0))
        per_object[r["object_id"]] = (n + 1, max(best, r["grasp_quality"]))
    assert [(o, n, pytest.approx(b)) for o, n, b in ns["per_object"]] == \
        [(o, n, b) for o, (n, b) in sorted(per_object.items())]
    assert list(ns["best"]["object_id"])[0] == max(
        (r for r in rows if r["rank"] == 0), key=lambda r: r["grasp_quality"])["object_id"]
    assert {"missing", "corrupt"} <= set(ns["failures"]["object_id"])
    assert "corrupt" in capsys.readouterr().out


def _to_first_layout(db: Path) -> None:
    """Rewrite a database in the previous layout (grasp_database.json, failures/*.parquet)."""
    (db / MARKER).rename(db / LEGACY_MARKER)
    (db / "failures").mkdir()
    for part in (db / "_failures").glob("part-*.parq"):
        part.rename(db / "failures" / (part.stem + ".parquet"))
    (db / "_failures").rmdir()


def test_previous_layout_is_read_and_moved_by_the_next_batch(first_run, meshes, tmp_path):
    out, inputs, _, _ = first_run
    db = tmp_path / "old.db"
    shutil.copytree(out, db)
    _to_first_layout(db)
    failures_before = pq.read_table(db / "failures").num_rows
    assert len(GraspDatabase.open(db)) == len(SHAPES)  # the node reads it as it is
    # An older batch still writing (its LOCK, a live pid on this host): refused, nothing moved.
    holder = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        (db / "LOCK").write_text(json.dumps({"pid": holder.pid, "host": os.uname().nodename}))
        with pytest.raises(DatabaseError, match=f"pid {holder.pid}"):
            run_batch(inputs, _config(db))
        assert (db / LEGACY_MARKER).is_file() and not (db / "_LOCK").exists()
    finally:
        holder.kill()
        holder.wait(timeout=10)
    # Its pid gone: the next batch moves the database and resumes from the old failures
    # (the corrupt file, a deterministic failure, is skipped; the missing one retried).
    again = run_batch(inputs, _config(db))
    assert (again.planned, again.skipped, again.failed) == (0, 4, 1)
    names = sorted(p.name for p in db.iterdir())
    assert names == ["_failures", "_grasp_database.json", "grasps"]
    assert pq.read_table(db / "_failures").num_rows == failures_before + 1
    assert pq.read_table(db).num_rows == len(_grasp_rows(out))
    assert json.loads((db / MARKER).read_text())["layout"] == 2
