"""Command line ``grasp_apso_plan`` (grasp_apso.tools.cli) and its pictures (grasp_apso.tools.plotting).

The real planner runs with small swarms (12 particles, 6 iterations) to stay fast.
"""
import json
import os
import subprocess
import sys

import matplotlib.image as mpimg
import numpy as np
import pytest
import trimesh

from grasp_apso.tools import cli
from grasp_apso.tools import plotting
from grasp_apso.model.hand import FINGER_NAMES, JOINT_NAMES, load_hand

SMALL = ["--particles", "12", "--iterations", "6"]
HAND = load_hand()


def _run(capsys, *argv):
    code = cli.main([*argv])
    out, err = capsys.readouterr()
    return code, out, err


def _check_png(path, min_bytes=10_000):
    assert os.path.isfile(path), path
    assert os.path.getsize(path) > min_bytes, (path, os.path.getsize(path))
    image = mpimg.imread(path)
    height, width = image.shape[:2]
    assert 300 <= height <= 4000 and 400 <= width <= 6000, image.shape
    assert image.shape[2] in (3, 4)
    # Not blank: a fair amount of non-white pixels, several colours.
    rgb = image[..., :3]
    assert (rgb.min(axis=2) < 0.9).mean() > 0.02
    assert rgb.std() > 0.05


def _table_rows(out):
    """Rows of the configuration table: name -> list of (value, low, high) in degrees."""
    rows = {}
    for line in out.splitlines():
        parts = line.split()
        if not parts or parts[0] not in (*FINGER_NAMES, "wrist"):
            continue
        cells = line.replace("*", " ").replace("[", " ").replace("]", " ").replace(",", " ").split()[1:]
        if parts[0] == "wrist":
            cells = [c for c in cells if c not in ("x", "y", "z")]
        try:
            numbers = [float(c) for c in cells]
        except ValueError:
            continue
        if len(numbers) == 9:
            rows[parts[0]] = [tuple(numbers[k:k + 3]) for k in range(0, 9, 3)]
    return rows


