"""Tests of grasp_apso.model.objects: validation, built-in objects, mesh files, poses."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import trimesh

from grasp_apso.model import mesh_files
from grasp_apso.model import objects
from grasp_apso.model.objects import GraspObject, from_arrays
from grasp_apso.model.builtin import BUILTIN_OBJECTS, builtin
from grasp_apso.errors import ObjectError
from grasp_apso.model.mesh_files import from_file
from grasp_apso.model.poses import matrix_to_pose, pose_to_matrix, transform_points, transform_vectors

MM = 1e-3


def cube_arrays(edge: float = 0.07) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (8, 3) and triangles (12, 3) of a closed cube centred at the origin."""
    box = trimesh.creation.box(extents=(edge, edge, edge))
    return np.array(box.vertices), np.array(box.faces)


# --------------------------------------------------------------------------------------
# Built-in objects
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "extents"),
    [
        ("sphere", (0.05, 0.05, 0.05)),
        ("cube", (0.07, 0.07, 0.07)),
        ("barrel", (0.03, 0.03, 0.11)),
        ("fish", (0.29, 0.06, 0.07)),
    ],
)
def test_builtin_sizes(name: str, extents: tuple[float, float, float]) -> None:
    obj = builtin(name)
    np.testing.assert_allclose(obj.extents, extents, atol=1 * MM)
    np.testing.assert_allclose(obj.mesh.extents, extents, atol=1 * MM)


@pytest.mark.parametrize("name", BUILTIN_OBJECTS)
def test_builtin_closed_outward_solid(name: str) -> None:
    obj = builtin(name)
    assert obj.watertight
    assert obj.mesh.is_watertight
    assert obj.mesh.is_winding_consistent
    assert obj.mesh.volume > 0.0
    assert obj.volume == pytest.approx(obj.mesh.volume)
    # Outward normals: the face farthest along each axis points that way.
    centres = obj.mesh.triangles_center
    for axis in range(3):
        face = int(np.argmax(centres[:, axis]))
        assert obj.mesh.face_normals[face, axis] > 0.0


@pytest.mark.parametrize("name", BUILTIN_OBJECTS)
def test_builtin_centre_of_mass_at_origin(name: str) -> None:
    np.testing.assert_allclose(builtin(name).center_of_mass, 0.0, atol=1e-6)


def test_builtin_volumes_match_the_shapes() -> None:
    assert builtin("cube").volume == pytest.approx(0.07**3, rel=1e-9)
    assert builtin("sphere").volume == pytest.approx(4 / 3 * np.pi * 0.025**3, rel=0.02)
    barrel = builtin("barrel").volume
    assert np.pi * (0.015 / 1.1) ** 2 * 0.11 < barrel < np.pi * 0.015**2 * 0.11


def test_builtin_characteristic_radius() -> None:
    assert builtin("sphere").characteristic_radius == pytest.approx(0.025, rel=1e-6)
    assert builtin("cube").characteristic_radius == pytest.approx(0.07 * np.sqrt(3) / 2)


def test_fish_has_body_stalk_and_tail_fin() -> None:
    fish = builtin("fish").mesh
    x = fish.vertices[:, 0]
    x_min, length = x.min(), np.ptp(x)

    def height_at(fraction: float) -> float:
        """Height (m) of the vertices in a 1 cm slab at ``fraction`` of the length."""
        near = np.abs(x - (x_min + fraction * length)) < 0.005
        return float(np.ptp(fish.vertices[near, 2]))

    body, stalk, fin = height_at(0.7), height_at(0.22), height_at(0.03)
    assert body > 0.06
    assert stalk < 0.4 * body
    assert fin > 2.0 * stalk
    # Thin tail fin, wide body.
    near_tail = x < x_min + 0.03
    assert np.ptp(fish.vertices[near_tail, 1]) < 0.01


def test_builtin_is_cached_and_unknown_name_rejected() -> None:
    assert builtin("fish") is builtin("fish")
    with pytest.raises(ObjectError, match="object_name: unknown built-in object 'teapot'") as err:
        builtin("teapot")
    for name in BUILTIN_OBJECTS:
        assert name in str(err.value)


