"""``grasp_apso_hand`` (issue 20) and the node's ``hand_description`` / ``hand_config``
start-up check: what a user runs to check a new hand, and what stops a node with a bad one.
"""

from __future__ import annotations

import json

import pytest

from grasp_apso.errors import HandDescriptionError
from grasp_apso.tools.hand_cli import main
from hand_files import installed_hand, write_allegro_like


@pytest.fixture(scope="module")
def allegro(tmp_path_factory):
    return write_allegro_like(tmp_path_factory.mktemp("cli"), "mixed")


def test_text_output_names_everything_a_user_checks(capsys):
    assert main([str(installed_hand("shadow"))]) == 0
    out = capsys.readouterr().out
    assert "root link (palm): robot0:palm" in out
    assert "held above the palm (fixed, not actuated for grasping): robot0:WRJ1=0, robot0:WRJ0=0" in out
    assert "finger th (thumb): tip robot0:thdistal" in out
    assert "robot0:FFJ3" in out and "pre-shape" in out and "+1 closes" in out
    assert "coupling: robot0:FFJ0 = 1.14184 * robot0:FFJ1" in out
    assert "collision spheres:" in out and "stray" in out
    assert out.count("pad on ") == 5


def test_json_output(capsys, allegro):
    assert main([str(allegro), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["root_link"] == "palm"
    assert [f["name"] for f in data["fingers"]] == ["index", "middle", "ring", "thumb"]
    assert [f["thumb"] for f in data["fingers"]] == [False, False, False, True]
    assert data["fingers"][0]["closing"] == [0, 1, 1, 1]
    assert set(data["spheres"]) >= {"palm", "index_tip", "thumb_tip"}
    for link, s in data["spheres"].items():
        assert s["count"] >= 1 and s["max_stray_m"] <= 0.0021, link


def test_hand_config_on_the_command_line(capsys, allegro, tmp_path):
    cfg = tmp_path / "allegro.yaml"
    cfg.write_text("thumb: index\nclosing: {index_joint_0: -1}\n")
    assert main([str(allegro), "--hand-config", str(cfg), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    index = data["fingers"][0]
    assert index["thumb"] and index["closing"][0] == -1


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


def test_node_accepts_a_urdf_hand_and_keeps_planning_with_the_paper_hand(context, allegro):
    params = _start(context, "hand_ok", hand_description=str(allegro))
    assert isinstance(params.settings.hand, PaperHand)
    assert params.settings["hand_description"] == str(allegro)


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