def test_apso_run_prints_the_table_and_writes_pictures_and_json(tmp_path, capsys):
    out_dir = tmp_path / "pictures"
    json_path = tmp_path / "result.json"
    code, out, err = _run(capsys, "--object", "sphere", *SMALL, "--seed", "1",
                          "--out", str(out_dir), "--json", str(json_path))
    assert code == 0, err
    # Header that explains the run.
    assert "sphere (built-in): 1280 triangles" in out
    assert "shape class sphere-like" in out
    assert "APSO: 12 particles, 6 iterations, seed 1, friction mu 0.5" in out
    # Configuration table: 5 fingers x (distal, proximal, pivot) + wrist x/y/z = 18 values,
    # each with its Table 2 limits, values inside them.
    rows = _table_rows(out)
    assert list(rows) == [*FINGER_NAMES, "wrist"], out
    lower, upper = np.degrees(HAND.lower), np.degrees(HAND.upper)
    for r, name in enumerate(rows):
        for k, (value, low, high) in enumerate(rows[name]):
            j = 3 * r + k
            assert (low, high) == (round(lower[j]), round(upper[j])), JOINT_NAMES[j]
            assert low - 0.05 <= value <= high + 0.05, (JOINT_NAMES[j], value)
    # Wrist pose, contacts and the quality block.
    assert "position" in out and "quaternion" in out and " mm" in out
    assert "Contacts:" in out
    for label in ("fitness", "maximised", "epsilon", "Ferrari-Canny", "force closure", "fingertip contacts",
                  "max penetration", "python-fcl check", "other links touching", "iterations           6 of 6", "evaluations",
                  "planning time", "preparation time"):
        assert label in out, label
    # Progress: not a terminal here, so plain lines on stderr.
    assert "iteration   1/6" in err and "iteration   6/6" in err
    # Pictures, listed at the end.
    grasp_png = out_dir / "sphere_apso_grasp.png"
    conv_png = out_dir / "sphere_convergence.png"
    for png in (grasp_png, conv_png):
        _check_png(str(png))
        assert str(png) in out
    # JSON for scripts: SI units, joints within the hand limits.
    doc = json.loads(json_path.read_text())
    result = doc["results"]["apso"]
    assert doc["options"] == {"particles": 12, "iterations": 6, "seed": 1, "friction": 0.5, "clearance": 0.005,
                              "approach_distance": 0.08, "grasps": 1, "simulate": False, "table": False,
                              "obstacles": []}
    assert doc["scene"] is None
    # Every candidate, best first; candidates[0] is the grasp of the top-level fields.
    assert len(result["candidates"]) >= 1
    best = result["candidates"][0]
    assert best["rank"] == 0 and best["joint_positions"] == result["joint_positions"]
    pre = np.array(best["pre_grasp_pose"]["position"])
    grasp = np.array(best["wrist_pose"]["position"])
    approach = np.array(best["approach_direction"])
    assert np.isclose(np.linalg.norm(approach), 1.0)
    assert np.allclose(grasp - pre, 0.08 * approach, atol=1e-9)  # pre-grasp 80 mm back along the approach
    assert best["sim_result"] == -1 and best["sim"] == "not simulated"
    assert result["joint_names"] == list(JOINT_NAMES)
    q = np.array(result["joint_positions"])
    assert q.shape == (18,)
    assert np.all(q >= HAND.lower - 1e-9) and np.all(q <= HAND.upper + 1e-9)
    assert np.allclose(np.array(result["configuration"]).reshape(-1), q)
    assert len(result["history"]) == 6 and result["history"][-1]["iteration"] == 6
    assert np.isclose(np.linalg.norm(result["wrist_pose"]["orientation_xyzw"]), 1.0)
    assert {c["finger"] for c in result["contacts"]} <= set(FINGER_NAMES)
    assert result["n_contacts"] == len(result["contacts"])
    assert 0.0 <= result["fitness"] <= 1.0 or not result["valid"]
    for key in ("epsilon", "force_closure", "valid", "fcl", "planning_time", "evaluations"):
        assert key in result
    assert np.array(result["fcl"]["link_distance"]).shape == (5, 3)
    assert all(link.split("_")[0] in FINGER_NAMES for link in result["fcl"]["touching_links"])


def test_both_algorithms_are_compared(tmp_path, capsys):
    code, out, err = _run(capsys, "--object", "cube", "--algorithm", "both", *SMALL, "--seed", "2",
                          "--out", str(tmp_path))
    assert code == 0, err
    assert "APSO result:" in out and "PSO result:" in out
    assert "Comparison (APSO, PSO; same object, seed 2" in out
    for label in ("final best fitness", "best fitness at iter. 5", "epsilon", "force closure",
                  "planning time (s)", "evaluations"):
        line = next(l for l in out.splitlines() if l.strip().startswith(label))
        assert len(line.split()) >= 3, line
    assert "iter. 20" not in out  # only 6 iterations ran
    assert len(_table_rows(out.split("PSO result:")[1])) == 6
    for name in ("cube_apso_grasp.png", "cube_pso_grasp.png", "cube_convergence.png"):
        _check_png(str(tmp_path / name))


def test_same_seed_gives_the_same_configuration(tmp_path, capsys):
    docs = []
    for k in range(2):
        path = tmp_path / f"run{k}.json"
        code, _, err = _run(capsys, "--object", "barrel", *SMALL, "--seed", "7", "--no-plots",
                            "--quiet", "--json", str(path))
        assert code == 0, err
        docs.append(json.loads(path.read_text())["results"]["apso"])
    assert docs[0]["joint_positions"] == docs[1]["joint_positions"]
    assert docs[0]["wrist_pose"] == docs[1]["wrist_pose"]
    assert docs[0]["fitness"] == docs[1]["fitness"]


def test_quiet_prints_one_line_per_run(capsys):
    code, out, err = _run(capsys, "--object", "sphere", *SMALL, "--seed", "3", "--no-plots", "--quiet")
    assert code == 0, err
    lines = out.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("sphere APSO: fitness ")
    assert err == ""