def test_principal_extents_and_axes() -> None:
    barrel = builtin("barrel")
    assert barrel.principal_extents[0] == pytest.approx(0.11, abs=1 * MM)
    assert abs(barrel.principal_axes[0, 2]) == pytest.approx(1.0, abs=1e-6)
    fish = builtin("fish")
    np.testing.assert_allclose(fish.principal_extents, (0.29, 0.07, 0.06), atol=1 * MM)
    for obj in (barrel, fish, builtin("sphere"), builtin("cube")):
        axes = obj.principal_axes
        np.testing.assert_allclose(axes @ axes.T, np.eye(3), atol=1e-9)
        assert np.linalg.det(axes) == pytest.approx(1.0)
        assert np.all(np.diff(obj.principal_extents) <= 0.0)


def test_principal_extents_of_a_rotated_cube() -> None:
    vertices, faces = cube_arrays()
    rotation = pose_to_matrix((0, 0, 0), (0.1, 0.3, 0.2, 0.9273618495495703))
    cube = from_arrays(transform_points(rotation, vertices), faces)
    np.testing.assert_allclose(cube.principal_extents, 0.07, atol=1e-6)
    assert np.all(cube.extents > 0.075)


def test_principal_extents_of_a_large_rotated_ellipsoid() -> None:
    # 2562 hull vertices: the oriented-box search runs on a subset of them.
    ellipsoid = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    ellipsoid.apply_scale((0.03, 0.018, 0.009))
    ellipsoid.apply_transform(trimesh.transformations.rotation_matrix(0.5, (1.0, 1.0, 0.0)))
    obj = from_arrays(ellipsoid.vertices, ellipsoid.faces)
    assert len(obj.hull_vertices) > objects._OBB_MAX_POINTS
    np.testing.assert_allclose(obj.principal_extents, (0.06, 0.036, 0.018), atol=1 * MM)
    axis = obj.principal_axes[0]
    longest = ellipsoid.vertices[np.argmax(np.linalg.norm(ellipsoid.vertices, axis=1))]
    assert abs(axis @ longest / np.linalg.norm(longest)) > 0.99


def test_object_is_immutable() -> None:
    obj = builtin("cube")
    with pytest.raises(dataclasses.FrozenInstanceError):
        obj.name = "other"  # type: ignore[misc]
    for array in (
        obj.center_of_mass,
        obj.extents,
        obj.principal_extents,
        obj.principal_axes,
        obj.hull_vertices,
        obj.mesh.vertices,
        obj.mesh.faces,
    ):
        with pytest.raises(ValueError):
            array[0] = 1.0


# --------------------------------------------------------------------------------------
# from_arrays: processing and bad input
# --------------------------------------------------------------------------------------


def test_from_arrays_accepts_lists_and_float_indices() -> None:
    vertices, faces = cube_arrays()
    obj = from_arrays(vertices.tolist(), faces.astype(float).tolist(), name="box")
    assert obj.name == "box"
    assert obj.watertight
    assert obj.mesh.volume == pytest.approx(0.07**3)


def test_inverted_and_mixed_winding_are_fixed() -> None:
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=0.03)
    volume = sphere.volume
    inverted = from_arrays(sphere.vertices, sphere.faces[:, ::-1])
    mixed_faces = np.array(sphere.faces)
    mixed_faces[::3] = mixed_faces[::3, ::-1]
    mixed = from_arrays(sphere.vertices, mixed_faces)
    for obj in (inverted, mixed):
        assert obj.watertight
        assert obj.mesh.is_winding_consistent
        assert obj.mesh.volume == pytest.approx(volume)


def test_each_closed_piece_is_turned_outward() -> None:
    left = trimesh.creation.box(extents=(0.02, 0.02, 0.02))
    right = left.copy()
    right.apply_translation((0.05, 0.0, 0.0))
    right_faces = np.array(right.faces)[:, ::-1] + len(left.vertices)  # inverted body
    right_faces[::2] = right_faces[::2, ::-1]  # ... with mixed winding
    obj = from_arrays(np.vstack([left.vertices, right.vertices]),
                      np.vstack([left.faces, right_faces]))
    assert obj.watertight
    assert obj.mesh.is_winding_consistent
    for body in obj.mesh.split(only_watertight=False):
        assert body.volume == pytest.approx(0.02**3)


