"""The README's main job: ``scripts/demo.sh`` starts the real node in its own process, plans
grasps of an object resting on a table through the service, prints them and stops the node.

Run as a user runs it (bash, the node as a separate process, DDS between them), with a small
swarm so it takes seconds; once with the paper's hand and a built-in object, once with
another hand (``--hand``, a URDF the tests write) and a mesh file (``--mesh``).
"""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
from pathlib import Path

from hand_files import urdf_actuated_joints, write_allegro_like

REPO = Path(__file__).resolve().parents[1]
DEMO = REPO / "scripts" / "demo.sh"
MUG = REPO / "grasp_apso" / "data" / "meshes" / "mug.stl"


def _run_demo(*args: str, timeout: float = 420.0) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env["GRASP_APSO_VENV"] = sys.prefix  # the venv running the tests: no set-up step
    # A domain of the demo's own range (102..201), apart from the tests' nodes (1..101).
    env["DEMO_ROS_DOMAIN_ID"] = str(102 + int(os.environ.get("ROS_DOMAIN_ID", "0")) % 100)
    return subprocess.run(["bash", str(DEMO), *args], cwd=REPO, env=env, capture_output=True,
                          text=True, timeout=timeout, check=False)


def _joint_degrees(out: str, names: list[str]) -> dict[str, float]:
    found = {}
    for name in names:
        m = re.search(rf"^\s+{re.escape(name)}\s+(-?\d+\.\d)\s*$", out, re.MULTILINE)
        if m:
            found[name] = float(m.group(1))
    return found


def test_demo_plans_a_built_in_object_on_a_table_through_the_node():
    res = _run_demo("cube", "--particles", "20", "--iterations", "10", "--seed", "3", "--grasps", "3")
    out = res.stdout + res.stderr
    assert res.returncode == 0, out[-3000:]
    assert "success        : True" in out
    assert "resting on a table" in out
    # The paper hand's 18 joints as a table: five fingers and the wrist.
    for finger in ("little", "ring", "middle", "index", "thumb", "wrist"):
        assert re.search(rf"^\s+{finger}\s+(-?\d+\.\d\s+){{3}}", out, re.MULTILINE), finger
    ranks = re.findall(r"^\s+(\d)\. g\d+\s+quality", out, re.MULTILINE)
    assert ranks and ranks[0] == "1" and len(ranks) <= 3
    m = re.search(r"progress\s+: (\d+) GraspProgress messages", out)
    assert m and int(m.group(1)) >= 1
    assert "node stopped (exit status 0)" in out


def test_demo_plans_with_another_hand_from_its_urdf_on_a_mesh(tmp_path):
    urdf = write_allegro_like(tmp_path)
    res = _run_demo("--hand", str(urdf), "--mesh", str(MUG), "--particles", "30", "--iterations", "15",
                    "--seed", "1", "--grasps", "2")
    out = res.stdout + res.stderr
    assert res.returncode == 0, out[-3000:]
    assert f"the mesh {MUG}" in out and "success        : True" in out
    # The reply's JointState carries that hand's actuated joints (not the paper's 18), in range.
    names = urdf_actuated_joints(urdf)
    degrees = _joint_degrees(out, names)
    assert sorted(degrees) == sorted(names)
    assert "little" not in out.split("configuration")[1].split("wrist pose")[0]
    assert all(math.isfinite(v) and abs(v) <= 180.0 for v in degrees.values())
    assert "node stopped (exit status 0)" in out


def test_demo_refuses_a_missing_hand_file_naming_the_option(tmp_path):
    res = _run_demo("--hand", str(tmp_path / "nope.urdf"), timeout=60.0)
    assert res.returncode == 2
    assert "--hand: no such file" in res.stdout + res.stderr


def test_demo_client_refuses_a_missing_mesh_naming_the_option(tmp_path):
    res = subprocess.run([sys.executable, "-m", "grasp_apso.ros.demo_client", "--mesh", str(tmp_path / "x.stl")],
                         cwd=REPO, capture_output=True, text=True, timeout=120, check=False)
    assert res.returncode == 2
    assert "--mesh: no such file" in res.stderr
