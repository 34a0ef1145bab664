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
  the path's least distance is at one of its ends (exact); a finger is its joints (the
  least distance of a chain of capsules to a plane is at a capsule's end);
- spheres: the distance from a sphere's centre to the path segment (exact);
- boxes and cylinders: the distance is convex along the path, bounded from below
  within 0.1 mm by the tangents at the ends of a shrinking bracket
  (:mod:`grasp_apso.geometry.convex_distance`); the palm box swept along its own
  normal is :mod:`grasp_apso.geometry.palm_kernels`;
- culling: a finger whose joints' ball, or whose capsules' sweeps by the slabs between a
  box's faces, or a group of link spheres whose ball stays farther than ``horizon`` from
  an obstacle skips it (and reads ``horizon``);
- the object along the approach: each link sphere's path is sphere-traced in the
  object's distance grid (:func:`approach_object_gaps`).

Arrays follow :meth:`grasp_apso.model.scene.Scene.packed` (object frame, float64,
C-contiguous). The kernels release the GIL and are cached on disk, as
:mod:`grasp_apso.geometry.kernels`.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from . import convex_distance
from .kernels import N_FINGERS, _grid_value, _link_point, _segments, _world_plane

_jit = numba.njit(cache=True, nogil=True)


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
def _inv_center(inv):
    """Centre (x, y, z) m of a primitive (world) from its world -> local transform."""
    return (-(inv[0, 0] * inv[0, 3] + inv[1, 0] * inv[1, 3] + inv[2, 0] * inv[2, 3]),
            -(inv[0, 1] * inv[0, 3] + inv[1, 1] * inv[1, 3] + inv[2, 1] * inv[2, 3]),
            -(inv[0, 2] * inv[0, 3] + inv[1, 2] * inv[1, 3] + inv[2, 2] * inv[2, 3]))


@_jit
def _planes_path_gap(q, radii, count, zx, zy, zz, length, planes, best):
    """Least gap (m) of spheres q[:count], radii, moved from q to q - length * z, to the
    support planes (K, 4), or ``best`` when farther: a gap to a half-space is linear
    along the path, so its least is at an end (exact)."""
    dx, dy, dz = -length * zx, -length * zy, -length * zz
    for k in range(planes.shape[0]):
        nx, ny, nz, d0 = planes[k, 0], planes[k, 1], planes[k, 2], planes[k, 3]
        shift = min(0.0, nx * dx + ny * dy + nz * dz)
        for m in range(count):
            g = nx * q[m, 0] + ny * q[m, 1] + nz * q[m, 2] + d0 + shift - radii[m]
            if g < best:
                best = g
    return best


@_jit
def _convex_obstacle(k, box_inv, box_half, cyl_inv, cyl_radius, cyl_half):
    """Obstacle k of the boxes then the cylinders: (is_box, world -> local (3, 4), box
    half sizes hx, hy, hz (0 for a cylinder), cylinder radius and half height (0 for a box))."""
    n_box = box_inv.shape[0]
    if k < n_box:
        return True, box_inv[k], box_half[k, 0], box_half[k, 1], box_half[k, 2], 0.0, 0.0
    c = k - n_box
    return False, cyl_inv[c], 0.0, 0.0, 0.0, cyl_radius[c], cyl_half[c]


@_jit
def _local_direction(inv, dx, dy, dz):
    """A direction (object frame) in an obstacle's frame."""
    return (inv[0, 0] * dx + inv[0, 1] * dy + inv[0, 2] * dz,
            inv[1, 0] * dx + inv[1, 1] * dy + inv[1, 2] * dz,
            inv[2, 0] * dx + inv[2, 1] * dy + inv[2, 2] * dz)


#: Link spheres per culling group of :func:`_spheres_path_gap` (consecutive spheres of a
#: finger: a group's bounding sphere is a few centimetres across).
CULL_GROUP = 7


