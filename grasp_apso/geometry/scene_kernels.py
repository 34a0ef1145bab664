"""Compiled distances from the hand to the scene (support planes, boxes, spheres,
cylinders), batched over particles: the decoder's hot-path scene check.

The hand is its palm box and the link spheres of each finger (the decoder's final
points: spheres every ~4 mm along the link capsules, the last one the fingertip pad).
Two postures are checked for every particle:

- the *grasp*: the palm and the closed fingers at the wrist pose;
- the *approach*: the open pre-shape (the particle's finger values) moved along the
  straight path from the pre-grasp (the wrist retreated ``approach_distance`` along
  minus the palm normal) to the grasp wrist pose.

Exact where cheap, conservative (the distance is never over-estimated) elsewhere:

- planes: a sphere's or a box's distance to a half-space is linear along the path, so
  the path's least distance is at one of its ends (exact);
- spheres: the distance from a sphere's centre to the path segment (exact);
- boxes and cylinders: finger spheres are sampled along the path every ``step`` m (at
  most 5 mm), and the gap a swept sphere may reach between two samples,
  ``r - sqrt(r^2 - (step / 2)^2)``, is subtracted. The palm swept along its own normal
  is one longer box; its distance to a box or a cylinder is bounded from below by the
  largest gap between their projections over a set of separating axes (the boxes' face
  normals, the pairwise cross products, the line between the centres);
- a finger or a palm whose bounding sphere, swept along the path, stays farther than
  ``horizon`` from an obstacle's bounding sphere skips that obstacle (reads ``horizon``).

Arrays follow :meth:`grasp_apso.model.scene.Scene.packed` (object frame, float64,
C-contiguous). The kernels release the GIL and are cached on disk, as
:mod:`grasp_apso.geometry.kernels`.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .kernels import N_FINGERS, _grid_distance, _segments, _world_plane

_jit = numba.njit(cache=True, nogil=True)


@_jit
def _box_point(inv, half, x, y, z):
    """Signed distance (m) of a point to a box (``inv`` world -> box, half sizes)."""
    lx = inv[0, 0] * x + inv[0, 1] * y + inv[0, 2] * z + inv[0, 3]
    ly = inv[1, 0] * x + inv[1, 1] * y + inv[1, 2] * z + inv[1, 3]
    lz = inv[2, 0] * x + inv[2, 1] * y + inv[2, 2] * z + inv[2, 3]
    qx = abs(lx) - half[0]
    qy = abs(ly) - half[1]
    qz = abs(lz) - half[2]
    ox, oy, oz = max(qx, 0.0), max(qy, 0.0), max(qz, 0.0)
    return math.sqrt(ox * ox + oy * oy + oz * oz) + min(max(qx, max(qy, qz)), 0.0)


@_jit
def _cylinder_point(inv, radius, half_height, x, y, z):
    """Signed distance (m) of a point to a cylinder (axis = local z)."""
    lx = inv[0, 0] * x + inv[0, 1] * y + inv[0, 2] * z + inv[0, 3]
    ly = inv[1, 0] * x + inv[1, 1] * y + inv[1, 2] * z + inv[1, 3]
    lz = inv[2, 0] * x + inv[2, 1] * y + inv[2, 2] * z + inv[2, 3]
    qr = math.sqrt(lx * lx + ly * ly) - radius
    qz = abs(lz) - half_height
    ox, oz = max(qr, 0.0), max(qz, 0.0)
    return math.sqrt(ox * ox + oz * oz) + min(max(qr, qz), 0.0)


@_jit
def _point_segment(px, py, pz, ax, ay, az, dx, dy, dz, length2):
    """Distance from a point to the segment a + s d, s in [0, 1]."""
    s = 0.0
    if length2 > 1e-18:
        s = ((px - ax) * dx + (py - ay) * dy + (pz - az) * dz) / length2
        s = min(max(s, 0.0), 1.0)
    ex = px - ax - s * dx
    ey = py - ay - s * dy
    ez = pz - az - s * dz
    return math.sqrt(ex * ex + ey * ey + ez * ez)


@_jit
def _inv_center(inv, out):
    """Centre (world) of a primitive from its world -> local transform."""
    for i in range(3):
        out[i] = -(inv[0, i] * inv[0, 3] + inv[1, i] * inv[1, 3] + inv[2, i] * inv[2, 3])


@_jit
def _spheres_path_gap(q, radii, count, zx, zy, zz, length, n_steps, horizon,
                      planes, box_inv, box_half, sphere_center, sphere_radius,
                      cyl_inv, cyl_radius, cyl_half):
    """Least gap (m) of spheres q[:count] (centres, object frame), radii, moved from
    q to q - length * z (``length`` 0: the spheres at q only), to the scene; at most
    ``horizon``."""
    best = horizon
    # bounding sphere of the set, for culling the obstacles
    cx = 0.0
    cy = 0.0
    cz = 0.0
    for m in range(count):
        cx += q[m, 0]
        cy += q[m, 1]
        cz += q[m, 2]
    cx /= count
    cy /= count
    cz /= count
    bound = 0.0
    rmax = 0.0
    for m in range(count):
        d = math.sqrt((q[m, 0] - cx) ** 2 + (q[m, 1] - cy) ** 2 + (q[m, 2] - cz) ** 2) + radii[m]
        bound = max(bound, d)
        rmax = max(rmax, radii[m])
    dx, dy, dz = -length * zx, -length * zy, -length * zz
    length2 = length * length
    # planes: linear along the path, least at an end
    for k in range(planes.shape[0]):
        nx, ny, nz, d0 = planes[k, 0], planes[k, 1], planes[k, 2], planes[k, 3]
        shift = min(0.0, nx * dx + ny * dy + nz * dz)
        for m in range(count):
            g = nx * q[m, 0] + ny * q[m, 1] + nz * q[m, 2] + d0 + shift - radii[m]
            if g < best:
                best = g
    # spheres: exact distance to the path segment
    for k in range(sphere_center.shape[0]):
        sx, sy, sz, sr = sphere_center[k, 0], sphere_center[k, 1], sphere_center[k, 2], sphere_radius[k]
        if _point_segment(sx, sy, sz, cx, cy, cz, dx, dy, dz, length2) - sr - bound >= best:
            continue
        for m in range(count):
            g = _point_segment(sx, sy, sz, q[m, 0], q[m, 1], q[m, 2], dx, dy, dz, length2) - sr - radii[m]
            if g < best:
                best = g
    n_obst = box_inv.shape[0] + cyl_inv.shape[0]
    if n_obst == 0:
        return best
    steps = n_steps if length > 0.0 else 1
    delta = length / (steps - 1) if steps > 1 else 0.0
    centre = np.empty(3)
    c = 0
    for k in range(n_obst):
        is_box = k < box_inv.shape[0]
        if is_box:
            inv = box_inv[k]
            hx, hy, hz = box_half[k, 0], box_half[k, 1], box_half[k, 2]
            reach = math.sqrt(hx * hx + hy * hy + hz * hz)
        else:
            c = k - box_inv.shape[0]
            inv = cyl_inv[c]
            reach = math.sqrt(cyl_radius[c] ** 2 + cyl_half[c] ** 2)
        _inv_center(inv, centre)
        if _point_segment(centre[0], centre[1], centre[2], cx, cy, cz, dx, dy, dz, length2) - reach - bound >= best:
            continue
        half_step = 0.5 * delta
        for j in range(steps):
            t = j / (steps - 1) if steps > 1 else 0.0
            # The set's bounding sphere first: the distance is 1-Lipschitz, so no sphere
            # of the set (nor its sweep to the next sample) is nearer than the centre's
            # distance minus the bound and the half step.
            x = cx + t * dx
            y = cy + t * dy
            z = cz + t * dz
            if is_box:
                g = _box_point(inv, box_half[k], x, y, z)
            else:
                g = _cylinder_point(inv, cyl_radius[c], cyl_half[c], x, y, z)
            if g - bound - (half_step if steps > 1 else 0.0) >= best:
                continue
            for m in range(count):
                r = radii[m]
                margin = r - math.sqrt(max(r * r - half_step * half_step, 0.0)) if half_step < r else half_step
                x = q[m, 0] + t * dx
                y = q[m, 1] + t * dy
                z = q[m, 2] + t * dz
                if is_box:
                    g = _box_point(inv, box_half[k], x, y, z)
                else:
                    g = _cylinder_point(inv, cyl_radius[c], cyl_half[c], x, y, z)
                g -= r + (margin if steps > 1 else 0.0)
                if g < best:
                    best = g
    return best


@_jit
def finger_scene_gaps(rows, rot, trans, planes_palm, lengths, ratio, distal0, proximal0,
                      coeff, radii, closed_points, approach_distance, n_steps, horizon,
                      planes, box_inv, box_half, sphere_center, sphere_radius,
                      cyl_inv, cyl_radius, cyl_half, out):
    """Least scene gap of each finger row: its closed pose at the grasp and its open
    pre-shape along the approach path.

    rows : (R,) int -- finger rows (particle * 5 + finger)
    rot (P, 3, 3), trans (P, 3) : palm frame in the object frame
    planes_palm : (F, 3, 3) -- flexion plane (base, ex, ey) of every row, palm frame
    lengths (5, 3) m, ratio -- link lengths, distal coupling ratio
    distal0, proximal0 : (F,) rad -- the pre-shape flexions
    coeff (3, K), radii (K,) m -- link spheres as combinations of the planar segments
    closed_points : (R, K, 3) m, object frame -- the closed pose of each row
    approach_distance : m; n_steps : samples along the path (>= 2)
    horizon : m -- gaps are reported up to this
    out : (R,) m (written)
    """
    seg = np.empty((3, 2))
    plane = np.empty((3, 3))
    k_pts = coeff.shape[1]
    q = np.empty((k_pts, 3))
    for k in range(rows.shape[0]):
        f = rows[k]
        p = f // N_FINGERS
        finger = f % N_FINGERS
        zx, zy, zz = rot[p, 0, 2], rot[p, 1, 2], rot[p, 2, 2]
        # the closed pose at the grasp
        for m in range(k_pts):
            q[m, 0] = closed_points[k, m, 0]
            q[m, 1] = closed_points[k, m, 1]
            q[m, 2] = closed_points[k, m, 2]
        gap = _spheres_path_gap(q, radii, k_pts, zx, zy, zz, 0.0, 1, horizon, planes, box_inv, box_half,
                                sphere_center, sphere_radius, cyl_inv, cyl_radius, cyl_half)
        if gap < 0.0:  # illegal at the grasp already: the approach is not traced
            out[k] = gap
            continue
        # the open pre-shape along the approach
        _world_plane(rot, trans, planes_palm, p, f, plane)
        _segments(lengths, finger, ratio, distal0[f], proximal0[f], seg)
        for m in range(k_pts):
            u = coeff[0, m] * seg[0, 0] + coeff[1, m] * seg[1, 0] + coeff[2, m] * seg[2, 0]
            v = coeff[0, m] * seg[0, 1] + coeff[1, m] * seg[1, 1] + coeff[2, m] * seg[2, 1]
            for i in range(3):
                q[m, i] = plane[0, i] + u * plane[1, i] + v * plane[2, i]
        g = _spheres_path_gap(q, radii, k_pts, zx, zy, zz, approach_distance, n_steps, min(gap, horizon),
                              planes, box_inv, box_half, sphere_center, sphere_radius,
                              cyl_inv, cyl_radius, cyl_half)
        out[k] = min(gap, g)


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
            _inv_center(inv, cb)
            for a in range(3):  # axes of the obstacle = rows of its inverse rotation
                for i in range(3):
                    axes_b[i, a] = inv[a, i]
            dist_c = math.sqrt((cb[0] - pc[0]) ** 2 + (cb[1] - pc[1]) ** 2 + (cb[2] - pc[2]) ** 2)
            if dist_c - reach - palm_reach >= best:
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


@_jit
def approach_object_gaps(rows, rot, trans, planes_palm, lengths, ratio, distal0, proximal0,
                         coeff, radii, values, grid_origin, spacing, approach_distance, zone,
                         min_step, max_step, out):
    """Least clearance (m) of the open pre-shape from the object along the approach,
    excluding the last ``zone`` m before the grasp (where the fingers may touch), per
    finger row; 0 is reported for a touch (not its depth), ``max_step`` at most.

    The path of each link sphere is sphere-traced in the signed-distance grid from the
    pre-grasp toward the grasp: a step of the clearance found (the distance is
    1-Lipschitz), clamped to [min_step, max_step] m (the grid over-estimates far
    outside its box; ``max_step`` keeps the tracing from jumping into it).

    rows, rot, trans, planes_palm, lengths, ratio, distal0, proximal0, coeff, radii:
        as :func:`finger_scene_gaps`; values, grid_origin, spacing: the object's grid
    out : (R,) m (written)
    """
    seg = np.empty((3, 2))
    plane = np.empty((3, 3))
    ox, oy, oz = grid_origin[0], grid_origin[1], grid_origin[2]
    inv = 1.0 / spacing
    for k in range(rows.shape[0]):
        f = rows[k]
        p = f // N_FINGERS
        finger = f % N_FINGERS
        zx, zy, zz = rot[p, 0, 2], rot[p, 1, 2], rot[p, 2, 2]
        _world_plane(rot, trans, planes_palm, p, f, plane)
        _segments(lengths, finger, ratio, distal0[f], proximal0[f], seg)
        best = max_step
        for m in range(coeff.shape[1]):
            u = coeff[0, m] * seg[0, 0] + coeff[1, m] * seg[1, 0] + coeff[2, m] * seg[2, 0]
            v = coeff[0, m] * seg[0, 1] + coeff[1, m] * seg[1, 1] + coeff[2, m] * seg[2, 1]
            qx = plane[0, 0] + u * plane[1, 0] + v * plane[2, 0]
            qy = plane[0, 1] + u * plane[1, 1] + v * plane[2, 1]
            qz = plane[0, 2] + u * plane[1, 2] + v * plane[2, 2]
            t = approach_distance
            for _ in range(1000):  # bounded: each step advances at least min_step
                if t < zone:
                    break
                d = _grid_distance(values, ox, oy, oz, inv, spacing, qx - t * zx, qy - t * zy, qz - t * zz) - radii[m]
                if d < best:
                    best = max(d, 0.0)
                if d <= 0.0:
                    break
                t -= min(max(d, min_step), max_step)
            if best <= 0.0:
                break
        out[k] = best