def test_non_orientable_closed_surface_is_not_a_solid() -> None:
    # The 6-vertex real projective plane: every edge in two triangles, not orientable.
    faces = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5], [0, 5, 1],
                      [1, 2, 4], [2, 3, 5], [3, 4, 1], [4, 5, 2], [5, 1, 3]])
    vertices = np.random.default_rng(1).uniform(-0.03, 0.03, (6, 3))
    obj = from_arrays(vertices, faces)
    assert not obj.watertight
    np.testing.assert_array_equal(obj.mesh.faces, faces)  # left as given, not half re-wound
    np.testing.assert_allclose(obj.center_of_mass, obj.mesh.convex_hull.center_mass)


def test_duplicate_and_degenerate_faces_are_removed() -> None:
    vertices, faces = cube_arrays()
    extra = np.vstack([faces, faces[:2], [[0, 0, 1]], [[0, 1, 1]]])
    obj = from_arrays(vertices, extra)
    assert len(obj.mesh.faces) == 12
    assert obj.watertight


def test_open_mesh_takes_centre_of_mass_from_hull() -> None:
    fish = builtin("fish").mesh
    # a hole whose rim is not a simple loop (a fin on one of its edges) stays open (issue
    # 19: other small holes are closed, large ones refused)
    faces = np.asarray(fish.faces)[1:]
    a, b = faces[0][0], faces[0][1]
    vertices = np.vstack([fish.vertices, np.asarray(fish.vertices)[[a, b]].mean(axis=0) + [0.0, 0.0, 0.01]])
    opened = from_arrays(vertices, np.vstack([faces, [[a, b, len(vertices) - 1]]]))
    assert not opened.watertight
    hull_com = opened.mesh.convex_hull.center_mass
    np.testing.assert_allclose(opened.center_of_mass, hull_com, atol=1e-9)
    assert opened.volume == pytest.approx(opened.mesh.convex_hull.volume)


def test_a_small_hole_is_closed_and_the_solid_gives_the_centre_of_mass() -> None:
    fish = builtin("fish")
    closed = from_arrays(fish.mesh.vertices, fish.mesh.faces[1:])
    assert closed.watertight
    np.testing.assert_allclose(closed.center_of_mass, fish.center_of_mass, atol=0.1 * MM)
    assert closed.volume == pytest.approx(fish.volume, rel=1e-3)
    # The hull fills the fork and the stalk: its centroid differs from the solid's.
    assert np.linalg.norm(fish.mesh.convex_hull.center_mass - closed.center_of_mass) > 1 * MM


def _bad_meshes() -> list[tuple[str, object, object, str]]:
    cube_v, cube_f = cube_arrays()
    bad_index = cube_f.copy()
    bad_index[3, 1] = 99
    negative = cube_f.copy()
    negative[0, 2] = -1
    square_v = np.array([[0, 0, 0], [0.05, 0, 0], [0.05, 0.05, 0], [0, 0.05, 0]], float)
    square_f = np.array([[0, 1, 2], [0, 2, 3]])
    line_v = np.array([[0, 0, 0], [0.01, 0, 0], [0.02, 0, 0]], float)
    thin_v, thin_f = cube_arrays()
    thin_v[:, 2] *= 0.5 * MM / 0.07
    float_idx = cube_f.astype(float)
    float_idx[2, 0] = 1.5
    nan_v = cube_v.copy()
    nan_v[5, 1] = np.nan
    inf_v = cube_v.copy()
    inf_v[2, 0] = np.inf
    return [
        ("no vertices", np.zeros((0, 3)), cube_f, "mesh: empty"),
        ("no triangles", cube_v, np.zeros((0, 3), int), "mesh: empty"),
        ("empty lists", [], [], "mesh: empty"),
        ("vertex shape", cube_v[:, :2], cube_f, "mesh: vertices must have shape (V, 3)"),
        ("triangle shape", cube_v, cube_f[:, :2], "mesh: triangles must have shape (T, 3)"),
        ("string vertices", [["a", "b", "c"]], cube_f, "mesh: vertices must be real numbers"),
        ("ragged vertices", [[0, 0, 0], [1, 0]], cube_f, "mesh: vertices are not a numeric array"),
        (
            "ragged triangles",
            cube_v,
            [[0, 1, 2], [0, 1]],
            "mesh: triangles are not an integer array",
        ),
        ("NaN vertex", nan_v, cube_f, "mesh: vertex 5 is NaN"),
        ("inf vertex", inf_v, cube_f, "mesh: vertex 2 is infinite"),
        ("index range", cube_v, bad_index, "mesh: triangle 3 index 99 out of range (8 vertices)"),
        ("negative index", cube_v, negative, "mesh: triangle 0 index -1 out of range (8 vertices)"),
        ("float index", cube_v, float_idx, "mesh: triangle 2 index 1.5 is not an integer"),
        ("bool index", cube_v, cube_f > 3, "mesh: triangles must be integer indices"),
        ("collinear", line_v, [[0, 1, 2]], "mesh: degenerate (all triangles have zero area)"),
        ("repeated vertex", cube_v, np.array([[0, 0, 1], [2, 2, 2]]), "mesh: degenerate"),
        ("flat square", square_v, square_f, "mesh: flat (thickness 0.0 m along its thinnest axis"),
        ("thin box", thin_v, thin_f, "mesh: flat (thickness 0.0005 m"),
        (
            "too many triangles",
            cube_v,
            np.zeros((250_000, 3), int),
            "mesh: 250000 triangles exceeds the limit of 200000",
        ),
    ]


