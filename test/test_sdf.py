"""Tests for grasp_apso.geometry.sdf: the signed distance grid against analytic distances of a
sphere, a box and a cylinder (accuracy in the band where decisions are made, sign
everywhere, far field), gradient and projection onto the surface, determinism and the
cache."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from grasp_apso.cache import CACHE_LIMITS, named_cache
from grasp_apso.geometry.sdf import SignedDistanceGrid, build_sdf_grid, cached_sdf_grid

R_SPHERE = 0.025
BOX_EDGE = 0.07
CYL_R, CYL_H = 0.015, 0.11
GRID_KWARGS = {"padding": 0.025}  # as make_grasp_model builds its grids
BAND_OUT, BAND_IN = 0.010, 0.003  # accuracy band: 10 mm outside, 3 mm inside


def sphere_sdf(p: np.ndarray) -> np.ndarray:
    return np.linalg.norm(p, axis=-1) - R_SPHERE


def box_sdf(p: np.ndarray, half: float = BOX_EDGE / 2) -> np.ndarray:
    q = np.abs(p) - half
    return np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(axis=-1), 0.0)


def cylinder_sdf(p: np.ndarray) -> np.ndarray:
    d = np.stack([np.linalg.norm(p[..., :2], axis=-1) - CYL_R, np.abs(p[..., 2]) - CYL_H / 2], axis=-1)
    return np.minimum(d.max(axis=-1), 0.0) + np.linalg.norm(np.maximum(d, 0.0), axis=-1)


def _meshes() -> dict:
    return {
        # icosphere facets lie at most ~0.02 mm inside the sphere; 128 cylinder sections
        # at most 0.005 mm inside the cylinder: negligible against the tolerances below.
        "sphere": (trimesh.creation.icosphere(subdivisions=4, radius=R_SPHERE), sphere_sdf),
        "box": (trimesh.creation.box(extents=(BOX_EDGE,) * 3), box_sdf),
        "cylinder": (trimesh.creation.cylinder(radius=CYL_R, height=CYL_H, sections=128), cylinder_sdf),
    }


MESHES = _meshes()


@pytest.fixture(scope="module")
def grids() -> dict[str, SignedDistanceGrid]:
    return {name: build_sdf_grid(mesh, **GRID_KWARGS) for name, (mesh, _) in MESHES.items()}


def band_points(name: str, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Points within the band and their analytic distances: uniform in the bounding box
    grown by 15 mm, plus surface samples pushed along the face normal (dense near the
    surface, edges and corners)."""
    mesh, exact = MESHES[name]
    rng = np.random.default_rng(seed)
    lo, hi = mesh.bounds[0] - 0.015, mesh.bounds[1] + 0.015
    uniform = rng.uniform(lo, hi, size=(200_000, 3))
    surf, face = trimesh.sample.sample_surface(mesh, 30_000, seed=seed)
    pushed = surf + mesh.face_normals[face] * rng.uniform(-BAND_IN, BAND_OUT, size=(len(surf), 1))
    pts = np.vstack([uniform, pushed])
    d = exact(pts)
    keep = (d <= BAND_OUT) & (d >= -BAND_IN)
    return pts[keep], d[keep]


# ------------------------------------------------------------------------------------------
# accuracy and sign
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", list(MESHES))
def test_band_accuracy_against_analytic_distance(grids, name: str) -> None:
    pts, exact = band_points(name, seed=10)
    assert len(pts) > 20_000
    err = np.abs(grids[name].distance(pts) - exact)
    assert err.max() < 0.001, f"{name}: max error {err.max() * 1e3:.3f} mm"
    assert np.percentile(err, 99) < 0.0005, f"{name}: 99th percentile {np.percentile(err, 99) * 1e3:.3f} mm"