@pytest.mark.parametrize("argv, words", [
    (["--object", "banana"], ["--object", "banana", "sphere, cube, barrel, fish"]),
    (["--mesh", "/no/such/dir/part.stl"], ["--mesh", "not found", "part.stl"]),
    (["--particles", "0"], ["--particles", "0"]),
    (["--particles", "many"], ["--particles", "many"]),
    (["--iterations", "-3"], ["--iterations", "-3"]),
    (["--algorithm", "ga"], ["--algorithm", "ga"]),
    (["--friction", "-1"], ["--friction"]),
    (["--object", "cube", "--mesh", "x.stl"], ["--mesh", "--object"]),
    (["--frobnicate"], ["--frobnicate"]),
    (["--obstacle", "box:0.1,0,0"], ["--obstacle", "box:0.1,0,0", "6 numbers", "x,y,z,sx,sy,sz"]),
    (["--obstacle", "cone:0,0,0,1"], ["--obstacle", "cone", "sphere:x,y,z,r", "cylinder:x,y,z,h,r"]),
    (["--obstacle", "sphere:0,0,a,0.1"], ["--obstacle", "expected numbers"]),
    (["--obstacle", "sphere:0.2,0,0,0.05", "--obstacle", "sphere:0.3,0,0,-0.05"], ["--obstacle 2"]),
    (["--obstacle", "cylinder:0.2,0,0,nan,0.1"], ["--obstacle", "finite"]),
    (["--clearance", "-0.01"], ["--clearance", "-0.01"]),
    (["--approach-distance", "-1"], ["--approach-distance"]),
    (["--grasps", "0"], ["--grasps", "0"]),
    (["--grasps", "51"], ["--grasps", "51"]),
    (["--mesh-scale", "0.001"], ["--mesh-scale", "--mesh FILE"]),
    (["--object", "cube", "--mesh-scale", "1"], ["--mesh-scale", "--mesh FILE"]),
    # The object placed into an obstacle: named after the obstacle's option, not object_pose.
    (["--object", "cube", "--obstacle", "box:0.2,0,0,0.01,0.01,0.01", "--obstacle", "sphere:0,0,0,0.3"],
     ["--obstacle 2: the object penetrates this obstacle (SPHERE)"]),
])
def test_bad_input_exits_2_with_a_one_line_message(argv, words, tmp_path, capsys):
    code, out, err = _run(capsys, *SMALL, *argv, "--out", str(tmp_path))
    assert code == 2
    assert out == ""
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("grasp_apso_plan: error: ")
    for word in words:
        assert word in lines[0], (word, lines[0])
    for ros_field in ("mesh_uri", "object_pose", "object_name", "obstacles[", "support_planes", "max_grasps"):
        assert ros_field not in lines[0], lines[0]
    assert not any(tmp_path.iterdir())  # nothing written


def test_json_into_a_missing_folder_is_refused_before_planning(tmp_path, capsys):
    target = tmp_path / "no" / "such" / "x.json"
    code, out, err = _run(capsys, "--object", "cube", *SMALL, "--no-plots", "--json", str(target))
    assert code == 2 and out == ""
    assert err.strip() == f"grasp_apso_plan: error: --json: the folder {target.parent} does not exist (create it first)"
    assert not (tmp_path / "no").exists()
    code, out, err = _run(capsys, "--object", "cube", *SMALL, "--no-plots", "--json", str(tmp_path))
    assert code == 2 and "--json" in err and "is a folder" in err


def test_mesh_errors_name_the_mesh_option(tmp_path, capsys):
    bad = tmp_path / "bad.stl"
    bad.write_bytes(b"solid nothing\nnot an stl\n")
    code, out, err = _run(capsys, "--mesh", str(bad), *SMALL, "--no-plots")
    assert code == 2 and err.startswith("grasp_apso_plan: error: --mesh: "), err
    assert "mesh_uri" not in err


def _box_file(path, edge):
    trimesh.creation.box(extents=(edge, edge * 0.8, edge * 0.6)).export(str(path))