@pytest.mark.parametrize(
    ("vertices", "triangles", "message"),
    [case[1:] for case in _bad_meshes()],
    ids=[case[0] for case in _bad_meshes()],
)
def test_bad_mesh_raises_object_error(vertices: object, triangles: object, message: str) -> None:
    with pytest.raises(ObjectError) as err:
        from_arrays(vertices, triangles)
    assert message in str(err.value)
    assert isinstance(err.value, ValueError)


def test_triangle_limit_is_a_parameter() -> None:
    vertices, faces = cube_arrays()
    with pytest.raises(ObjectError, match="mesh: 12 triangles exceeds the limit of 10"):
        from_arrays(vertices, faces, max_triangles=10)
    with pytest.raises(ValueError, match="max_triangles"):
        from_arrays(vertices, faces, max_triangles=0)


# --------------------------------------------------------------------------------------
# mesh_hash
# --------------------------------------------------------------------------------------


def test_mesh_hash_stable_and_distinct() -> None:
    vertices, faces = cube_arrays()
    first = from_arrays(vertices, faces)
    again = from_arrays(vertices.copy(), faces.copy(), name="other")
    assert len(first.mesh_hash) == 64
    assert first.mesh_hash == again.mesh_hash
    assert first.mesh_hash == builtin("cube").mesh_hash
    moved = from_arrays(vertices + (0.001, 0.0, 0.0), faces)
    assert moved.mesh_hash != first.mesh_hash
    hashes = {builtin(name).mesh_hash for name in BUILTIN_OBJECTS}
    assert len(hashes) == len(BUILTIN_OBJECTS)


def test_equality_and_hash_follow_name_and_mesh() -> None:
    vertices, faces = cube_arrays()
    assert from_arrays(vertices, faces, name="cube") == builtin("cube")
    assert from_arrays(vertices, faces, name="box") != builtin("cube")
    assert len({builtin("cube"), from_arrays(vertices, faces, name="cube")}) == 1


# --------------------------------------------------------------------------------------
# Mesh files
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("fmt", objects.MESH_FORMATS)
@pytest.mark.parametrize("name", ["barrel", "fish"])
def test_file_round_trip(tmp_path, fmt: str, name: str) -> None:
    original = builtin(name)
    path = tmp_path / f"{name}.{fmt}"
    original.mesh.export(str(path))
    loaded = from_file(str(path), allowed_dir=tmp_path)
    assert loaded.name == name
    assert loaded.watertight
    assert loaded.mesh.volume == pytest.approx(original.mesh.volume, rel=1e-4)
    np.testing.assert_allclose(loaded.center_of_mass, original.center_of_mass, atol=1e-6)


