"""Spheres that cover a link's collision geometry for the compiled search.

The search tests thousands of hand poses per plan, so each link stands for its exact
collision geometry (:class:`.geometry.LinkGeometry`, checked exactly with python-fcl at the
end) by a few spheres that

- cover it: every point of its surface lies inside at least one sphere, and
- stray at most ``tolerance`` outside it.

A sphere centred at ``c`` inside the geometry, at depth ``depth(c)`` below its surface,
with radius ``depth(c) + tolerance`` strays at most ``tolerance`` (the signed distance is
1-Lipschitz). :func:`cover_link` draws candidate centres inside the geometry (surface
samples moved inward along their normals by several depths, and a grid filtered by
depth), gives each that radius (less a small margin for the tessellation the checks
measure against), and picks a small set covering all surface samples by greedy set cover.
Surface samples count as covered only with a margin inside the sphere, so the surface
between samples is covered too; a denser independent sample then checks the cover, and
the points it finds uncovered (there should be none) join the samples for another round.

A box needs many spheres with a 2 mm stray: its edges and corners are covered only by
spheres centred within a few millimetres of them (a 20 x 27 x 54 mm box: see the numbers
in the tests' docstring and the README).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import trimesh
from scipy import sparse

from ...errors import InputError
from .capsules import capsule_candidates, principal_axes
from .cover_kernels import covered_pairs
from .geometry import LinkGeometry

__all__ = ["SphereCover", "cover_link", "union_signed_distance", "surface_samples", "MAX_STRAY",
           "MAX_SPHERES"]

#: The stray allowed by DESIGN.md Part 3 (m): the spheres' surface outside the geometry.
MAX_STRAY = 0.002
#: Spheres per link at most (the compiled search's budget); beyond it the cover stops and
#: reports the fraction left uncovered.
MAX_SPHERES = 256
#: Radius kept below depth + tolerance (m): checks measure the stray against tessellated
#: primitives (up to 0.12 % of the radius inside the true surface) with trimesh's
#: approximate closest points (up to 0.08 mm too far on a capsule).
_STRAY_MARGIN = 1e-4
#: Surface samples for the cover: spacing as a fraction of the tolerance, and at most so many.
_SPACING = 0.5
_MAX_SAMPLES = 5000
#: A sample counts as covered when it lies this fraction of the spacing inside a sphere.
_COVER_MARGIN = 0.3
#: Inward offsets of the candidate centres along the normals, in tolerances (besides the
#: medial axis), the most samples that seed candidates, the most grid candidates, every
#: how many seeds one is moved to the medial axis, and the bisection steps that find it.
_OFFSETS = (0.125, 0.5, 1.0, 1.5, 2.5)
_MAX_SEEDS = 1200
_MAX_GRID = 600
_MEDIAL_STRIDE = 2
_MEDIAL_STEPS = 9
#: The checking sample: this many times denser than the cover's, rounds of repair.
_CHECK_FACTOR = 6
_REPAIR_ROUNDS = 6
#: The margin (in tolerances) by which a missed point must lie inside its new sphere.
_REPAIR_MARGIN = 0.25
#: How far inside a sphere (in tolerances) a checking point must lie to count as covered.
_CHECK_MARGIN = 0.05
#: Points per sphere for the measured stray.
_STRAY_POINTS = 64


@dataclass(frozen=True, eq=False)
class SphereCover:
    """Spheres covering one link's collision geometry (immutable).

    Attributes
    ----------
    centers : (k, 3) float, m, link frame
    radii : (k,) float, m
    max_stray : float, m
        The largest distance a point of a sphere's surface lies outside the exact
        geometry, measured on points spread over every sphere (<= ``tolerance``).
    uncovered : float
        Fraction of an independent dense surface sample inside no sphere (0 when the
        cover is complete).
    tolerance : float, m
        The stray allowed when the cover was built.
    ends : (k, 3) float, m, link frame
        Element i is the capsule from ``centers[i]`` to ``ends[i]`` of radius ``radii[i]``;
        a sphere where the two are equal. Default (and always unless ``cover_link`` was
        asked for capsules): equal to ``centers``, all spheres.
    """

    centers: np.ndarray
    radii: np.ndarray
    max_stray: float
    uncovered: float
    tolerance: float
    ends: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.ends is None:
            object.__setattr__(self, "ends", self.centers)
        for name in ("centers", "radii", "ends"):
            value = np.array(getattr(self, name), dtype=np.float64)
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def count(self) -> int:
        """The number of elements (spheres and capsules)."""
        return int(len(self.radii))

    @property
    def is_capsule(self) -> np.ndarray:
        """(k,) bool: which elements are capsules (their two ends differ)."""
        return np.any(self.centers != self.ends, axis=1)

    def contains(self, points: np.ndarray) -> np.ndarray:
        """Whether each point lies inside at least one sphere (or capsule).

        points : (N, 3) float, m, link frame -> (N,) bool
        """
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        hits = _coverage(self.centers, self.ends, self.radii, pts, 0.0)
        return np.asarray(hits.sum(axis=0)).ravel() > 0


def union_signed_distance(geoms: Sequence[LinkGeometry], points: np.ndarray) -> np.ndarray:
    """Signed distance to the union of the geometries (> 0 outside).

    Exact outside; inside, the deepest single geometry's depth (a lower bound of the
    union's depth where geometries overlap, which keeps spheres inside).
    points : (N, 3) float, m, link frame -> (N,) float, m
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    out = np.full(len(pts), np.inf)
    for geom in geoms:
        np.minimum(out, geom.signed_distance(pts), out=out)
    return out