@_jit
def _spheres_path_gap(q, radii, count, zx, zy, zz, length, horizon,
                      planes, box_inv, box_half, sphere_center, sphere_radius,
                      cyl_inv, cyl_radius, cyl_half, gc, gb):
    """Least gap (m) of spheres q[:count] (centres, object frame), radii, moved from
    q to q - length * z (``length`` 0: the spheres at q only), to the scene; at most
    ``horizon``.

    Obstacles are culled per group of :data:`CULL_GROUP` consecutive spheres: a group
    whose bounding sphere stays farther than the least gap found so far is skipped.
    gc (G, 3), gb (G,) : scratch for the groups' bounding spheres, G >= count / CULL_GROUP."""
    best = horizon
    dx, dy, dz = -length * zx, -length * zy, -length * zz
    length2 = length * length
    best = _planes_path_gap(q, radii, count, zx, zy, zz, length, planes, best)
    n_box = box_inv.shape[0]
    n_obst = n_box + cyl_inv.shape[0]
    if sphere_center.shape[0] + n_obst == 0:
        return best
    # bounding spheres of the groups
    n_groups = (count + CULL_GROUP - 1) // CULL_GROUP
    for g in range(n_groups):
        lo, hi = g * CULL_GROUP, min(count, (g + 1) * CULL_GROUP)
        gc[g, 0] = gc[g, 1] = gc[g, 2] = gb[g] = 0.0
        for m in range(lo, hi):
            for i in range(3):
                gc[g, i] += q[m, i]
        for i in range(3):
            gc[g, i] /= hi - lo
        for m in range(lo, hi):
            gb[g] = max(gb[g], math.sqrt((q[m, 0] - gc[g, 0]) ** 2 + (q[m, 1] - gc[g, 1]) ** 2
                                         + (q[m, 2] - gc[g, 2]) ** 2) + radii[m])
    # spheres: exact distance to the path segment
    for k in range(sphere_center.shape[0]):
        sx, sy, sz, sr = sphere_center[k, 0], sphere_center[k, 1], sphere_center[k, 2], sphere_radius[k]
        for g in range(n_groups):
            if _point_segment(sx, sy, sz, gc[g, 0], gc[g, 1], gc[g, 2], dx, dy, dz, length2) - sr - gb[g] >= best:
                continue
            for m in range(g * CULL_GROUP, min(count, (g + 1) * CULL_GROUP)):
                d = _point_segment(sx, sy, sz, q[m, 0], q[m, 1], q[m, 2], dx, dy, dz, length2) - sr - radii[m]
                if d < best:
                    best = d
    # boxes and cylinders: the least along the path of a convex distance (tangent bound)
    for k in range(n_obst):
        is_box, inv, hx, hy, hz, rad, hh = _convex_obstacle(k, box_inv, box_half, cyl_inv, cyl_radius, cyl_half)
        reach = math.sqrt(hx * hx + hy * hy + hz * hz + rad * rad + hh * hh)  # one of the pairs is 0
        ex, ey, ez = _inv_center(inv)
        wx, wy, wz = _local_direction(inv, dx, dy, dz)
        for g in range(n_groups):
            # the obstacle's bounding sphere, then the obstacle itself, against the
            # group's bounding sphere: no sphere of the group comes nearer
            if _point_segment(ex, ey, ez, gc[g, 0], gc[g, 1], gc[g, 2], dx, dy, dz, length2) - reach - gb[g] >= best:
                continue
            if convex_distance.path_least(is_box, inv, hx, hy, hz, rad, hh, gc[g, 0], gc[g, 1], gc[g, 2], length,
                                          dx, dy, dz, wx, wy, wz, best + gb[g]) - gb[g] >= best:
                continue
            for m in range(g * CULL_GROUP, min(count, (g + 1) * CULL_GROUP)):
                r = radii[m]
                # the slabs' bound first (a few products), the convex least when needed
                if convex_distance.path_slab_bound(is_box, inv, hx, hy, hz, rad, hh, q[m, 0], q[m, 1], q[m, 2],
                                                   wx, wy, wz) - r >= best:
                    continue
                d = convex_distance.path_least(is_box, inv, hx, hy, hz, rad, hh, q[m, 0], q[m, 1], q[m, 2],
                                               length, dx, dy, dz, wx, wy, wz, best + r) - r
                if d < best:
                    best = d
    return best


@_jit
def _ball_clear(points, radii, count, zx, zy, zz, length, best, box_inv, box_half, sphere_center, sphere_radius,
                cyl_inv, cyl_radius, cyl_half):
    """True when the ball around spheres points[:count], radii, moved from them to
    them - length * z, stays at least ``best`` (m) from every obstacle: then nothing
    inside that ball comes nearer (a ball holding a finger's joints holds its capsules)."""
    cx = cy = cz = 0.0
    for m in range(count):
        cx += points[m, 0]
        cy += points[m, 1]
        cz += points[m, 2]
    cx /= count
    cy /= count
    cz /= count
    bound = 0.0
    for m in range(count):
        bound = max(bound, math.sqrt((points[m, 0] - cx) ** 2 + (points[m, 1] - cy) ** 2
                                     + (points[m, 2] - cz) ** 2) + radii[m])
    dx, dy, dz = -length * zx, -length * zy, -length * zz
    length2 = length * length
    for k in range(sphere_center.shape[0]):
        if _point_segment(sphere_center[k, 0], sphere_center[k, 1], sphere_center[k, 2], cx, cy, cz,
                          dx, dy, dz, length2) - sphere_radius[k] - bound < best:
            return False
    n_box = box_inv.shape[0]
    for k in range(n_box + cyl_inv.shape[0]):
        is_box, inv, hx, hy, hz, rad, hh = _convex_obstacle(k, box_inv, box_half, cyl_inv, cyl_radius, cyl_half)
        wx, wy, wz = _local_direction(inv, dx, dy, dz)
        if convex_distance.path_least(is_box, inv, hx, hy, hz, rad, hh, cx, cy, cz, length, dx, dy, dz, wx, wy, wz,
                       best + bound) - bound < best:
            return False
    return True


