"""The grasp database for any hand (issue 21): rows carry ``hand_name`` and ``hand_hash``; a
database opened for a hand answers only with that hand's rows; files of schema 1 (no
``hand_hash``, float64[18] joints) read as the shipped paper hand's; a general hand's rows
keep its actuated joints and are moved to the request pose without wrist angles."""

from __future__ import annotations

import dataclasses
import datetime as dt
import math

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from hand_files import write_allegro_like

from grasp_apso.database.lookup import GraspDatabase
from grasp_apso.database.schema import GRASP_SCHEMA, candidate_rows
from grasp_apso.model.builtin import builtin
from grasp_apso.model.planning_hand import load_planning_hand, paper_hand_hash
from grasp_apso.search.options import PlanOptions
from grasp_apso.search.planner import plan


@pytest.fixture(scope="module")
def paper_plan():
    obj = builtin("cube")
    result = plan(obj, np.eye(4), PlanOptions(particles=12, iterations=4, max_grasps=3), rng=np.random.default_rng(2))
    assert any(c.valid for c in result.candidates)
    return obj, result


@pytest.fixture(scope="module")
def allegro(tmp_path_factory):
    return load_planning_hand(str(write_allegro_like(tmp_path_factory.mktemp("db_hand"))))


def _common(obj, name, digest):
    return {"object_id": "cube", "source_path": "cube.stl", "source_sha256": "0" * 64, "scale": 1.0,
            "mesh_hash": obj.mesh_hash, "hand_name": name, "hand_hash": digest, "options_key": "k" * 16,
            "options": "{}", "seed": 2, "package_version": "test", "planning_time": 0.1,
            "created": dt.datetime.now(dt.timezone.utc)}


def _write(path, cols, schema=GRASP_SCHEMA):
    pq.write_table(pa.Table.from_pydict(cols, schema=schema), path)
    return path


def test_rows_of_another_hand_are_never_answered(paper_plan, allegro, tmp_path):
    obj, result = paper_plan
    valid = sum(c.valid for c in result.candidates)
    mine = candidate_rows(result.candidates, np.eye(4), _common(obj, "apso_paper_hand", paper_hand_hash()))
    # Same name, another description: another hash (an edited YAML).
    other = candidate_rows(result.candidates, np.eye(4), _common(obj, "apso_paper_hand", "f" * 64))
    both = {k: mine[k] + other[k] for k in mine}
    db = GraspDatabase.open(_write(tmp_path / "both.parquet", both))
    assert db.count(obj.mesh_hash, "apso_paper_hand") == valid
    assert db.rows == len(result.candidates) and db.other_rows == len(result.candidates)
    only_other = GraspDatabase.open(_write(tmp_path / "other.parquet", other))
    assert len(only_other) == 0 and only_other.lookup(obj.mesh_hash, "apso_paper_hand", np.eye(4)) == []
    # The Allegro hand sees none of the paper hand's rows.
    assert GraspDatabase.open(tmp_path / "both.parquet", hand=allegro).other_rows == 2 * len(result.candidates)
    assert len(GraspDatabase.open(tmp_path / "both.parquet", hand=allegro)) == 0


def test_schema_1_files_read_as_the_shipped_paper_hand(paper_plan, allegro, tmp_path):
    obj, result = paper_plan
    cols = candidate_rows(result.candidates, np.eye(4), _common(obj, "apso_paper_hand", ""))
    del cols["hand_hash"]
    fields = [pa.field(f.name, pa.list_(pa.float64(), 18), nullable=False)
              if f.name in ("joint_positions", "pre_grasp_positions") else f
              for f in GRASP_SCHEMA if f.name != "hand_hash"]
    path = _write(tmp_path / "v1.parquet", cols, pa.schema(fields))
    assert "hand_hash" not in pq.read_schema(path).names
    db = GraspDatabase.open(path)
    found = db.lookup(obj.mesh_hash, "apso_paper_hand", np.eye(4), max_grasps=5)
    valid = [c for c in result.candidates if c.valid]
    assert len(found) == len(valid) >= 1
    best = min(valid, key=lambda c: c.rank)
    assert any(np.allclose(g.joint_positions, best.joint_positions, atol=1e-9) for g in found)
    assert len(GraspDatabase.open(path, hand=allegro)) == 0