@pytest.mark.parametrize("name", list(MESHES))
def test_sign_is_correct_everywhere_in_the_grid(grids, name: str) -> None:
    grid = grids[name]
    _, exact = MESHES[name]
    rng = np.random.default_rng(11)
    pts = np.vstack([rng.uniform(grid.origin, grid.upper, size=(100_000, 3)), band_points(name, seed=12)[0]])
    d = exact(pts)
    sure = np.abs(d) > 0.001
    got = grid.distance(pts[sure])
    wrong = np.sign(got) != np.sign(d[sure])
    assert not wrong.any(), f"{name}: {wrong.sum()} wrong signs, e.g. at {pts[sure][wrong][:3]}"
    # deep inside: negative and roughly right (coarse distance transform, about a spacing)
    assert grid.distance(np.zeros(3)) < -0.01
    assert abs(grid.distance(np.zeros(3)) - exact(np.zeros(3))) < 2 * grid.spacing


@pytest.mark.parametrize("name", list(MESHES))
def test_far_points_are_positive_over_estimates(grids, name: str) -> None:
    grid = grids[name]
    _, exact = MESHES[name]
    rng = np.random.default_rng(13)
    u = rng.normal(size=(2000, 3))
    pts = u / np.linalg.norm(u, axis=1, keepdims=True) * rng.uniform(0.12, 2.0, size=(2000, 1))
    outside_box = np.any((pts < grid.origin) | (pts > grid.upper), axis=1)
    assert outside_box.all()
    got = grid.distance(pts)
    assert (got > 0.0).all()
    assert (got >= exact(pts) - 2 * grid.spacing).all()  # never much closer than the truth


def test_distance_equals_distance_xyz_and_keeps_shape(grids) -> None:
    grid = grids["box"]
    rng = np.random.default_rng(14)
    pts = rng.uniform(grid.origin - 0.02, grid.upper + 0.02, size=(7, 11, 3))
    d = grid.distance(pts)
    assert d.shape == (7, 11)
    np.testing.assert_array_equal(d, grid.distance_xyz(pts[..., 0], pts[..., 1], pts[..., 2]))
    assert np.shape(grid.distance(pts[0, 0])) == ()
    assert grid.distance(pts[0, 0]) == d[0, 0]


def test_grid_geometry(grids) -> None:
    for name, grid in grids.items():
        mesh, _ = MESHES[name]
        assert np.all(grid.origin <= mesh.bounds[0] - GRID_KWARGS["padding"] + 1e-12)
        assert np.all(grid.upper >= mesh.bounds[1] + GRID_KWARGS["padding"] - 1e-12)
        assert 0.001 <= grid.spacing <= 0.0025
        assert not grid.values.flags.writeable


# ------------------------------------------------------------------------------------------
# gradient and projection
# ------------------------------------------------------------------------------------------
def sphere_shell(seed: int, inner: float, outer: float, n: int = 20_000) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return u * (R_SPHERE + rng.uniform(inner, outer, size=(n, 1))), u


def angles_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(np.einsum("...i,...i->...", a, b), -1.0, 1.0)))


def test_gradient_is_unit_and_mostly_radial_on_the_sphere(grids) -> None:
    """Regression guard that passes today; the strict requirement is the xfail below."""
    grid = grids["sphere"]
    pts, radial = sphere_shell(15, -0.005, 0.005)
    g = grid.gradient(pts)
    np.testing.assert_allclose(np.linalg.norm(g, axis=-1), 1.0, atol=1e-12)
    ang = angles_deg(g, radial)
    assert np.median(ang) < 1.0
    assert np.percentile(ang, 95) < 5.0
    far, radial = sphere_shell(16, 0.003, 0.010)  # away from the nodes next to the surface
    assert angles_deg(grid.gradient(far), radial).max() < 5.0


def test_gradient_within_5_degrees_of_the_normal_near_the_sphere(grids) -> None:
    pts, radial = sphere_shell(15, -0.005, 0.005)
    ang = angles_deg(grids["sphere"].gradient(pts), radial)
    assert ang.max() < 5.0, f"max angle {ang.max():.1f} deg"