@_jit
def _slab_gap(inv, hx, hy, hz, ends, count, is_box):
    """Lower bound (m) of the distance from the convex hull of ``ends[:count]`` (points,
    object frame) to a box (half sizes hx, hy, hz) or, with ``is_box`` False, to the slab
    of a cylinder's height (half height ``hz``): along each of the obstacle's axes the
    hull's coordinates span an interval; the largest gap of an interval to the slab."""
    best = -np.inf
    for axis in range(3 if is_box else 1):
        ax = 2 if not is_box else axis
        half = hx if ax == 0 else (hy if ax == 1 else hz)
        lo, hi = np.inf, -np.inf
        for m in range(count):
            c = inv[ax, 0] * ends[m, 0] + inv[ax, 1] * ends[m, 1] + inv[ax, 2] * ends[m, 2] + inv[ax, 3]
            lo = min(lo, c)
            hi = max(hi, c)
        best = max(best, lo - half, -half - hi)
    return best


@_jit
def _capsules_slab_clear(joints, link_radii, zx, zy, zz, length, best, box_inv, box_half, cyl_inv, cyl_radius,
                         cyl_half, ends):
    """True when every capsule and the pad of a finger (``joints`` (J, 3) m, radii
    link_radii (J,) m, moved from there by -length * z) stay at least ``best`` (m) from
    every box and cylinder by the slabs between their faces (:func:`_slab_gap`: exact
    for a flat wall); ``ends`` (4, 3) is scratch."""
    n_links = joints.shape[0] - 1
    dx, dy, dz = -length * zx, -length * zy, -length * zz
    for k in range(box_inv.shape[0] + cyl_inv.shape[0]):
        is_box, inv, hx, hy, hz, _, hh = _convex_obstacle(k, box_inv, box_half, cyl_inv, cyl_radius, cyl_half)
        hz = hz if is_box else hh  # a cylinder: the slab of its height
        for j in range(n_links + 1):
            count = 0
            for e in range(2 if j < n_links else 1):
                for i in range(3):
                    ends[count, i] = joints[j + e, i]
                    ends[count + 1, i] = joints[j + e, i] + (dx if i == 0 else (dy if i == 1 else dz))
                count += 2
            if _slab_gap(inv, hx, hy, hz, ends, count, is_box) - link_radii[j] < best:
                return False
    return True