def test_file_uri_pathlike_and_upper_case_extension(tmp_path) -> None:
    path = tmp_path / "my cube.STL"
    builtin("cube").mesh.export(str(path), file_type="stl")
    by_uri = from_file("file://" + str(path).replace(" ", "%20"), allowed_dir=tmp_path)
    by_pathlike = from_file(path)
    assert by_uri.name == "my cube"
    assert by_uri.mesh_hash == by_pathlike.mesh_hash
    assert by_uri.mesh.volume == pytest.approx(0.07**3)


def test_scene_files_are_concatenated(tmp_path, monkeypatch) -> None:
    path = tmp_path / "scene.obj"
    builtin("cube").mesh.export(str(path))
    left = trimesh.creation.box(extents=(0.02, 0.02, 0.02))
    right = left.copy()
    right.apply_translation((0.05, 0.0, 0.0))
    monkeypatch.setattr(trimesh, "load", lambda *a, **k: trimesh.Scene([left, right]))
    obj = from_file(path)
    assert len(obj.mesh.faces) == 24
    np.testing.assert_allclose(obj.center_of_mass, (0.025, 0.0, 0.0), atol=1e-9)


def _write(path, data: bytes) -> str:
    path.write_bytes(data)
    return str(path)


def test_file_not_found(tmp_path) -> None:
    with pytest.raises(ObjectError, match="mesh_uri: file not found: .*missing.stl"):
        from_file(tmp_path / "missing.stl")


@pytest.mark.parametrize(
    ("filename", "shown"),
    [("points.xyz", "'.xyz'"), ("mesh", "'(none)'"), ("mesh.dae", "'.dae'")],
)
def test_unknown_format(tmp_path, filename: str, shown: str) -> None:
    path = _write(tmp_path / filename, b"0 0 0\n")
    with pytest.raises(ObjectError) as err:
        from_file(path)
    assert f"mesh_uri: unknown format {shown} (expected stl, obj, ply, off)" in str(err.value)


@pytest.mark.parametrize(
    "uri", ["http://example.com/cube.stl", "package://grasp_apso/cube.stl", "ftp://host/x.stl"]
)
def test_other_uri_schemes_refused(uri: str) -> None:
    with pytest.raises(ObjectError, match="mesh_uri: unsupported URI scheme"):
        from_file(uri)


def test_remote_file_uri_and_empty_path_refused() -> None:
    with pytest.raises(ObjectError, match="mesh_uri: remote file:// host"):
        from_file("file://server/share/cube.stl")
    with pytest.raises(ObjectError, match="mesh_uri: empty"):
        from_file("")


def test_path_traversal_refused(tmp_path) -> None:
    allowed = tmp_path / "meshes"
    allowed.mkdir()
    builtin("cube").mesh.export(str(tmp_path / "secret.stl"))
    builtin("cube").mesh.export(str(allowed / "ok.stl"))
    assert from_file(allowed / "ok.stl", allowed_dir=allowed).watertight
    for attempt in (
        f"{allowed}/../secret.stl",
        f"file://{allowed}/../secret.stl",
        str(tmp_path / "secret.stl"),
    ):
        with pytest.raises(ObjectError, match="mesh_uri: outside the allowed mesh directory"):
            from_file(attempt, allowed_dir=allowed)
    # A sibling whose name starts with the allowed directory's name is outside too.
    sibling = tmp_path / "meshes-evil"
    sibling.mkdir()
    builtin("cube").mesh.export(str(sibling / "x.stl"))
    with pytest.raises(ObjectError, match="outside the allowed mesh directory"):
        from_file(sibling / "x.stl", allowed_dir=allowed)
    # Refused before looking: a missing file outside says "outside", not "not found".
    with pytest.raises(ObjectError, match="outside the allowed mesh directory"):
        from_file(f"{allowed}/../nothing.stl", allowed_dir=allowed)


def test_symlink_escaping_the_directory_refused(tmp_path) -> None:
    allowed = tmp_path / "meshes"
    allowed.mkdir()
    builtin("cube").mesh.export(str(tmp_path / "secret.stl"))
    (allowed / "link.stl").symlink_to(tmp_path / "secret.stl")
    (allowed / "subdir").symlink_to(tmp_path)
    for attempt in (allowed / "link.stl", allowed / "subdir" / "secret.stl"):
        with pytest.raises(ObjectError, match="mesh_uri: outside the allowed mesh directory"):
            from_file(attempt, allowed_dir=allowed)
    # A symlink that stays inside is fine.
    builtin("cube").mesh.export(str(allowed / "real.stl"))
    (allowed / "alias.stl").symlink_to(allowed / "real.stl")
    assert from_file(allowed / "alias.stl", allowed_dir=allowed).name == "alias"