def grid_nodes(grid: SignedDistanceGrid) -> np.ndarray:
    axes = [grid.origin[a] + grid.spacing * np.arange(grid.shape[a]) for a in range(3)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)


def sphere_projection_queries(grid: SignedDistanceGrid) -> np.ndarray:
    """Random points 3 mm inside to 10 mm outside the sphere, and the grid nodes there."""
    nodes = grid_nodes(grid).reshape(-1, 3)
    d = sphere_sdf(nodes)
    return np.vstack([sphere_shell(17, -BAND_IN, BAND_OUT)[0], nodes[(d > -BAND_IN) & (d < BAND_OUT)]])


def test_closest_surface_point_on_the_sphere_regression_guard(grids) -> None:
    """Passes today; the strict 0.3 mm requirement is the xfail below."""
    pts = sphere_projection_queries(grids["sphere"])
    surface, normal = grids["sphere"].closest_surface_point(pts)
    err = np.abs(np.linalg.norm(surface, axis=-1) - R_SPHERE)
    assert np.percentile(err, 99) < 0.0002
    assert err.max() < 0.0008
    np.testing.assert_allclose(normal, grids["sphere"].gradient(pts), atol=0)


def test_closest_surface_point_within_0_3_mm_of_the_sphere(grids) -> None:
    pts = sphere_projection_queries(grids["sphere"])
    surface, _ = grids["sphere"].closest_surface_point(pts)
    err = np.abs(np.linalg.norm(surface, axis=-1) - R_SPHERE)
    assert err.max() < 0.0003, f"max {err.max() * 1e3:.3f} mm"


def test_node_values_next_to_a_smooth_surface(grids) -> None:
    """Pins the defect down at the nodes: the sphere grid's node values in the band."""
    grid = grids["sphere"]
    nodes = grid_nodes(grid)
    exact = sphere_sdf(nodes)
    band = (exact > -BAND_IN) & (exact < BAND_OUT)
    err = np.abs(grid.values - exact)[band]
    assert np.median(err) < 0.00005  # tangent-plane distances: nearly exact
    assert err.max() < 0.001


# ------------------------------------------------------------------------------------------
# determinism and cache
# ------------------------------------------------------------------------------------------
SMALL = {"padding": 0.02, "max_nodes": 20_000}  # coarse grids: cheap builds for these tests


def test_build_is_deterministic() -> None:
    mesh, _ = MESHES["box"]
    first, again = build_sdf_grid(mesh, **SMALL), build_sdf_grid(mesh, **SMALL)
    assert again.spacing == first.spacing
    np.testing.assert_array_equal(again.origin, first.origin)
    np.testing.assert_array_equal(again.values, first.values)
    # the seed of the surface sampling is the only source of randomness
    assert not np.array_equal(build_sdf_grid(mesh, seed=1, **SMALL).values, first.values)


def test_cache_returns_the_same_object_for_the_same_key(grids) -> None:
    mesh, _ = MESHES["sphere"]
    key = "test_sdf-cache-key-sphere"
    first = cached_sdf_grid(mesh, key, **GRID_KWARGS)
    assert cached_sdf_grid(mesh, key, **GRID_KWARGS) is first
    np.testing.assert_array_equal(first.values, grids["sphere"].values)  # == an uncached build
    # other options are another entry
    other = cached_sdf_grid(mesh, key, **SMALL)
    assert other is not first
    assert other.shape != first.shape
    assert cached_sdf_grid(mesh, key, **SMALL) is other
    assert cached_sdf_grid(mesh, key, **GRID_KWARGS) is first
    # the cache is bounded
    grid_cache = named_cache("sdf_grid")
    assert len(grid_cache) <= CACHE_LIMITS["sdf_grid"].entries
    assert grid_cache.stats().nbytes <= CACHE_LIMITS["sdf_grid"].nbytes