@_jit
def finger_path_gaps(rows, rot, trans, planes_palm, lengths, ratio, distal0, proximal0,
                     coeff, radii, joint_cols, joint_radii, link_radii, approach_distance, horizon,
                     planes, box_inv, box_half, sphere_center, sphere_radius, cyl_inv, cyl_radius, cyl_half,
                     out):
    """Least scene gap (m, at most ``horizon``) of each finger row's open pre-shape moved
    along the approach, from the pre-grasp to the grasp (both included).

    Against the support planes a finger is its joints: the least distance of a chain of
    capsules (and the pad) to a plane is at a capsule's end, so the joints with the
    largest radius of the parts ending there give it exactly. Against obstacles it is
    its link spheres, once the ball around its joints comes near one.

    rows : (R,) int -- finger rows (particle * 5 + finger)
    rot (P, 3, 3), trans (P, 3) : palm frame in the object frame
    planes_palm : (F, 3, 3) -- flexion plane (base, ex, ey) of every row, palm frame
    lengths (5, 3) m, ratio -- link lengths, distal coupling ratio
    distal0, proximal0 : (F,) rad -- the pre-shape flexions
    coeff (3, K), radii (K,) m -- link spheres as combinations of the planar segments
    joint_cols (J,) int, joint_radii (J,) m -- the columns of the joints among them and
        the radius of the hand at each joint; link_radii (J,) m -- the capsules' radii and
        the pad's
    approach_distance : m
    out : (R,) m (written)
    """
    seg = np.empty((3, 2))
    plane = np.empty((3, 3))
    k_pts = coeff.shape[1]
    n_joints = joint_cols.shape[0]
    q = np.empty((k_pts, 3))
    joints = np.empty((n_joints, 3))
    no_planes = planes[:0]
    obstacles = sphere_center.shape[0] + box_inv.shape[0] + cyl_inv.shape[0] > 0
    n_groups = (k_pts + CULL_GROUP - 1) // CULL_GROUP
    gc = np.empty((n_groups, 3))
    gb = np.empty(n_groups)
    ends = np.empty((4, 3))
    for k in range(rows.shape[0]):
        f = rows[k]
        p = f // N_FINGERS
        zx, zy, zz = rot[p, 0, 2], rot[p, 1, 2], rot[p, 2, 2]
        _world_plane(rot, trans, planes_palm, p, f, plane)
        _segments(lengths, f % N_FINGERS, ratio, distal0[f], proximal0[f], seg)
        for j in range(n_joints):
            joints[j, 0], joints[j, 1], joints[j, 2] = _link_point(coeff, joint_cols[j], seg, plane)
        g = _planes_path_gap(joints, joint_radii, n_joints, zx, zy, zz, approach_distance, planes, horizon)
        # obstacles: the ball around the joints, then (boxes and cylinders only) the
        # slabs of each capsule's sweep, then the link spheres
        if obstacles and not _ball_clear(joints, joint_radii, n_joints, zx, zy, zz, approach_distance, g,
                                         box_inv, box_half, sphere_center, sphere_radius, cyl_inv, cyl_radius,
                                         cyl_half) and not (
                sphere_center.shape[0] == 0
                and _capsules_slab_clear(joints, link_radii, zx, zy, zz, approach_distance, g, box_inv, box_half,
                                         cyl_inv, cyl_radius, cyl_half, ends)):
            for m in range(k_pts):
                q[m, 0], q[m, 1], q[m, 2] = _link_point(coeff, m, seg, plane)
            g = _spheres_path_gap(q, radii, k_pts, zx, zy, zz, approach_distance, g,
                                  no_planes, box_inv, box_half, sphere_center, sphere_radius,
                                  cyl_inv, cyl_radius, cyl_half, gc, gb)
        out[k] = g


@_jit
def _capsules_gap(joints, link_radii, best, box_inv, box_half, sphere_center, sphere_radius,
                  cyl_inv, cyl_radius, cyl_half):
    """Least gap (m) of a finger at rest, its capsules between consecutive ``joints``
    (J, 3) m with radii link_radii[:J-1] and a pad of radius link_radii[J-1] on the
    last joint, to the obstacles; ``best`` when farther. Exact: a sphere's distance to
    a segment, a box's or a cylinder's least along it (convex)."""
    n_links = joints.shape[0] - 1
    for k in range(sphere_center.shape[0]):
        sx, sy, sz, sr = sphere_center[k, 0], sphere_center[k, 1], sphere_center[k, 2], sphere_radius[k]
        for j in range(n_links + 1):
            a = joints[j]
            if j < n_links:
                dx, dy, dz = joints[j + 1, 0] - a[0], joints[j + 1, 1] - a[1], joints[j + 1, 2] - a[2]
            else:
                dx = dy = dz = 0.0
            g = _point_segment(sx, sy, sz, a[0], a[1], a[2], dx, dy, dz, dx * dx + dy * dy + dz * dz)
            best = min(best, g - sr - link_radii[j])
    n_box = box_inv.shape[0]
    for k in range(n_box + cyl_inv.shape[0]):
        is_box, inv, hx, hy, hz, rad, hh = _convex_obstacle(k, box_inv, box_half, cyl_inv, cyl_radius, cyl_half)
        for j in range(n_links + 1):
            a = joints[j]
            r = link_radii[j]
            if j < n_links:
                dx, dy, dz = joints[j + 1, 0] - a[0], joints[j + 1, 1] - a[1], joints[j + 1, 2] - a[2]
                wx, wy, wz = _local_direction(inv, dx, dy, dz)
                g = convex_distance.convex_path_least(is_box, inv, hx, hy, hz, rad, hh, a[0], a[1], a[2],
                                                      dx, dy, dz, wx, wy, wz, best + r)
            else:
                g = convex_distance.convex_value_slope(is_box, inv, hx, hy, hz, rad, hh, a[0], a[1], a[2],
                                                       0.0, 0.0, 0.0)[0]
            best = min(best, g - r)
    return best