def test_mesh_file_and_mesh_scale(tmp_path, capsys):
    metres = tmp_path / "block.stl"
    _box_file(metres, 0.05)
    code, out, err = _run(capsys, "--mesh", str(metres), *SMALL, "--seed", "0", "--out", str(tmp_path))
    assert code == 0, err
    assert "block (mesh file " in out and "12 triangles, 50 x 40 x 30 mm" in out
    _check_png(str(tmp_path / "block_apso_grasp.png"))
    # The same block in millimetres: too large unless scaled, and the message says so.
    mm = tmp_path / "block_mm.stl"
    _box_file(mm, 50.0)
    code, out, err = _run(capsys, "--mesh", str(mm), *SMALL, "--no-plots")
    assert code == 2 and "too large" in err and "--mesh-scale 0.001" in err and "Traceback" not in err
    assert err.startswith("grasp_apso_plan: error: --mesh: too large"), err
    code, out, err = _run(capsys, "--mesh", str(mm), "--mesh-scale", "0.001", *SMALL, "--no-plots")
    assert code == 0, err
    assert "50 x 40 x 30 mm" in out


def test_module_runs_as_a_script_with_json_on_stdout(tmp_path):
    """One real process: ``python -m grasp_apso.tools.cli`` (what the console script calls)."""
    proc = subprocess.run(
        [sys.executable, "-m", "grasp_apso.tools.cli", "--object", "fish", *SMALL, "--seed", "0",
         "--out", str(tmp_path), "--json", "-"],
        capture_output=True, text=True, timeout=240, cwd=str(tmp_path),
    )
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)  # the report went to stderr
    assert doc["object"]["name"] == "fish" and doc["object"]["shape_class"]
    assert "APSO result:" in proc.stderr and "Traceback" not in proc.stderr
    assert len(doc["results"]["apso"]["joint_positions"]) == 18
    for path in doc["pictures"]:
        _check_png(path)


# ----------------------------------------------------------------------------- plotting
def test_view_angles_put_the_requested_direction_up():
    from matplotlib.figure import Figure
    from mpl_toolkits.mplot3d import proj3d

    rng = np.random.default_rng(0)
    for _ in range(5):
        direction = rng.normal(size=3)
        up = np.cross(direction, rng.normal(size=3))
        elev, azim, roll = plotting.view_angles(direction, up)
        ax = Figure().add_subplot(projection="3d")
        ax.set_xlim(-1, 1), ax.set_ylim(-1, 1), ax.set_zlim(-1, 1)
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(elev=elev, azim=azim, roll=roll)
        up = up / np.linalg.norm(up)
        x, y, _ = proj3d.proj_transform(*up, ax.get_proj())
        x0, y0, _ = proj3d.proj_transform(0, 0, 0, ax.get_proj())
        assert y - y0 > 0 and abs(x - x0) < 1e-6 * max(1.0, abs(y - y0)) + 1e-9


def test_large_meshes_are_decimated_for_drawing():
    mesh = trimesh.creation.icosphere(subdivisions=5)  # 20480 triangles
    verts, faces = plotting.decimate_for_drawing(mesh.vertices, mesh.faces, 3000)
    assert 200 < len(faces) <= 3000
    assert faces.max() < len(verts)
    radii = np.linalg.norm(verts, axis=1)
    assert np.all(np.abs(radii - 1.0) < 0.1)  # still a sphere


def test_plot_convergence_accepts_plain_histories(tmp_path):
    runs = {
        "A": {"best": np.linspace(-1.0, 0.8, 30), "mean": np.linspace(-1.5, 0.5, 30)},
        "B": {"best": np.linspace(0.2, 0.6, 30)},
    }
    path = plotting.plot_convergence(runs, tmp_path / "sub" / "conv.png", title="test")
    assert path == str(tmp_path / "sub" / "conv.png")
    _check_png(path)
    with pytest.raises(ValueError):
        plotting.plot_convergence({}, tmp_path / "none.png")