def surface_samples(geoms: Sequence[LinkGeometry], spacing: float, rng: np.random.Generator,
                    max_count: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Area-weighted random samples of every geometry's surface and their outward normals.

    About one sample per ``spacing`` squared of area (at most ``max_count`` in all, at
    least 50 per geometry).
    Returns (points (N, 3), normals (N, 3)), link frame.
    """
    meshes = [g.to_trimesh() for g in geoms]
    areas = np.array([m.area for m in meshes])
    counts = areas / spacing**2
    if max_count is not None and counts.sum() > max_count:
        counts *= max_count / counts.sum()
    points, normals = [], []
    for mesh, count in zip(meshes, counts):
        p, face = trimesh.sample.sample_surface(mesh, max(50, int(count)), seed=rng)
        points.append(np.asarray(p))
        normals.append(np.asarray(mesh.face_normals)[face])
    return np.vstack(points), np.vstack(normals)


def _medial_offsets(geoms: Sequence[LinkGeometry], seeds: np.ndarray, inward: np.ndarray,
                    reach: float) -> np.ndarray:
    """Per seed, the inward offset k (m) of the largest inscribed ball touching the seed:
    the largest k with depth(seed + k inward) ~ k (bisection: k - depth grows with k)."""
    lo = np.zeros(len(seeds))
    hi = np.full(len(seeds), reach)
    slack = 0.02 * reach
    for _ in range(_MEDIAL_STEPS):
        mid = 0.5 * (lo + hi)
        depth = -union_signed_distance(geoms, seeds + mid[:, None] * inward)
        ok = depth >= mid - slack
        lo = np.where(ok, mid, lo)
        hi = np.where(ok, hi, mid)
    return lo


def _candidates(geoms: Sequence[LinkGeometry], points: np.ndarray, normals: np.ndarray,
                tolerance: float, max_seeds: int = _MAX_SEEDS, grid: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Candidate centres inside the geometry and their radii (depth + tolerance - margin):
    seeds moved inward by a few shallow offsets (edges, corners) and to the medial axis
    (flat and thick parts), and a grid over the bounding box."""
    lo = np.min([g.bounds[0] for g in geoms], axis=0)
    hi = np.max([g.bounds[1] for g in geoms], axis=0)
    stride = max(1, int(np.ceil(len(points) / max_seeds)))
    seeds, inward = points[::stride], -normals[::stride]
    moved = [seeds + (tolerance * f) * inward for f in _OFFSETS]
    # Deep centres cover much each, so fewer of them do (and keep the coverage matrix small).
    deep, deep_in = seeds[::_MEDIAL_STRIDE], inward[::_MEDIAL_STRIDE]
    medial = _medial_offsets(geoms, deep, deep_in, 0.5 * float((hi - lo).max()))
    moved.append(deep + medial[:, None] * deep_in)
    if grid:
        volume = float(np.prod(np.maximum(hi - lo, 1e-9)))
        step = max(tolerance, (volume / _MAX_GRID) ** (1.0 / 3.0))
        axes = [np.arange(a + 0.5 * step, b, step) if b - a > step else np.array([0.5 * (a + b)])
                for a, b in zip(lo, hi)]
        moved.append(np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3))
    centers = np.vstack(moved)
    depth = -union_signed_distance(geoms, centers)
    keep = depth >= 0.0
    return centers[keep], depth[keep] + tolerance - _STRAY_MARGIN