def test_missing_allowed_dir_refused(tmp_path) -> None:
    path = tmp_path / "cube.stl"
    builtin("cube").mesh.export(str(path))
    with pytest.raises(ObjectError, match="mesh_uri: the allowed mesh directory does not exist"):
        from_file(path, allowed_dir=tmp_path / "nope")


def test_file_too_large_refused(tmp_path) -> None:
    path = tmp_path / "cube.stl"
    builtin("cube").mesh.export(str(path))
    with pytest.raises(ObjectError, match=r"mesh_uri: file is \d+ bytes, exceeds the limit of 100"):
        from_file(path, max_bytes=100)


def test_too_many_triangles_in_file(tmp_path) -> None:
    path = tmp_path / "sphere.ply"
    builtin("sphere").mesh.export(str(path))
    with pytest.raises(ObjectError) as err:
        from_file(path, max_triangles=1000)
    assert "mesh: 1280 triangles exceeds the limit of 1000" in str(err.value)
    assert "mesh_uri" in str(err.value)


def test_flat_mesh_file_names_the_mesh_problem(tmp_path) -> None:
    square = trimesh.Trimesh(
        [[0, 0, 0], [0.05, 0, 0], [0.05, 0.05, 0], [0, 0.05, 0]], [[0, 1, 2], [0, 2, 3]]
    )
    path = tmp_path / "square.obj"
    square.export(str(path))
    with pytest.raises(ObjectError, match=r"mesh: flat .*\(mesh_uri: .*square.obj\)"):
        from_file(path)


PLY_POINTS = b"""ply
format ascii 1.0
element vertex 3
property float x
property float y
property float z
end_header
0 0 0
1 0 0
0 1 0
"""


@pytest.mark.parametrize(
    ("filename", "data", "message"),
    [
        ("empty.stl", b"", "mesh_uri: file is empty"),
        ("text.stl", b"hello, not a mesh", "mesh_uri: file contains no triangles"),
        # 1024 bytes that trimesh reads as a (bogus) binary STL header with no usable facets
        ("binary.stl", bytes(range(256)) * 4, "mesh_uri: file contains no triangles"),
        ("garbage.ply", b"garbage", "mesh_uri: cannot parse as PLY"),
        ("garbage.off", b"garbage", "mesh_uri: cannot parse as OFF"),
        ("points.ply", PLY_POINTS, "mesh_uri: file contains no triangles"),
        ("points.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", "mesh_uri: file contains no triangles"),
    ],
)
def test_unparseable_files(tmp_path, filename: str, data: bytes, message: str) -> None:
    path = _write(tmp_path / filename, data)
    with pytest.raises(ObjectError) as err:
        from_file(path)
    assert message in str(err.value)


def test_directory_and_unreadable_file_refused(tmp_path, monkeypatch) -> None:
    (tmp_path / "dir.stl").mkdir()
    with pytest.raises(ObjectError, match="mesh_uri: not a regular file"):
        from_file(tmp_path / "dir.stl")
    path = tmp_path / "locked.stl"
    builtin("cube").mesh.export(str(path))

    def refuse(*args: object, **kwargs: object) -> None:
        raise PermissionError(13, "Permission denied")

    # Root reads files without read permission, so simulate the failing open().
    monkeypatch.setattr(mesh_files, "open", refuse, raising=False)
    with pytest.raises(ObjectError, match="mesh_uri: cannot read file \\(Permission denied\\)"):
        from_file(path)


# --------------------------------------------------------------------------------------
# Poses
# --------------------------------------------------------------------------------------