def test_grasp_title_names_the_quality():
    class R:
        algorithm, fitness, epsilon, force_closure, valid, cancelled = "apso", 0.8123, 0.0456, True, True, False
        contacts = ()
    title = plotting.grasp_title(R(), "sphere")
    assert "sphere" in title and "APSO" in title and "0.812" in title and "0.046" in title
    assert "force closure: yes" in title and "0 contacts: none" in title


# ----------------------------------------------------------------------------- scene, candidates, summary
from dataclasses import replace  # noqa: E402

from grasp_apso.errors import SceneError, UsageError  # noqa: E402
from grasp_apso.model.builtin import builtin  # noqa: E402
from grasp_apso.model.scene import BOX, CYLINDER, SPHERE  # noqa: E402
from grasp_apso.search.planner import PlanOptions, plan  # noqa: E402
from grasp_apso.tools import cli_inputs  # noqa: E402
from grasp_apso.presentation import summary  # noqa: E402
from grasp_apso.presentation.palette import APPROACH_COLOR, SCENE_COLOR, rgb  # noqa: E402


def test_obstacles_and_table_are_parsed_in_the_planning_frame():
    fish = builtin("fish")
    scene = cli_inputs.build_scene(fish, True, ["box:0.1,0,0.02,0.04,0.2,0.1", "sphere:0,0.1,0,0.03",
                                                "cylinder:-0.2,0,0,0.3,0.02"])
    lowest = float(np.asarray(fish.mesh.vertices)[:, 2].min())
    assert np.allclose(scene.planes, [[0.0, 0.0, 1.0, -lowest]])  # z = lowest point, normal up
    kinds = [(o.kind, o.dimensions, tuple(o.pose[:3, 3])) for o in scene.obstacles]
    assert kinds == [(BOX, (0.04, 0.2, 0.1), (0.1, 0.0, 0.02)), (SPHERE, (0.03,), (0.0, 0.1, 0.0)),
                     (CYLINDER, (0.3, 0.02), (-0.2, 0.0, 0.0))]
    assert all(np.allclose(o.pose[:3, :3], np.eye(3)) for o in scene.obstacles)
    assert cli_inputs.build_scene(fish, False, []) is None
    with pytest.raises(UsageError):
        cli_inputs.parse_obstacle("box:1,2,3,4,5")


def test_library_errors_are_named_after_the_options():
    assert cli_inputs.cli_message(SceneError("obstacles[1]: the object penetrates it by 3.0 mm")) == \
        "--obstacle 2: the object penetrates it by 3.0 mm"
    assert cli_inputs.cli_message(SceneError("support_planes[0]: the object sinks 7 mm into it")) == \
        "--table: the object sinks 7 mm into it"
    assert cli_inputs.cli_message(ValueError("approach_distance: must be >= 0")) == \
        "--approach-distance: must be >= 0"
    assert cli_inputs.cli_message(ValueError("max_grasps: 0 not in 1..50")) == "--grasps: 0 not in 1..50"
    assert cli_inputs.cli_message(ValueError("something else: x")) == "something else: x"
    # Placement errors of the object go to the scene item they name; others to the object's option.
    placed = SceneError("object_pose: the object penetrates obstacles[0] (BOX) by 4.0 mm", "object_pose")
    assert cli_inputs.cli_message(placed) == "--obstacle 1: the object penetrates this obstacle (BOX) by 4.0 mm"
    sunk = SceneError("object_pose: the object sinks 3.0 mm into support_planes[0] (at most 1 mm)")
    assert cli_inputs.cli_message(sunk) == "--table: the object sinks 3.0 mm into the table (at most 1 mm)"
    large = ValueError("object: too large for a precision grasp")
    assert cli_inputs.cli_message(large, "--mesh") == "--mesh: too large for a precision grasp"
    assert cli_inputs.cli_message(large) == "--object: too large for a precision grasp"
    assert cli_inputs.cli_message(ValueError("planning: near obstacles[2]")) == "planning: near --obstacle 3"
    assert cli_inputs.cli_message(ValueError("hand description: /h.yaml is not valid YAML")) == \
        "--hand: /h.yaml is not valid YAML"