def _coverage(a: np.ndarray, b: np.ndarray, radii: np.ndarray, points: np.ndarray,
              margin: float) -> sparse.csr_matrix:
    """(M, S) sparse: sample s lies at least ``margin`` inside element m (the capsule from
    a[m] to b[m] of radius radii[m]; a sphere when a[m] == b[m])."""
    reach = np.maximum(radii - margin, 0.0)
    cell = float(np.median(reach)) if len(reach) else 1.0
    rows, cols = covered_pairs(a, b, reach, points, cell)
    data = np.ones(len(rows), dtype=np.int32)
    return sparse.csr_matrix((data, (rows, cols)), shape=(len(a), len(points)))


def _greedy(cover: sparse.csr_matrix, chosen: list[int], limit: int) -> np.ndarray:
    """Greedy set cover: extend ``chosen`` (rows of ``cover``) until every coverable column
    is covered or ``limit`` rows are chosen. Returns the uncovered columns (bool)."""
    by_sample = cover.tocsc()
    uncovered = np.ones(cover.shape[1], dtype=bool)
    for row in chosen:
        uncovered[cover.indices[cover.indptr[row]:cover.indptr[row + 1]]] = False
    gains = np.asarray(cover[:, uncovered].sum(axis=1)).ravel()
    while len(chosen) < limit and uncovered.any():
        best = int(np.argmax(gains))
        if gains[best] <= 0:
            break
        cols = cover.indices[cover.indptr[best]:cover.indptr[best + 1]]
        newly = cols[uncovered[cols]]
        uncovered[newly] = False
        rows = np.concatenate([by_sample.indices[by_sample.indptr[c]:by_sample.indptr[c + 1]] for c in newly])
        gains -= np.bincount(rows, minlength=len(gains))
        chosen.append(best)
    return uncovered


def _fibonacci_sphere(count: int) -> np.ndarray:
    """(count, 3) unit vectors spread evenly over the sphere."""
    i = np.arange(count) + 0.5
    z = 1.0 - 2.0 * i / count
    phi = np.pi * (1.0 + 5.0**0.5) * i
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def measure_stray(geoms: Sequence[LinkGeometry], centers: np.ndarray, radii: np.ndarray,
                  rng: np.random.Generator, points_per_sphere: int = _STRAY_POINTS,
                  ends: np.ndarray | None = None) -> float:
    """The largest distance of a point on a sphere's (or capsule's) surface outside the
    geometry (m, >= 0), on ``points_per_sphere`` points per sphere turned by a random
    rotation (a capsule: that many at each of 9 stations along its segment)."""
    if len(radii) == 0:
        return 0.0
    ends = centers if ends is None else ends
    unit = _fibonacci_sphere(points_per_sphere)
    unit = unit @ trimesh.transformations.random_rotation_matrix(rng.random(3))[:3, :3].T
    stations = np.linspace(0.0, 1.0, 9)
    worst = 0.0
    for is_capsule in (False, True):
        pick = np.any(centers != ends, axis=1) == is_capsule
        if not pick.any():
            continue
        t = stations if is_capsule else stations[:1]
        axis_pts = centers[pick, None, :] + t[None, :, None] * (ends[pick] - centers[pick])[:, None, :]
        pts = axis_pts[:, :, None, :] + radii[pick, None, None, None] * unit[None, None]
        worst = max(worst, float(union_signed_distance(geoms, pts.reshape(-1, 3)).max()))
    return worst


def _check(geoms, tolerance, rng, max_spheres) -> tuple[Sequence[LinkGeometry], float, np.random.Generator, int]:
    geoms = tuple(geoms)
    if not geoms or not all(isinstance(g, LinkGeometry) for g in geoms):
        raise InputError("geoms: expected one or more LinkGeometry", field="geoms")
    if not (isinstance(tolerance, (int, float)) and np.isfinite(tolerance) and 0.0 < tolerance <= 0.05):
        raise InputError(f"tolerance: expected a stray in (0, 0.05] m, got {tolerance!r}", field="tolerance")
    if rng is None:
        rng = np.random.default_rng(0)
    elif not isinstance(rng, np.random.Generator):
        raise InputError("rng: expected a numpy.random.Generator or None", field="rng")
    if isinstance(max_spheres, bool) or not isinstance(max_spheres, (int, np.integer)) or max_spheres < 1:
        raise InputError(f"max_spheres: expected a positive integer, got {max_spheres!r}", field="max_spheres")
    return geoms, float(tolerance), rng, int(max_spheres)


