"""Compiled distance from the palm box to the scene (support planes, boxes, spheres,
cylinders), swept from the pre-grasp to the grasp along the palm normal: one longer box.

Against a plane exact (the box's support); against a sphere exact; against a box or a
cylinder bounded from below by the largest gap between their projections over a set of
separating axes (the boxes' face normals, the pairwise cross products, the line between
the centres), after bounding spheres have culled far obstacles. Arrays follow
:meth:`grasp_apso.model.scene.Scene.packed`; the kernel releases the GIL and is cached on
disk, as :mod:`grasp_apso.geometry.scene_kernels`.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from . import convex_distance
from .scene_kernels import _inv_center

_jit = numba.njit(cache=True, nogil=True)


@_jit
def _box_projection(ax, half, ux, uy, uz):
    """Half length of a box (axes = columns of ``ax``) projected on u."""
    return (half[0] * abs(ax[0, 0] * ux + ax[1, 0] * uy + ax[2, 0] * uz)
            + half[1] * abs(ax[0, 1] * ux + ax[1, 1] * uy + ax[2, 1] * uz)
            + half[2] * abs(ax[0, 2] * ux + ax[1, 2] * uy + ax[2, 2] * uz))


@_jit
def _separation(pa, pc, half, axes_b, cb, kind, hb, rb, hh, ux, uy, uz):
    """Gap along u (normalised here) between the palm box and a box (kind 0, half
    sizes ``hb``) or a cylinder (kind 1, radius rb, half height hh, axis = axes_b[:, 2])."""
    norm = math.sqrt(ux * ux + uy * uy + uz * uz)
    if norm < 1e-9:
        return -np.inf
    ux /= norm
    uy /= norm
    uz /= norm
    span = abs((cb[0] - pc[0]) * ux + (cb[1] - pc[1]) * uy + (cb[2] - pc[2]) * uz)
    reach = _box_projection(pa, half, ux, uy, uz)
    if kind == 0:
        reach += _box_projection(axes_b, hb, ux, uy, uz)
    else:
        c = axes_b[0, 2] * ux + axes_b[1, 2] * uy + axes_b[2, 2] * uz
        reach += hh * abs(c) + rb * math.sqrt(max(0.0, 1.0 - c * c))
    return span - reach


@_jit
def palm_scene_gaps(rot, trans, center, half_extents, approach_distance, horizon,
                    planes, box_inv, box_half, sphere_center, sphere_radius,
                    cyl_inv, cyl_radius, cyl_half, out):
    """Least scene gap (m, at most ``horizon``) of the palm box swept from the
    pre-grasp to the grasp (one box longer by ``approach_distance`` along the palm
    normal), per particle.

    rot (P, 3, 3), trans (P, 3) : palm frame in the object frame
    center, half_extents : (3,) m -- the palm box in the palm frame
    out : (P,) m (written)
    """
    half = np.empty(3)
    pc = np.empty(3)
    cb = np.empty(3)
    hb = np.empty(3)
    axes_b = np.empty((3, 3))
    half[0] = half_extents[0]
    half[1] = half_extents[1]
    half[2] = half_extents[2] + 0.5 * approach_distance
    n_box = box_inv.shape[0]
    for p in range(rot.shape[0]):
        pa = rot[p]
        for i in range(3):
            pc[i] = (trans[p, i] + pa[i, 0] * center[0] + pa[i, 1] * center[1] + pa[i, 2] * center[2]
                     - 0.5 * approach_distance * pa[i, 2])
        best = horizon
        for k in range(planes.shape[0]):
            g = (planes[k, 0] * pc[0] + planes[k, 1] * pc[1] + planes[k, 2] * pc[2] + planes[k, 3]
                 - _box_projection(pa, half, planes[k, 0], planes[k, 1], planes[k, 2]))
            best = min(best, g)
        palm_reach = math.sqrt(half[0] ** 2 + half[1] ** 2 + half[2] ** 2)
        for k in range(sphere_center.shape[0]):
            dx = sphere_center[k, 0] - pc[0]
            dy = sphere_center[k, 1] - pc[1]
            dz = sphere_center[k, 2] - pc[2]
            out2 = 0.0
            inside = -np.inf
            for a in range(3):
                local = pa[0, a] * dx + pa[1, a] * dy + pa[2, a] * dz
                qa = abs(local) - half[a]
                inside = max(inside, qa)
                if qa > 0.0:
                    out2 += qa * qa
            best = min(best, math.sqrt(out2) + min(inside, 0.0) - sphere_radius[k])
        for k in range(n_box + cyl_inv.shape[0]):
            if k < n_box:
                inv = box_inv[k]
                kind = 0
                hb[0], hb[1], hb[2] = box_half[k, 0], box_half[k, 1], box_half[k, 2]
                rb = 0.0
                hh = 0.0
                reach = math.sqrt(hb[0] ** 2 + hb[1] ** 2 + hb[2] ** 2)
            else:
                c = k - n_box
                inv = cyl_inv[c]
                kind = 1
                rb = cyl_radius[c]
                hh = cyl_half[c]
                reach = math.sqrt(rb * rb + hh * hh)
            cb[0], cb[1], cb[2] = _inv_center(inv)
            for a in range(3):  # axes of the obstacle = rows of its inverse rotation
                for i in range(3):
                    axes_b[i, a] = inv[a, i]
            dist_c = math.sqrt((cb[0] - pc[0]) ** 2 + (cb[1] - pc[1]) ** 2 + (cb[2] - pc[2]) ** 2)
            if dist_c - reach - palm_reach >= best:
                continue
            # the palm's bounding sphere against the obstacle itself (a large wall's own
            # bounding sphere culls nothing)
            if convex_distance.convex_value_slope(kind == 0, inv, hb[0], hb[1], hb[2], rb, hh, pc[0], pc[1], pc[2],
                                   0.0, 0.0, 0.0)[0] - palm_reach >= best:
                continue
            gap = _separation(pa, pc, half, axes_b, cb, kind, hb, rb, hh,
                              cb[0] - pc[0], cb[1] - pc[1], cb[2] - pc[2])
            for a in range(3):
                gap = max(gap, _separation(pa, pc, half, axes_b, cb, kind, hb, rb, hh,
                                           pa[0, a], pa[1, a], pa[2, a]))
                gap = max(gap, _separation(pa, pc, half, axes_b, cb, kind, hb, rb, hh,
                                           axes_b[0, a], axes_b[1, a], axes_b[2, a]))
                for b in range(3):
                    if kind == 1 and b != 2:
                        continue
                    ux = pa[1, a] * axes_b[2, b] - pa[2, a] * axes_b[1, b]
                    uy = pa[2, a] * axes_b[0, b] - pa[0, a] * axes_b[2, b]
                    uz = pa[0, a] * axes_b[1, b] - pa[1, a] * axes_b[0, b]
                    gap = max(gap, _separation(pa, pc, half, axes_b, cb, kind, hb, rb, hh, ux, uy, uz))
            best = min(best, gap)
        out[p] = best