@pytest.fixture(scope="module")
def cube_result():
    return plan(builtin("cube"), options=PlanOptions(particles=12, iterations=6), rng=np.random.default_rng(0))


def test_one_summary_wording_for_the_cli_and_the_node(cube_result):
    r = cube_result
    assert r.valid and summary.why_not_valid(r) == ""
    line = summary.grasp_summary(r, iterations=6, elapsed=1.5)
    assert line.startswith(f"{r.n_contacts} contacts, fitness {r.fitness:.3f}, epsilon {r.epsilon:.4f}, "
                           f"force closure {'yes' if r.force_closure else 'no'}, 6 of 6 iterations in 1.50 s")
    assert summary.grasp_verdict(r, 6, 1.5) == "grasp found: " + line
    bad = replace(r, valid=False, contacts=r.contacts[:1])
    assert summary.why_not_valid(bad) == "only 1 fingertip contact"
    assert summary.grasp_verdict(bad).startswith("no valid grasp found (only 1 fingertip contact): 1 contacts")
    assert "NO valid grasp (only 1 fingertip contact)" in summary.format_report(bad, HAND, 0.5)
    # several candidates, simulated: counted in the one line and tabulated
    c0 = r.candidates[0]
    cands = (c0, replace(c0, id="g1", rank=1, grasp_quality=0.1, force_closure=False, sim_result=0,
                         sim_max_shift=0.07, sim_max_turn=0.5))
    many = replace(r, candidates=(replace(c0, sim_result=1, sim_max_shift=0.002, sim_max_turn=0.01), cands[1]),
                   candidates_message="2 of 5 requested: the search found no more distinct valid grasps")
    line = summary.grasp_summary(many)
    assert "; 2 candidates (1 force closure); simulation: 1 of 2 held; 2 of 5 requested" in line
    table = summary.format_candidates(many).splitlines()
    assert "rank" in table[1] and "simulation" in table[1] and "approach" in table[1]
    first, second = table[2].split(), table[3].split()
    assert first[0] == "1" and "held" in first and second[0] == "2" and "dropped" in second
    assert "70.0" in second and f"{np.degrees(0.5):.1f}" in second  # shift mm, turn deg
    assert summary.approach_angle_from_above(np.array([0, 0, -1.0]), np.array([0, 0, 1.0])) == pytest.approx(0)
    assert summary.approach_angle_from_above(np.array([1.0, 0, 0]), np.array([0, 0, 1.0])) == pytest.approx(90)


def _pixels_near(path, color, alpha, tol=0.02):
    """Share of pixels whose colour is ``color`` blended at ``alpha`` over white (or solid)."""
    image = mpimg.imread(path)[..., :3]
    target = np.array(rgb(color))
    blended = alpha * target + (1 - alpha)
    near = lambda c: (np.abs(image - c).max(axis=2) < tol).mean()  # noqa: E731
    return max(near(blended), near(target))


def test_pictures_show_the_table_obstacles_and_the_approach(cube_result, tmp_path):
    cube = builtin("cube")
    scene = cli_inputs.build_scene(cube, True, ["box:0.12,0,0,0.04,0.2,0.1", "sphere:0,0.13,0,0.03",
                                                "cylinder:-0.13,0,0,0.1,0.02"])
    with_scene = plotting.plot_grasp(cube_result, cube, path=tmp_path / "scene.png", scene=scene)
    without = plotting.plot_grasp(cube_result, cube, path=tmp_path / "free.png")
    _check_png(with_scene)
    assert _pixels_near(with_scene, SCENE_COLOR, 0.22) > 0.02  # the table patch is plain to see
    assert _pixels_near(without, SCENE_COLOR, 0.22) < 0.2 * _pixels_near(with_scene, SCENE_COLOR, 0.22)
    for path in (with_scene, without):
        assert _pixels_near(path, APPROACH_COLOR, 1.0) > 0.0005  # the approach arrow
    # small multiples: one panel per candidate
    c0 = cube_result.candidates[0]
    three = replace(cube_result, candidates=tuple(replace(c0, rank=k, id=f"g{k}") for k in range(3)))
    path = plotting.plot_candidates(three, cube, path=tmp_path / "cands.png", scene=scene)
    _check_png(path)
    with pytest.raises(ValueError):
        plotting.plot_candidates(replace(cube_result, candidates=()), cube, path=tmp_path / "none.png")


