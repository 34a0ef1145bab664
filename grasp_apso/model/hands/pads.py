"""The fingertip pad: where a finger's last link touches an object, and how round it is there.

Where closing the finger tells (:func:`.pad_probe.probe_pad`), the pad is where the tip
link first meets what it closes on (``at``); otherwise the geometric rule below.

:func:`find_pad` takes the collision geometry of the link (link frame) and two directions
of that frame: ``palmar`` (the side the finger closes toward) and ``distal`` (toward the
tip). The pad is the part of the surface farthest along ``palmar`` among the points in
the distal part of the link; its centre is the surface point nearest the middle of that
patch. The radius is the radius of curvature of the surface across the finger there (a
circle fitted to the cross-section), or, where the surface is flat across (a box), the
half-width of the flat face; clamped to a range that makes sense for a fingertip.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ...errors import HandDescriptionError, InputError
from .geometry import LinkGeometry
from .spheres import surface_samples, union_signed_distance

__all__ = ["find_pad", "outer_surface_samples", "PAD_RADIUS_RANGE"]

#: The pad radius is clamped to this range (m).
PAD_RADIUS_RANGE = (0.003, 0.015)
#: The distal part of the link: this fraction of its length along ``distal``.
_DISTAL_FRACTION = 0.35
#: Points within this of the farthest along ``palmar`` form the pad patch (m).
_PATCH_DEPTH = 5e-4
#: Surface samples per link (spacing 0.4 mm for a small fingertip, at most this many).
_SPACING = 4e-4
_MAX_SAMPLES = 30000
#: The cross-section for the curvature fit: slab half-thickness along ``distal`` (m) and
#: the largest lateral half-window (m); fewer points than this mean no fit.
_SLAB = 0.75e-3
_WINDOW = 6e-3
_MIN_FIT_POINTS = 12
#: The step along a sample's normal that must leave the link for the sample to be on its
#: outer surface (m).
_OUT_STEP = 5e-4
#: A fitted radius this many times the fitted half-window means flat across.
_FLAT_RATIO = 4.0


def _unit(value, name: str) -> np.ndarray:
    v = np.asarray(value, dtype=np.float64)
    if v.shape != (3,) or not np.all(np.isfinite(v)) or np.linalg.norm(v) < 1e-9:
        raise InputError(f"{name}: expected a finite non-zero (3,) direction, got {value!r}", field=name)
    return v / np.linalg.norm(v)


def outer_surface_samples(geoms: Sequence[LinkGeometry], spacing: float, rng: np.random.Generator,
                          max_count: int) -> tuple[np.ndarray, np.ndarray]:
    """Surface samples (points (N, 3), outward normals (N, 3), link frame) of the link's
    outer surface only: a sample is kept when a step :data:`_OUT_STEP` along its normal
    leaves the link. Parts inside another geometry, and the faces where a mesh's convex
    parts meet (a seam inside the solid), touch nothing."""
    points, normals = surface_samples(geoms, spacing, rng, max_count)
    outer = union_signed_distance(geoms, points + _OUT_STEP * normals) > 0.5 * _OUT_STEP
    if not outer.any():  # a union of solids always has an outer surface: the geometry is broken
        raise HandDescriptionError(f"collision: {geoms[0].where}: no point of its surface reads outside it "
                                   "(a mesh wound inside out or intersecting itself?)", field="collision")
    return points[outer], normals[outer]


def find_pad(geoms: Sequence[LinkGeometry], palmar, distal,
             rng: np.random.Generator | None = None, at=None) -> tuple[np.ndarray, float]:
    """The pad of a fingertip link.

    geoms : the link's collision geometries (link frame).
    palmar, distal : (3,) directions in the link frame (need not be unit; ``distal`` is
        made perpendicular to ``palmar``).
    rng : seeds the surface samples (default: a fixed seed).
    at : (3,) link frame, optional: the pad is the surface point nearest this (found by
        closing the finger, :mod:`.pad_probe`), its palmar side the surface's normal there.
    Returns (center (3,) m on the surface, link frame; radius m in ``PAD_RADIUS_RANGE``).
    """
    geoms = tuple(geoms)
    if not geoms or not all(isinstance(g, LinkGeometry) for g in geoms):
        raise InputError("geoms: expected one or more LinkGeometry", field="geoms")
    up = _unit(palmar, "palmar")
    along = _unit(distal, "distal")
    along = along - (along @ up) * up
    if np.linalg.norm(along) < 1e-6:
        raise InputError("distal: parallel to palmar", field="distal")
    along /= np.linalg.norm(along)
    across = np.cross(up, along)
    rng = np.random.default_rng(0) if rng is None else rng

    points, normals = outer_surface_samples(geoms, _SPACING, rng, _MAX_SAMPLES)
    if at is not None:
        center = points[np.argmin(np.linalg.norm(points - np.asarray(at, float), axis=1))]
        near = np.linalg.norm(points - center, axis=1) <= 2.0 * _SLAB
        up = normals[near].mean(axis=0)
        up /= np.linalg.norm(up)
        along = along - (along @ up) * up
        along = along / np.linalg.norm(along) if np.linalg.norm(along) > 1e-6 else np.cross(up, across)
        across = np.cross(up, along)
        patch = np.abs((points - center) @ up) <= _PATCH_DEPTH
        return center, _pad_radius(points, normals, center, up, along, across, patch)
    t = points @ along
    distal_part = t >= t.max() - _DISTAL_FRACTION * (t.max() - t.min())
    height = points @ up
    top = height[distal_part].max()
    patch = distal_part & (height >= top - _PATCH_DEPTH)
    middle = points[patch].mean(axis=0)
    center = points[patch][np.argmin(np.linalg.norm(points[patch] - middle, axis=1))]
    return center, _pad_radius(points, normals, center, up, along, across, patch)


def _pad_radius(points, normals, center, up, along, across, patch) -> float:
    """Radius of curvature across the finger at ``center`` (in the normal section through
    ``across``), or the flat face's half-width."""
    rel = points - center
    near = np.linalg.norm(rel, axis=1) <= 2.0 * _SLAB
    normal = normals[near].mean(axis=0) if near.any() else up
    normal /= np.linalg.norm(normal)
    across = across - (across @ normal) * normal
    across /= np.linalg.norm(across)
    u = rel @ across
    # The normal section: the plane through the pad spanned by its normal and ``across``.
    section_axis = np.cross(normal, across)
    slab = (np.abs(rel @ section_axis) <= _SLAB) & (normals @ normal > 0.2)
    # The flat patch's half-width across the finger at the pad.
    in_patch = patch & (np.abs(rel @ along) <= 2.0 * _SLAB)
    half_width = 0.5 * float(np.ptp(u[in_patch])) if in_patch.sum() > 1 else PAD_RADIUS_RANGE[0]
    window = slab & (np.abs(u) <= _WINDOW)
    radius = np.inf
    if window.sum() >= _MIN_FIT_POINTS:
        # A circle through the cross-section (algebraic fit: u^2 + h^2 + D u + E h + F = 0),
        # exact for the round cross-sections of capsules, cylinders and spheres.
        uu, hh = u[window], rel[window] @ normal
        design = np.stack([uu, hh, np.ones_like(uu)], axis=1)
        (d, e, f), *_ = np.linalg.lstsq(design, -(uu**2 + hh**2), rcond=None)
        r2 = 0.25 * (d * d + e * e) - f
        if r2 > 0 and -0.5 * e < 0:  # the centre below the pad: a convex surface
            radius = float(np.sqrt(r2))
        # Flat across the fitted window (a box face): the face's half-width bounds the contact.
        if radius > _FLAT_RATIO * np.abs(uu).max():
            radius = np.inf
    if not np.isfinite(radius):
        radius = half_width
    return float(np.clip(radius, *PAD_RADIUS_RANGE))
