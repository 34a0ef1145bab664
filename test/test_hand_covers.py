"""Every link of a hand covered by its spheres (issue 20, deliver 2), checked independently
of the cover's own measures: surface samples of the exact geometry (trimesh) must lie inside
some sphere, and points spread over the spheres must lie at most 2 mm outside the exact
geometry (trimesh's signed distance). CI covers the Allegro-like URDF hand (boxes, cylinders
and meshes) and the Shadow hand (MJCF capsules and meshes); ``-m slow`` every test hand.
Covers are built once per machine (kept on disk): the tests use a folder of their own so
that they build them. The probed pads are kept on disk the same way (the last test)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from grasp_apso.cache import cache_root, clear_caches
from grasp_apso.model.hands.load import load_hand
from grasp_apso.model.hands.spheres import MAX_STRAY
from hand_files import HANDS, installed_hand, write_allegro_like

#: Judge tolerance: a sample counts as inside when it is within 0.05 mm of a sphere
#: (trimesh tessellates primitives, so its surface points lie slightly off the exact one).
INSIDE = 5e-5


@pytest.fixture(scope="module")
def cover_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("covers")


def _load(name, tmp_path_factory, cover_dir, monkeypatch_module):
    path = write_allegro_like(tmp_path_factory.mktemp("allegro")) if name == "allegro_like" else installed_hand(name)
    return load_hand(path)


def _check_hand(hand, rng) -> None:
    for link, cover in hand.spheres.items():
        mesh = trimesh.util.concatenate([g.to_trimesh() for g in hand.collision[link]])
        surface = mesh.sample(3000, seed=int(rng.integers(1 << 30)))
        # capsules too: the distance to each element's segment
        a, b, r = cover.centers, cover.ends, cover.radii
        ab = b - a
        t = np.clip(np.einsum("nkj,kj->nk", surface[:, None] - a[None], ab) / np.maximum(
            np.einsum("kj,kj->k", ab, ab), 1e-18), 0.0, 1.0)
        gap = np.linalg.norm(surface[:, None] - (a[None] + t[..., None] * ab[None]), axis=2) - r[None]
        missed = np.mean(gap.min(axis=1) > INSIDE)
        assert missed <= 0.005, f"{hand.name} {link}: {missed:.2%} of the surface outside every sphere"
        # stray: 12 points on each of up to 60 elements, trimesh's signed distance (+ inside)
        pick = rng.choice(len(r), size=min(60, len(r)), replace=False)
        dirs = rng.normal(size=(12, 3))
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        pts = (a[pick][:, None] + r[pick][:, None, None] * dirs[None]).reshape(-1, 3)
        # the union of the link's geometries: outside by the least of the distances
        outside = np.min([-trimesh.proximity.signed_distance(g.to_trimesh(), pts) for g in hand.collision[link]],
                         axis=0)
        assert outside.max() <= MAX_STRAY + 1e-4, f"{hand.name} {link}: a sphere strays {outside.max() * 1000:.2f} mm"


@pytest.mark.parametrize("name", ["allegro_like", "shadow"])
def test_every_link_is_covered_and_no_sphere_strays_over_2mm(name, tmp_path_factory, monkeypatch):
    monkeypatch.setenv("GRASP_APSO_CACHE", str(tmp_path_factory.mktemp("covers")))
    clear_caches()
    hand = _load(name, tmp_path_factory, None, None)
    _check_hand(hand, np.random.default_rng(2020))


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(set(HANDS) - {"shadow"}))
def test_every_link_of_every_test_hand_is_covered(name, tmp_path_factory):
    hand = _load(name, tmp_path_factory, None, None)
    _check_hand(hand, np.random.default_rng(2021))


def test_covers_are_read_back_from_disk(tmp_path_factory, monkeypatch):
    """A second load (a restarted node) reads the covers the first one wrote."""
    monkeypatch.setenv("GRASP_APSO_CACHE", str(tmp_path_factory.mktemp("covers")))
    folder = tmp_path_factory.mktemp("allegro_disk")
    clear_caches()
    first = load_hand(write_allegro_like(folder))
    stored = list((tmp_path_factory.getbasetemp()).rglob("hand_covers/*.npz"))
    assert stored, "no cover written to disk"
    clear_caches()
    second = load_hand(write_allegro_like(folder))
    assert second is not first
    for link, cover in first.spheres.items():
        assert np.array_equal(cover.centers, second.spheres[link].centers)
        assert np.array_equal(cover.radii, second.spheres[link].radii)
        assert cover.uncovered == second.spheres[link].uncovered


def test_pads_are_read_back_from_disk_and_probed_again_when_the_hand_changes(tmp_path_factory, monkeypatch):
    """A hand's probed pads (``pad_probe``) are kept on disk: a second load (a new process, a
    command-line run) reads the same pads without probing; a hand whose fingertip geometry
    differs is probed again. The probe is spied on, not replaced."""
    from grasp_apso.model.hands import pad_probe

    monkeypatch.setenv("GRASP_APSO_CACHE", str(tmp_path_factory.mktemp("pads")))
    probed = []
    probe = pad_probe._probe

    def spying(hand, links, tip_link, poses, normal):
        probed.append(tip_link)
        return probe(hand, links, tip_link, poses, normal)

    monkeypatch.setattr(pad_probe, "_probe", spying)
    clear_caches()
    first = load_hand(installed_hand("shadow"))
    # every finger probed (this hand's fingers are derived twice: again with its tendons'
    # couplings moved to the edge of their play, which moves four fingers' closing)
    assert set(probed) == {f.tip_link for f in first.fingers} and len(first.fingers) == 5
    assert len(list(cache_root().glob("hand_pads/*.npz"))) == len(probed)
    clear_caches()
    probed.clear()
    second = load_hand(installed_hand("shadow"))
    assert second is not first and probed == []  # read back, not probed
    for a, b in zip(first.fingers, second.fingers):
        assert (a.pad_link, a.pad_radius) == (b.pad_link, b.pad_radius)
        np.testing.assert_array_equal(a.pad_center, b.pad_center)
    # Another hand (the Allegro-like's boxes and cylinders) is probed, under its own keys.
    clear_caches()
    load_hand(write_allegro_like(tmp_path_factory.mktemp("allegro_pads")))
    assert probed, "another hand's pads were read from the Shadow's entries"