def test_camera_keeps_the_table_level():
    rng = np.random.default_rng(3)
    up = np.array([0.0, 0.0, 1.0])
    for _ in range(5):
        palm, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        for view, (direction, picture_up) in plotting.camera_directions(palm, up).items():
            if view == "palm":
                continue
            assert np.allclose(picture_up, up)
            d = direction / np.linalg.norm(direction)
            assert 15 < np.degrees(np.arcsin(d @ up)) < 35  # a little above the table


def _json_run(capsys, tmp_path, *argv):
    path = tmp_path / "run.json"
    code, out, err = _run(capsys, *SMALL, "--seed", "1", "--out", str(tmp_path), "--json", str(path), *argv)
    assert code == 0, err
    return out, json.loads(path.read_text())


def test_fish_on_a_table_is_grasped_from_above(tmp_path, capsys):
    out, doc = _json_run(capsys, tmp_path, "--object", "fish", "--table")
    assert "scene      table (support plane, normal +z) at z = " in out
    assert "from above" in out
    table_z = -doc["scene"]["support_planes"][0][3]
    assert doc["scene"]["support_planes"][0][:3] == [0.0, 0.0, 1.0]
    result = doc["results"]["apso"]
    assert result["valid"]
    reach = max(HAND.pad_radius, *HAND.link_radii)
    for cand in result["candidates"]:
        approach = np.array(cand["approach_direction"])
        assert approach[2] < -0.5, approach  # from above: within 60 degrees of straight down
        assert cand["scene_distance"] >= 0.005 - 1e-4  # clearance, by the planner's python-fcl check
        pre, grasp = np.array(cand["pre_grasp_pose"]["position"]), np.array(cand["wrist_pose"]["position"])
        assert pre[2] > grasp[2] > table_z + reach
    _check_png(str(tmp_path / "fish_apso_grasp.png"))


def test_grasps_prints_the_candidate_table_and_small_multiples(tmp_path, capsys):
    out, doc = _json_run(capsys, tmp_path, "--object", "cube", "--table", "--grasps", "3",
                         "--obstacle", "box:0.1,0,0,0.04,0.2,0.1")
    cands = doc["results"]["apso"]["candidates"]
    assert 1 <= len(cands) <= 3
    assert [c["rank"] for c in cands] == list(range(len(cands)))
    quality = [c["grasp_quality"] for c in cands]
    assert quality == sorted(quality, reverse=True) and all(0.0 <= q <= 1.0 for q in quality)
    assert cands[0]["joint_positions"] == doc["results"]["apso"]["joint_positions"]
    rows = [l.split() for l in out.split("Candidates:")[1].splitlines()[2:2 + len(cands)]]
    assert [int(r[0]) for r in rows] == [c["rank"] + 1 for c in cands]
    assert cli.RANK_NOTE in out  # the table's 1-based rank is labelled as such
    assert [float(r[1]) for r in rows] == pytest.approx(quality, abs=1e-3)
    if len(cands) < 3:
        assert doc["results"]["apso"]["candidates_message"]
    _check_png(str(tmp_path / "cube_apso_candidates.png"))
    assert doc["scene"]["obstacles"][0]["type"] == "BOX"


def test_simulate_reports_held_or_dropped_per_candidate(tmp_path, capsys):
    out, doc = _json_run(capsys, tmp_path, "--object", "sphere", "--simulate", "--grasps", "2", "--no-plots")
    cands = doc["results"]["apso"]["candidates"]
    assert cands and all(c["sim_result"] in (0, 1) for c in cands)
    assert all(c["sim_max_shift"] is not None and c["sim_max_turn"] is not None for c in cands)
    assert "simulation" in out and ("held" in out or "dropped" in out)
