"""``grasp_apso_hand`` (issue 20) and the node's ``hand_description`` / ``hand_config``
start-up check: what a user runs to check a new hand, and what stops a node with a bad one.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from grasp_apso.errors import HandDescriptionError
from grasp_apso.tools.hand_cli import main
from hand_files import urdf_actuated_joints, write_allegro_like

PAPER_YAML = Path(__file__).resolve().parents[1] / "grasp_apso" / "data" / "hand.yaml"


@pytest.fixture(scope="module")
def allegro(tmp_path_factory):
    return write_allegro_like(tmp_path_factory.mktemp("cli"), "mixed")


def test_text_output_names_everything_a_user_checks(capsys):
    assert main([str(PAPER_YAML)]) == 0
    out = capsys.readouterr().out
    assert "root link (palm): palm   palm normal (root frame): [0.0, 0.0, 1.0]" in out
    assert "held above or beside the palm (fixed, not actuated for grasping): wrist_z=0, wrist_y=0, wrist_x=0" in out
    assert "finger thumb (thumb): tip thumb_tip" in out
    assert "index_pivot" in out and "pre-shape" in out and "+1 closes" in out
    assert "coupling: index_middle = 1.5 * index_distal + 0  (joint index_middle mimic; its own effort limit)" in out
    # the simulation's servo on the leader: 1 + 1.5^2 times as stiff, its torque limit that over the
    # largest gear (1.5), so that the mimic joint bears an uncoupled servo's limit
    assert "servo on index_distal: gain x3.25, torque limit x2.1667 (it drives coupled joints)" in out
    assert "collision spheres:" in out and "stray" in out
    assert out.count("pad on ") == 5


def test_json_output_and_picture(capsys, tmp_path):
    picture = tmp_path / "hand.png"
    assert main([str(PAPER_YAML), "--json", "--picture", str(picture)]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["root_link"] == "palm"
    assert [f["name"] for f in data["fingers"]] == ["little", "ring", "middle", "index", "thumb"]
    assert [f["thumb"] for f in data["fingers"]] == [False] * 4 + [True]
    assert data["fingers"][0]["closing"] == [0, 1, 1]
    assert len(data["actuated_joints"]) == 15
    assert all(c["own_effort"] for c in data["couplings"]) and len(data["couplings"]) == 5
    assert data["servo_torque_scale"]["index_distal"] == pytest.approx(3.25 / 1.5, abs=1e-4)
    assert data["servo_gain_scale"]["index_pivot"] == 1.0 and data["servo_torque_scale"]["index_pivot"] == 1.0
    for link, s in data["spheres"].items():
        assert s["count"] >= 1 and s["max_stray_m"] <= 0.0021, link
    assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_hand_config_on_the_command_line(capsys, allegro, tmp_path):
    cfg = tmp_path / "allegro.yaml"
    cfg.write_text("thumb: index\nclosing: {index_joint_0: -1}\nmax_spheres: 4\ncapsules: true\n")
    assert main([str(allegro), "--hand-config", str(cfg), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    index = data["fingers"][0]
    assert index["name"] == "index" and index["thumb"] and index["closing"][0] == -1
    assert max(s["count"] for s in data["spheres"].values()) <= 4


@pytest.mark.parametrize("content, name, words", [
    ("hello", "bad.urdf", "not a valid URDF"),
    ("x", "bad.stl", "not a URDF (.urdf), MJCF (.xml)"),
])
def test_bad_input_exits_2_with_one_line(capsys, tmp_path, content, name, words):
    path = tmp_path / name
    path.write_text(content)
    assert main([str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith("grasp_apso_hand: error: hand_description") and words in err


def test_bad_config_exits_2_naming_the_key(capsys, allegro, tmp_path):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text("closing: {index_joint_1: 5}\n")
    assert main([str(allegro), "--hand-config", str(cfg)]) == 2
    assert "hand_config.closing.index_joint_1" in capsys.readouterr().err


# ------------------------------------------------------------------ node start-up
rclpy = pytest.importorskip("rclpy")
from rclpy.parameter import Parameter  # noqa: E402

from grasp_apso.model.hand import HandModel as PaperHand  # noqa: E402
from grasp_apso.ros.parameters import NodeParameters  # noqa: E402


@pytest.fixture(scope="module")
def context():
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.shutdown(context=ctx)


def _start(context, name, **values):
    node = rclpy.create_node(name, context=context,
                             parameter_overrides=[Parameter(k, value=v) for k, v in values.items()])
    try:
        return NodeParameters(node)
    finally:
        node.destroy_node()


def test_node_plans_with_the_urdf_hand_it_is_given(context, allegro):
    from grasp_apso.model.hands.model import HandModel as AnyHand

    params = _start(context, "hand_ok", hand_description=str(allegro))
    hand = params.settings.hand
    assert isinstance(hand, AnyHand) and not isinstance(hand, PaperHand)
    assert params.settings["hand_description"] == str(allegro)
    joints = urdf_actuated_joints(allegro)  # independent of the loader
    assert list(hand.actuated_joints) == joints and len(joints) == 16
    assert hand.spheres  # the search's sphere cover is built at start-up, not per request


def test_node_keeps_the_paper_hand_for_a_yaml_or_no_description(context):
    from grasp_apso.model.hand import default_hand_path

    for values in ({}, {"hand_description": str(default_hand_path())}):
        params = _start(context, "hand_paper", **values)
        assert isinstance(params.settings.hand, PaperHand)


@pytest.mark.parametrize("kind", ["missing_mesh", "suffix", "config"])
def test_node_refuses_a_bad_hand_naming_the_parameter(context, allegro, tmp_path, kind):
    values = {"hand_description": str(allegro)}
    if kind == "missing_mesh":
        path = allegro.parent / "no_mesh.urdf"
        path.write_text(allegro.read_text().replace("meshes/ring_distal_0.stl", "meshes/gone.stl"))
        values["hand_description"], field = str(path), "hand_description"
    elif kind == "suffix":
        path = tmp_path / "hand.obj"
        path.write_text("v 0 0 0\n")
        values["hand_description"], field = str(path), "hand_description"
    else:
        cfg = tmp_path / "c.yaml"
        cfg.write_text("thumb: nobody\n")
        values["hand_config"], field = str(cfg), "hand_config"
    with pytest.raises(HandDescriptionError) as info:
        _start(context, f"hand_bad_{kind}", **values)
    assert info.value.field == field and str(info.value).startswith(field)