@pytest.fixture
def disk_cache(tmp_path, monkeypatch):
    """The disk caches in a fresh folder, the in-memory grids forgotten, and a count of the
    grids built (a spy on :func:`build_sdf_grid`)."""
    from grasp_apso import cache
    from grasp_apso.geometry import sdf

    built = []
    real = sdf.build_sdf_grid

    def spy(mesh, **kwargs):
        built.append(kwargs)
        return real(mesh, **kwargs)

    monkeypatch.setattr(sdf, "build_sdf_grid", spy)
    cache.set_cache_root(tmp_path)
    cache.clear_caches("sdf_grid")
    try:
        yield tmp_path / "sdf_grids", built
    finally:
        cache.set_cache_root(None)
        cache.clear_caches("sdf_grid")


def test_grids_are_read_back_from_disk_and_built_again_when_the_mesh_changes(disk_cache):
    """A new process (here: the in-memory cache forgotten) reads a mesh's grid back from the
    disk, bit for bit, instead of building it; another mesh under the same key, other
    options or an unreadable file build again."""
    from grasp_apso.cache import clear_caches

    folder, built = disk_cache
    mesh, _ = MESHES["sphere"]
    first = cached_sdf_grid(mesh, "a-key", **SMALL)
    assert len(built) == 1 and len(list(folder.glob("*.npz"))) == 1
    clear_caches("sdf_grid")
    again = cached_sdf_grid(mesh, "a-key", **SMALL)
    assert len(built) == 1  # read back, not built
    np.testing.assert_array_equal(again.values, first.values)
    np.testing.assert_array_equal(again.origin, first.origin)
    assert again.spacing == first.spacing
    assert not again.values.flags.writeable
    p = np.array([[0.0, 0.0, R_SPHERE + 0.003], [0.01, 0.0, 0.0]])
    np.testing.assert_array_equal(again.distance(p), first.distance(p))
    # the same key with another mesh (in a new process), and other options: built, each in
    # its own file
    clear_caches("sdf_grid")
    other = trimesh.creation.icosphere(subdivisions=3, radius=0.03)
    assert not np.allclose(cached_sdf_grid(other, "a-key", **SMALL).distance(p), first.distance(p))
    cached_sdf_grid(mesh, "a-key", **{**SMALL, "seed": 1})
    assert len(built) == 3 and len(list(folder.glob("*.npz"))) == 3
    # an unreadable file is built again and replaced
    clear_caches("sdf_grid")
    for path in folder.glob("*.npz"):
        path.write_bytes(b"not a zip")
    np.testing.assert_array_equal(cached_sdf_grid(mesh, "a-key", **SMALL).values, first.values)
    assert len(built) == 4


def test_the_disk_grids_keep_within_their_bytes_the_least_recently_used_removed_first(disk_cache, monkeypatch):
    """Past :data:`grasp_apso.cache.DISK_LIMITS`' bytes the folder loses its least recently
    used grids: reading a grid makes it recent, so the one not read since goes first."""
    import os

    from grasp_apso import cache

    folder, built = disk_cache
    mesh, _ = MESHES["sphere"]

    def new_file(**options):
        before = set(folder.glob("*.npz"))
        cached_sdf_grid(mesh, "k", **{**SMALL, **options})
        (path,) = set(folder.glob("*.npz")) - before
        return path

    first = new_file()
    monkeypatch.setitem(cache.DISK_LIMITS, "sdf_grids", int(2.5 * first.stat().st_size))  # two grids
    second = new_file(seed=1)
    # the order of use made unambiguous whatever the file system's time resolution
    os.utime(first, (1e9, 1e9))
    os.utime(second, (1e9 + 100, 1e9 + 100))
    cache.clear_caches("sdf_grid")
    cached_sdf_grid(mesh, "k", **SMALL)  # the first read back: now the most recent
    assert len(built) == 2 and first.stat().st_mtime > 1e9 + 100
    third = new_file(seed=2)
    assert len(built) == 3
    assert sorted(folder.glob("*.npz")) == sorted([first, third])  # the second, least recently used, went
    assert sum(q.stat().st_size for q in folder.glob("*.npz")) <= cache.DISK_LIMITS["sdf_grids"]