def test_a_general_hand_s_rows_keep_its_joints_and_move_with_the_pose(paper_plan, allegro, tmp_path):
    obj, result = paper_plan
    hand = allegro.hand
    n = len(hand.actuated_joints)
    rng = np.random.default_rng(9)
    empty = np.zeros((0, 4, 3))
    cands = tuple(dataclasses.replace(c, joint_positions=rng.uniform(hand.lower, hand.upper),
                                      pre_grasp_positions=rng.uniform(hand.lower, hand.upper),
                                      joints=empty, pre_grasp_joints=empty)
                  for c in result.candidates if c.valid)
    cols = candidate_rows(cands, np.eye(4), _common(obj, hand.name, allegro.hash), wrist_angles=False)
    assert all(len(q) == n for q in cols["joint_positions"])
    path = _write(tmp_path / "allegro.parquet", cols)
    assert len(GraspDatabase.open(path)) == 0  # the paper hand does not see them
    db = GraspDatabase.open(path, hand=allegro)
    assert db.count(obj.mesh_hash, hand.name) == len(cands)
    pose = np.eye(4)
    angle = 1.1
    pose[:3, :3] = [[math.cos(angle), -math.sin(angle), 0], [math.sin(angle), math.cos(angle), 0], [0, 0, 1]]
    pose[:3, 3] = [0.3, -0.2, 0.7]
    found = db.lookup(obj.mesh_hash, hand.name, pose, approach_distance=0.05, max_grasps=10)
    assert len(found) == len(cands)
    by_wrist = {tuple(np.round(c.wrist_pose[:3, 3], 9)): c for c in cands}
    for g in found:
        c = by_wrist[tuple(np.round(np.linalg.inv(pose)[:3, :3] @ g.wrist_pose[:3, 3] + np.linalg.inv(pose)[:3, 3], 9))]
        np.testing.assert_allclose(g.joint_positions, c.joint_positions, atol=1e-12)  # no wrist angles added
        np.testing.assert_allclose(g.pre_grasp_positions, c.pre_grasp_positions, atol=1e-12)
        np.testing.assert_allclose(g.wrist_pose, pose @ c.wrist_pose, atol=1e-9)
        normal = pose[:3, :3] @ c.wrist_pose[:3, :3] @ hand.palm_normal
        np.testing.assert_allclose(g.approach, normal / np.linalg.norm(normal), atol=1e-9)
        np.testing.assert_allclose(g.pre_grasp_pose[:3, 3], g.wrist_pose[:3, 3] - 0.05 * g.approach, atol=1e-9)
        assert g.joints.shape == (0, 4, 3)


def test_batch_with_a_urdf_hand_writes_its_name_hash_and_joints(allegro, tmp_path):
    from grasp_apso.database.batch import BatchConfig, run_batch

    mesh = tmp_path / "cube.stl"
    builtin("cube").mesh.export(mesh)
    out = tmp_path / "allegro.db"
    config = BatchConfig(out=str(out), options=PlanOptions(particles=16, iterations=6, max_grasps=2), seed=3,
                         workers=1, progress="none", hand_path=allegro.path)
    summary = run_batch([str(mesh)], config)
    assert (summary.planned, summary.failed) == (1, 0), summary.failures
    rows = pq.read_table(out / "grasps").to_pylist()
    assert rows and {r["hand_name"] for r in rows} == {allegro.name}
    assert {r["hand_hash"] for r in rows} == {allegro.hash}
    assert all(len(r["joint_positions"]) == len(r["pre_grasp_positions"]) == 16 for r in rows)
    assert len(GraspDatabase.open(out, hand=allegro)) == 1
    assert len(GraspDatabase.open(out)) == 0  # the paper hand's node would not answer from them
    again = run_batch([str(mesh)], config)  # resumable: the same hand and options are done
    assert (again.planned, again.skipped) == (0, 1)


def test_a_general_hand_s_stored_grasps_are_rechecked_against_the_request_scene(allegro, tmp_path):
    from grasp_apso.model.scene import Scene
    from grasp_apso.presentation.hand_geometry import hand_triangles

    obj = builtin("cube")
    table = Scene.table_under(np.asarray(obj.mesh.vertices))
    result = plan(obj, np.eye(4), PlanOptions(particles=16, iterations=6, max_grasps=3), rng=np.random.default_rng(4),
                  hand=allegro.hand, scene=table)
    valid = [c for c in result.candidates if c.valid]
    assert valid
    cols = candidate_rows(result.candidates, np.eye(4), _common(obj, allegro.name, allegro.hash), wrist_angles=False)
    db = GraspDatabase.open(_write(tmp_path / "table.parquet", cols), hand=allegro)
    pose = np.eye(4)
    pose[:3, 3] = [0.1, 0.2, 0.5]
    scene = Scene.table_under(np.asarray(obj.mesh.vertices) + pose[:3, 3])
    found = db.lookup(obj.mesh_hash, allegro.name, pose, scene, clearance=0.005, approach_distance=0.05,
                      max_grasps=5, obj=obj)
    assert found
    top = -scene.planes[0][3]
    for g in found:
        assert 0.005 - 1e-6 <= g.scene_distance < math.inf
        # Independent: the hand's own collision surface stays above the table, at the grasp and
        # at the pre-grasp (vertex clustering for drawing only pulls points inward).
        for q, root in ((g.joint_positions, g.wrist_pose), (g.pre_grasp_positions, g.pre_grasp_pose)):
            lowest = min(t[..., 2].min() for t in hand_triangles(allegro.hand, q, root).values())
            assert lowest >= top + 0.005 - 1e-3
    # A table through the contacts' height leaves no stored grasp.
    high = max(float(c.position[2]) for g in found for c in g.contacts) + 0.002  # planning frame
    cut = Scene.from_primitives(planes=[(0.0, 0.0, 1.0, -high)])
    assert db.lookup(obj.mesh_hash, allegro.name, pose, cut, clearance=0.005, max_grasps=5, obj=obj) == []
