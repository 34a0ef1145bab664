"""``grasp_apso_plan --hand FILE [--hand-config FILE]`` with a general hand (issue 21), and the
pictures of a general hand's grasp (its own collision geometry)."""
import dataclasses
import json
import os

import matplotlib.image as mpimg
import numpy as np
import pytest

from hand_files import urdf_actuated_joints as _urdf_actuated, write_allegro_like

from grasp_apso.model import builtin
from grasp_apso.model.hands.load import load_hand as load_any_hand
from grasp_apso.model.planning_hand import load_planning_hand, paper_hand_hash
from grasp_apso.errors import HandDescriptionError
from grasp_apso.presentation.hand_geometry import hand_triangles
from grasp_apso.search.planner import PlanOptions, plan
from grasp_apso.tools import cli, plotting

SMALL = ["--particles", "12", "--iterations", "6"]


@pytest.fixture(scope="module")
def allegro(tmp_path_factory):
    return write_allegro_like(tmp_path_factory.mktemp("any_cli"), "mixed")


def _run(capsys, *argv):
    code = cli.main([*argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_planning_hand_chooses_by_suffix_and_names_its_identity(allegro):
    import hashlib

    from grasp_apso.model.hand import HandModel as PaperHand, default_hand_path

    paper = load_planning_hand(None)
    assert isinstance(paper.hand, PaperHand) and paper.name == "apso_paper_hand"
    assert paper.hash == hashlib.sha256(default_hand_path().read_bytes()).hexdigest() == paper_hand_hash()
    general = load_planning_hand(str(allegro))
    assert list(general.joint_names) == _urdf_actuated(allegro)
    assert general.hash == general.hand.source_hash and len(general.hash) == 64 and general.hash != paper.hash


@pytest.mark.parametrize("kind, option", [("missing", "--hand"), ("config", "--hand-config")])
def test_a_bad_hand_is_a_one_line_error_naming_the_option(capsys, allegro, tmp_path, kind, option):
    argv = ["--object", "cube", *SMALL, "--no-plots"]
    if kind == "missing":
        argv += ["--hand", str(tmp_path / "nothing.urdf")]
    else:
        cfg = tmp_path / "c.yaml"
        cfg.write_text("thumb: nobody\n")
        argv += ["--hand", str(allegro), "--hand-config", str(cfg)]
    code, out, err = _run(capsys, *argv)
    assert code == 2 and out == ""
    assert err.startswith(f"grasp_apso_plan: error: {option}:") and err.count("\n") == 1, err
    with pytest.raises(HandDescriptionError) as info:
        load_planning_hand(*([str(tmp_path / "nothing.urdf")] if kind == "missing" else [str(allegro), str(cfg)]))
    assert info.value.field == ("hand_description" if kind == "missing" else "hand_config")


def _general_result(hand, obj):
    """A result over the hand's joints built by hand from a paper-hand plan's numbers
    (the drawing does not depend on how the grasp was found)."""
    res = plan(obj, options=PlanOptions(particles=10, iterations=2, max_grasps=2), rng=np.random.default_rng(1))
    q = hand.closed_configuration(0.4)
    empty = np.zeros((0, 4, 3))
    cands = tuple(dataclasses.replace(c, joint_positions=q, pre_grasp_positions=hand.open_configuration(),
                                      joints=empty, pre_grasp_joints=empty) for c in res.candidates)
    return dataclasses.replace(res, joint_names=hand.actuated_joints, joint_positions=q, candidates=cands,
                               joints=empty)


def test_pictures_draw_the_general_hand_from_its_collision_geometry(allegro, tmp_path):
    hand = load_any_hand(allegro, spheres=False)
    obj = builtin.builtin("cube")
    result = _general_result(hand, obj)
    grasp = plotting._grasp_of(result, hand)
    assert set(grasp.hand_tris) == {k for k, g in hand.collision.items() if g}
    assert grasp.pre_hand_tris is not None and set(grasp.pre_hand_tris) == set(grasp.hand_tris)
    # Independent: a primitive link's triangles are its own geometry moved by
    # wrist_pose @ link_transforms (a box keeps its 8 corners: every drawn vertex is one).
    link = next(k for k, g in hand.collision.items() if len(g) == 1 and g[0].kind == "box")
    geom = hand.collision[link][0]
    tf = np.asarray(result.wrist_pose) @ hand.link_transforms(result.joint_positions)[link] @ np.asarray(geom.origin)
    half = np.asarray(geom.size)  # a box's size is its half extents
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half
    expected = (corners @ tf[:3, :3].T + tf[:3, 3]) * 1000
    drawn = grasp.hand_tris[link].reshape(-1, 3)
    assert np.max(np.min(np.linalg.norm(drawn[:, None] - expected[None], axis=2), axis=1)) < 1e-6
    total = sum(len(t) for t in hand_triangles(hand, result.joint_positions, np.eye(4)).values())
    assert 100 < total <= 3500
    for name, fn in (("g.png", plotting.plot_grasp), ("c.png", plotting.plot_candidates)):
        path = fn(result, obj, path=tmp_path / name, hand=hand)
        image = mpimg.imread(path)
        assert image.shape[0] >= 300 and (image[..., :3].min(axis=2) < 0.9).mean() > 0.02


def test_plan_with_an_allegro_urdf_prints_its_joints_and_draws_it(capsys, allegro, tmp_path):
    target = tmp_path / "out.json"
    code, out, err = _run(capsys, "--hand", str(allegro), "--object", "cube", "--table", *SMALL, "--seed", "4",
                          "--grasps", "2", "--out", str(tmp_path), "--json", str(target))
    assert code == 0, err
    joints = _urdf_actuated(allegro)
    assert "allegro_like" in out and "16 actuated joints" in out
    for name in joints:
        assert name in out
    assert "wrist_x" not in out
    doc = json.loads(target.read_text())
    assert doc["results"]["apso"]["joint_names"] == joints
    assert len(doc["results"]["apso"]["joint_positions"]) == 16
    pictures = [p for p in doc["pictures"] if p.endswith("_grasp.png")]
    assert pictures and os.path.getsize(pictures[0]) > 10_000


def test_candidate_table_and_pictures_speak_of_the_hands_own_fingers(allegro, tmp_path):
    """A hand whose fingers are called ``3``, ``7``, ``11`` (dex-urdf's Allegro) is tabulated
    with those names, not run together as initials ("3711"); the paper hand keeps its
    initials; the side view of any other hand does not speak of a little finger."""
    from grasp_apso.presentation import summary
    from grasp_apso.search.result import PAPER_HAND_NAME

    hand = load_any_hand(allegro, spheres=False)
    result = _general_result(hand, builtin.builtin("cube"))
    names = ("3", "7", "11", "15")
    renamed = tuple(dataclasses.replace(c, contacts=tuple(dataclasses.replace(x, finger=names[i % 4])
                                                          for i, x in enumerate(c.contacts)))
                    for c in result.candidates)
    table = summary.format_candidates(dataclasses.replace(result, candidates=renamed)).splitlines()
    assert "little ring middle" not in table[0] and "fingers touching" in table[0]
    for cand, row in zip(renamed, table[2:]):
        label = ",".join(x.finger for x in cand.contacts)
        assert row.split()[4:6] == [str(cand.n_contacts), label], row
        assert "".join(x.finger for x in cand.contacts) not in row.split()
    # Another hand whose touching fingers are called like the paper hand's (the Allegro-like
    # hand's index, middle, ring, thumb; an Inspire's when its pinky does not touch): its
    # table still names them (the hand decides, not which fingers touch in this plan).
    own = summary.format_candidates(dataclasses.replace(result, hand_name=hand.name)).splitlines()
    assert "fingers touching" in own[0]
    assert own[2].split()[5] == ",".join(x.finger for x in result.candidates[0].contacts)
    assert result.hand_name == PAPER_HAND_NAME  # built from a paper-hand plan
    paper = summary.format_candidates(result).splitlines()
    assert "L R M I T = little ring middle index thumb" in paper[0]
    initials = {"little": "L", "ring": "R", "middle": "M", "index": "I", "thumb": "T"}
    assert paper[2].split()[5] == "".join(initials[x.finger] for x in result.candidates[0].contacts)
    assert plotting._view_label("side", hand) == "side view (across the palm)"
    assert "little-finger side" in plotting._view_label("side", plotting.load_hand())


def test_a_link_fixed_to_a_contacting_pad_is_not_reported_as_another_link_touching(allegro):
    # The Revo2's thumb carries a 0.5 mm marker plate fixed to its pad link: it was listed
    # under "other links touching", though it is the fingertip's own body.
    from grasp_apso.presentation.summary import _general_touching  # noqa: PLC0415

    hand = load_any_hand(allegro)
    result = plan(builtin.builtin("sphere"), hand=hand, options=PlanOptions(particles=12, iterations=6, max_grasps=1),
                  rng=np.random.default_rng(0))
    fingers = {c.finger for c in result.contacts}
    assert fingers
    report = result.fcl
    # every link touching: the contacting fingers' tips and distals (one body) are theirs,
    # every other link is reported
    everything = dataclasses.replace(report, touching=np.ones(len(report.links), dtype=bool))
    shown = set(_general_touching(dataclasses.replace(result, fcl=everything), hand))
    own = {f"{name}_{part}" for name in fingers for part in ("tip", "distal")}
    assert shown == set(report.links) - own