def cover_link(geoms: Sequence[LinkGeometry], tolerance: float = MAX_STRAY,
               rng: np.random.Generator | None = None, max_spheres: int = MAX_SPHERES,
               capsules: bool = False) -> SphereCover:
    """Few spheres covering the surface of ``geoms`` (one link), straying <= ``tolerance``.

    geoms : the link's collision geometries (link frame); their union is covered (the
        parts of one surface inside another geometry too: a check that samples each
        geometry's surface finds them covered).
    tolerance : m, the largest stray allowed.
    rng : seeds the samples (default: a fixed seed); same inputs and seed, same spheres.
    max_spheres : the cover stops there and reports the fraction left ``uncovered``.
    capsules : also offer capsules to the set cover (``SphereCover.ends`` then differ
        from ``centers`` for them): a box takes ~20 elements instead of ~180.
    """
    geoms, tolerance, rng, max_spheres = _check(geoms, tolerance, rng, max_spheres)
    spacing = _SPACING * tolerance
    points, normals = surface_samples(geoms, spacing, rng, _MAX_SAMPLES)
    area = sum(g.to_trimesh().area for g in geoms)
    spacing = max(spacing, float(np.sqrt(area / len(points))))
    centers, radii = _candidates(geoms, points, normals, tolerance)
    ends = centers
    if capsules:
        lo = np.min([g.bounds[0] for g in geoms], axis=0)
        hi = np.max([g.bounds[1] for g in geoms], axis=0)
        depth_of = lambda p: -union_signed_distance(geoms, p)  # noqa: E731
        cap_a, cap_b, cap_r = capsule_candidates(depth_of, centers, radii - tolerance + _STRAY_MARGIN,
                                                 principal_axes(geoms, points), float(np.linalg.norm(hi - lo)),
                                                 tolerance, _STRAY_MARGIN, rng)
        centers, ends = np.vstack([centers, cap_a]), np.vstack([centers, cap_b])
        radii = np.concatenate([radii, cap_r])
    margins = [_COVER_MARGIN * spacing]
    groups = [points]
    chosen: list[int] = []
    for _ in range(_REPAIR_ROUNDS):
        cover = sparse.hstack([_coverage(centers, ends, radii, g, m) for g, m in zip(groups, margins)],
                              format="csr")
        _greedy(cover, chosen, max_spheres)
        # A fresh, denser sample checks the cover; it is independent of the spheres chosen.
        check, check_normals = surface_samples(geoms, spacing / np.sqrt(_CHECK_FACTOR), rng,
                                               _CHECK_FACTOR * _MAX_SAMPLES)
        # Points less than _CHECK_MARGIN inside every sphere count as missed: slivers are
        # thin, their neighbourhoods are not, so a check this strict finds every one.
        inside = SphereCover(centers[chosen], radii[chosen] - _CHECK_MARGIN * tolerance, 0.0, 0.0,
                             tolerance, ends[chosen]).contains(check)
        if inside.all() or len(chosen) >= max_spheres:
            break
        # The missed points (slivers between spheres) join the samples with a wide margin,
        # which closes the sliver around each; their inward offsets join the candidates.
        missed, missed_normals = check[~inside], check_normals[~inside]
        extra_c, extra_r = _candidates(geoms, missed, missed_normals, tolerance, grid=False)
        centers, ends = np.vstack([centers, extra_c]), np.vstack([ends, extra_c])
        radii = np.concatenate([radii, extra_r])
        groups.append(missed)
        margins.append(_REPAIR_MARGIN * tolerance)
    centers, ends, radii = centers[chosen], ends[chosen], radii[chosen]
    check, _ = surface_samples(geoms, spacing / np.sqrt(_CHECK_FACTOR), rng, _CHECK_FACTOR * _MAX_SAMPLES)
    uncovered = float(1.0 - SphereCover(centers, radii, 0.0, 0.0, tolerance, ends).contains(check).mean())
    stray = measure_stray(geoms, centers, radii, rng, ends=ends)
    return SphereCover(centers, radii, stray, uncovered, tolerance, ends)