def test_pose_round_trip() -> None:
    rng = np.random.default_rng(7)
    for _ in range(20):
        quaternion = rng.normal(size=4)
        quaternion /= np.linalg.norm(quaternion)
        position = rng.uniform(-1.0, 1.0, size=3)
        transform = pose_to_matrix(position, quaternion)
        rotation = transform[:3, :3]
        np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)
        np.testing.assert_allclose(transform[3], (0, 0, 0, 1))
        back_position, back_quaternion = matrix_to_pose(transform)
        np.testing.assert_allclose(back_position, position, atol=1e-12)
        sign = np.sign(quaternion[3]) or 1.0
        np.testing.assert_allclose(back_quaternion, sign * quaternion, atol=1e-9)
        assert back_quaternion[3] >= 0.0


def test_pose_known_rotation() -> None:
    half = np.sqrt(0.5)
    transform = pose_to_matrix((1.0, 2.0, 3.0), (0.0, 0.0, half, half))  # 90 deg about z
    point = transform_points(transform, (1.0, 0.0, 0.0))
    vector = transform_vectors(transform, (1.0, 0.0, 0.0))
    np.testing.assert_allclose(point, (1.0, 3.0, 3.0), atol=1e-12)
    np.testing.assert_allclose(vector, (0.0, 1.0, 0.0), atol=1e-12)


def test_transform_keeps_leading_shape() -> None:
    transform = pose_to_matrix((0.1, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
    points = np.zeros((2, 5, 3))
    moved = transform_points(transform, points)
    assert moved.shape == (2, 5, 3)
    np.testing.assert_allclose(moved[..., 0], 0.1)
    np.testing.assert_allclose(transform_vectors(transform, points), 0.0)
    with pytest.raises(ValueError, match="points"):
        transform_points(transform, np.zeros((4, 2)))
    with pytest.raises(ValueError, match="T: expected shape"):
        transform_vectors(np.eye(3), np.zeros(3))


def test_nearly_unit_quaternion_is_normalised() -> None:
    transform = pose_to_matrix((0, 0, 0), (0.0, 0.0, 0.0, 1.0005))
    np.testing.assert_allclose(transform[:3, :3], np.eye(3), atol=1e-12)


@pytest.mark.parametrize(
    ("position", "quaternion", "message"),
    [
        ((0, 0, 0), (0, 0, 0, 1.7), "object_pose: quaternion is not unit (norm 1.7)"),
        ((0, 0, 0), (0.5, 0.5, 0.5, 0.4), "object_pose: quaternion is not unit (norm 0.9539)"),
        ((0, 0, 0), (0, 0, 0, 0), "object_pose: zero quaternion"),
        ((0, 0, 0), (0, 0, np.nan, 1), "object_pose: quaternion is not finite"),
        ((0, np.inf, 0), (0, 0, 0, 1), "object_pose: position is not finite"),
        ((0, 0), (0, 0, 0, 1), "object_pose: position must have shape (3,)"),
        ((0, 0, 0), (0, 0, 1), "object_pose: quaternion must have shape (4,)"),
    ],
)
def test_bad_pose_rejected(position: object, quaternion: object, message: str) -> None:
    with pytest.raises(ObjectError) as err:
        pose_to_matrix(position, quaternion)
    assert message in str(err.value)


def test_pose_field_name_is_configurable() -> None:
    with pytest.raises(ObjectError, match="wrist_pose: zero quaternion"):
        pose_to_matrix((0, 0, 0), (0, 0, 0, 0), field="wrist_pose")


def test_matrix_to_pose_rejects_non_rigid() -> None:
    with pytest.raises(ValueError, match="T: rotation block is not a proper rotation"):
        matrix_to_pose(np.diag((2.0, 1.0, 1.0, 1.0)))
    with pytest.raises(ValueError, match="T: rotation block"):
        matrix_to_pose(np.diag((-1.0, 1.0, 1.0, 1.0)))
    bad_row = np.eye(4)
    bad_row[3, 0] = 1.0
    with pytest.raises(ValueError, match="T: last row"):
        matrix_to_pose(bad_row)


def test_each_source_has_one_home() -> None:
    """No aliases or re-exports: objects.py builds from arrays, builtin.py and mesh_files.py
    are the other sources (issue 10: no import cycle through re-exports)."""
    from grasp_apso.model import objects as objects_module

    vertices, faces = cube_arrays()
    assert from_arrays(vertices, faces, name="cube") == builtin("cube")
    for name in ("builtin", "from_file", "pose_to_matrix", "BUILTIN_OBJECTS"):
        assert not hasattr(objects_module, name), name