@_jit
def finger_grasp_gaps(rows, rot, joint_cols, joint_radii, link_radii, points, horizon,
                      planes, box_inv, box_half, sphere_center, sphere_radius, cyl_inv, cyl_radius, cyl_half,
                      out):
    """Least scene gap (m, at most ``horizon``) of each finger row's closed pose at the
    grasp, exact for its capsules and pad: against the planes its joints (as
    :func:`finger_path_gaps`), against obstacles its capsules (:func:`_capsules_gap`).

    rows : (R,) int; rot (P, 3, 3) -- for the rows' particles
    joint_cols (J,) int, joint_radii (J,) m -- the joints among ``points`` and the hand's
        radius there; link_radii (J,) m -- the capsules' radii and the pad's
    points : (R, K, 3) m, object frame -- the closed pose's link points
    out : (R,) m (written)
    """
    n_joints = joint_cols.shape[0]
    joints = np.empty((n_joints, 3))
    obstacles = sphere_center.shape[0] + box_inv.shape[0] + cyl_inv.shape[0] > 0
    for k in range(rows.shape[0]):
        p = rows[k] // N_FINGERS
        zx, zy, zz = rot[p, 0, 2], rot[p, 1, 2], rot[p, 2, 2]
        for j in range(n_joints):
            for i in range(3):
                joints[j, i] = points[k, joint_cols[j], i]
        g = _planes_path_gap(joints, joint_radii, n_joints, zx, zy, zz, 0.0, planes, horizon)
        if obstacles and not _ball_clear(joints, joint_radii, n_joints, zx, zy, zz, 0.0, g, box_inv, box_half,
                                         sphere_center, sphere_radius, cyl_inv, cyl_radius, cyl_half):
            g = _capsules_gap(joints, link_radii, g, box_inv, box_half, sphere_center, sphere_radius,
                              cyl_inv, cyl_radius, cyl_half)
        out[k] = g


@_jit
def _object_distance_below(values, ox, oy, oz, inv, spacing, box_lo, box_hi, x, y, z):
    """Distance (m) of a point to the object for tracing: never over-estimated far away,
    0 or less inside it (not its depth).

    The larger of two lower bounds of the distance outside the object: the grid's value
    at the nearest point ``c`` of the grid's box minus ``|p - c|`` (the distance is
    1-Lipschitz; inside the box that is the grid's value; outside it the grid's own
    extension, :func:`grasp_apso.geometry.kernels._grid_distance`, over-estimates) and
    the distance to the object's bounding box ``box_lo``, ``box_hi`` (3,) m.
    Branch-free: about as fast as a plain look-up.
    """
    value, outside = _grid_value(values, ox, oy, oz, inv, spacing, x, y, z)
    dx = max(box_lo[0] - x, 0.0, x - box_hi[0])
    dy = max(box_lo[1] - y, 0.0, y - box_hi[1])
    dz = max(box_lo[2] - z, 0.0, z - box_hi[2])
    return max(value - outside, math.sqrt(dx * dx + dy * dy + dz * dz))


@_jit
def approach_object_gaps(rows, rot, trans, planes_palm, lengths, ratio, distal0, proximal0,
                         coeff, radii, values, grid_origin, spacing, box_lo, box_hi, approach_distance,
                         zone, min_step, cap, out):
    """Least clearance (m) of the open pre-shape from the object along the approach,
    excluding the last ``zone`` m before the grasp (where the fingers may touch), per
    finger row; 0 is reported for a touch (not its depth), ``cap`` at most.

    The path of each link sphere is sphere-traced from the pre-grasp toward the grasp:
    a step of the clearance found (the distance is 1-Lipschitz), at least ``min_step``
    m. Far from the object the distance is a lower bound (:func:`_object_distance_below`),
    so that a long step never jumps into the object; most paths take one or two steps.

    rows, rot, trans, planes_palm, lengths, ratio, distal0, proximal0, coeff, radii:
        as :func:`finger_scene_gaps`; values, grid_origin, spacing: the object's grid;
        box_lo, box_hi : (3,) m, the object's bounding box
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
        best = cap
        for m in range(coeff.shape[1]):
            qx, qy, qz = _link_point(coeff, m, seg, plane)
            t = approach_distance
            for _ in range(1000):  # bounded: each step advances at least min_step
                if t < zone:
                    break
                d = _object_distance_below(values, ox, oy, oz, inv, spacing, box_lo, box_hi,
                                           qx - t * zx, qy - t * zy, qz - t * zz) - radii[m]
                if d < best:
                    best = max(d, 0.0)
                if d <= 0.0:
                    break
                t -= max(d, min_step)
            if best <= 0.0:
                break
        out[k] = best
