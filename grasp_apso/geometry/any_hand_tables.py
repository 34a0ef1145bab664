"""Flat tables of a general hand for the compiled search (:mod:`.any_hand_kernels`), and
the particle layout derived from the hand.

Built once per hand and cached by ``HandModel.source_hash`` (:mod:`grasp_apso.cache`).

Particle layout (:class:`ParticleLayout`), D = 6 + n (SI): the wrist orientation (3 angles,
the palm frame in the object frame, ``R = Rz Ry Rx`` as the paper hand's
:func:`grasp_apso.model.hand.wrist_rotation`), the standoff (m), the pre-shape of the
``n`` actuated joints (rad or m) and the grasp centre's shift across the palm (2, m, along
palm x and y). The palm frame is the paper's convention (x toward the
fingers, z the palm normal); the root (palm link) is ``R_palm @ basis.T``.

Kinematics in the tables: a finger's links are posed from a constant pose of the chain's
first parent (links above the fingers move with held joints only) and the motions of the
file (revolute about an axis through an anchor, prismatic along an axis) whose values are
``full = A @ q + b`` (couplings). Link collision spheres (``hand.spheres``) are grouped by
:data:`GROUP_SIZE` with a bounding sphere per group, so that a look-up skips the groups
far from the surface.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..cache import cached
from ..errors import HandDescriptionError
from ..model.hands.fk_kernel import PRISMATIC, REVOLUTE

__all__ = ["ParticleLayout", "HandTables", "hand_tables", "pad_body_links", "GROUP_SIZE"]

#: Spheres per bounding group (culling unit of the look-ups).
GROUP_SIZE = 12
#: Spheres per link the compiled search reads (:func:`search_spheres`).
SEARCH_SPHERES = 64
#: Wrist angle bounds (rad): theta_x, theta_y, theta_z (the paper hand's, ``model.hand``).
WRIST_LOWER = np.array([-np.pi, -np.pi / 2, -np.pi])
WRIST_UPPER = np.array([np.pi, np.pi / 2, np.pi])
#: Standoff range (m) from the hand's reach (half its longest finger): this fraction of
#: it, within [STANDOFF_MIN, STANDOFF_MAX].
REACH_FRACTION = 1.0
STANDOFF_MIN, STANDOFF_MAX = 0.03, 0.12
#: The grasp centre's shift across the palm: within this fraction of the hand's reach
#: (half its longest finger) along palm x and y. The paper's rule puts the grasp centre
#: on the line through the centre of mass; a large hand turned sideways over a low object
#: then reaches the table, and its grasps come from above with every contact above the
#: centre of mass (measured, the Schunk SVH on the orange: of 6000 GRG draws none from the
#: side kept the clearance). Shifted, the palm passes beside the centre of mass: 13 hands'
#: best grasps held with DexGraspBench's parameters 675 -> 703 of 819, the SVH's 38 -> 48
#: (``bench/held_rate.py --seeds 3 --dexgraspbench``; docs/any-hand-measurements.md).
SHIFT_FRACTION = 0.5
#: The grasp centre's postures (:func:`_opposition_point`): how many, and the share (those
#: with the pads nearest each other) whose pads' mean it is.
OPPOSITION_SAMPLES = 2048
OPPOSITION_SHARE = 0.05



@dataclass(frozen=True)
class ParticleLayout:
    """Named slices of a general hand's particle: ``wrist`` (3 angles), ``standoff``
    (index), ``joints`` (the n actuated joints), ``shift`` (2: the grasp centre across the
    palm, m), ``dims`` = 6 + n."""

    n_joints: int

    @property
    def wrist(self) -> slice:
        return slice(0, 3)

    @property
    def standoff(self) -> int:
        return 3

    @property
    def joints(self) -> slice:
        return slice(4, 4 + self.n_joints)

    @property
    def shift(self) -> slice:
        return slice(4 + self.n_joints, 6 + self.n_joints)

    @property
    def dims(self) -> int:
        return 6 + self.n_joints


def _ro(a, dtype=np.float64) -> np.ndarray:
    out = np.ascontiguousarray(a, dtype=dtype)
    out.flags.writeable = False
    return out


@dataclass(frozen=True, eq=False)
class HandTables:
    """The hand as the kernels read it (read-only, C-contiguous). F fingers, at most
    ``Lmax`` links each; the finger-local link ``l`` of finger ``f`` is
    ``finger_link[f, l]`` (index into ``hand.links``), -1 padding."""

    layout: ParticleLayout
    lower: np.ndarray            # (D,) particle bounds
    upper: np.ndarray            # (D,)
    full_a: np.ndarray           # (m, n) full = A q + b
    full_b: np.ndarray           # (m,)
    n_links: np.ndarray          # (F,) int
    finger_link: np.ndarray      # (F, Lmax) int
    parent: np.ndarray           # (F, Lmax) int, finger-local parent or -1
    pre: np.ndarray              # (F, Lmax, 4, 4) constant parent pose @ origin, or origin
    m_start: np.ndarray          # (F, Lmax) int
    m_count: np.ndarray          # (F, Lmax) int
    m_kind: np.ndarray           # (M,) int, fk_kernel.REVOLUTE (0) or PRISMATIC (1)
    m_axis: np.ndarray           # (M, 3)
    m_anchor: np.ndarray         # (M, 3)
    m_index: np.ndarray          # (M,) int, full index
    m_ref: np.ndarray            # (M,)
    g_start: np.ndarray          # (F, Lmax) int: groups of the link
    g_count: np.ndarray          # (F, Lmax) int
    grp_start: np.ndarray        # (G,) int: spheres of the group
    grp_count: np.ndarray        # (G,) int
    grp_center: np.ndarray       # (G, 3) link frame
    grp_radius: np.ndarray       # (G,)
    sph_center: np.ndarray       # (S, 3) link frame
    sph_radius: np.ndarray       # (S,)
    pad_local: np.ndarray        # (F,) int, finger-local index of the pad link
    pad_center: np.ndarray       # (F, 3) pad link frame: the pad sphere's centre (pad_sphere_center)
    pad_radius: np.ndarray       # (F,)
    pad_point: np.ndarray        # (F, 3) pad link frame: the pad point (``Finger.pad_center``, on the surface)
    pad_slack: np.ndarray        # (F,) m: how far the pad body's covers stray outside its geometry
    j_count: np.ndarray          # (F,) int
    j_index: np.ndarray          # (F, Jmax) int, into q
    j_target: np.ndarray         # (F, Jmax) closing limit (or NaN for pre-shape joints)
    lnk_center: np.ndarray       # (F, Lmax, 3) link frame: bounding sphere of the link's groups
    lnk_radius: np.ndarray       # (F, Lmax), -1 for a link without spheres
    moving: np.ndarray           # (F, Lmax) int: 1 when the finger's closing moves the link
    pad_body: np.ndarray         # (F, Lmax) int: 1 when the link is rigidly fixed to the pad link (one body)
    palm_bound: np.ndarray       # (4,) root frame: centre and radius bounding the palm's spheres
    palm_groups: np.ndarray      # (Gp,) int groups of the palm (root and non-finger links)
    palm_pose: np.ndarray        # (Gp, 4, 4) their link pose in the root frame
    pairs: np.ndarray            # (K, 4) int: f1, l1, f2, l2 link pairs checked for overlap
    basis: np.ndarray            # (3, 3) columns: palm x, y, z (normal) in the root frame
    grasp_center: np.ndarray     # (3,) root frame, on the palm face
    open_q: np.ndarray           # (n,)
    #: The open pads stand beyond the hand's reach in front of the palm face (a claw's
    #: fingers extend along the normal): the standoff reaches them (:func:`standoff_range`)
    #: and GRG pre-shapes the fingers less closed.
    closes_ahead: bool = False

    @property
    def n_fingers(self) -> int:
        return len(self.n_links)

    def root_rotations(self, angles: np.ndarray) -> np.ndarray:
        """Root rotations in the object frame: wrist angles (P, 3) -> (P, 3, 3)."""
        from ..model.hand import wrist_rotation

        return wrist_rotation(angles) @ self.basis.T


def hand_tables(hand) -> HandTables:
    """The tables of ``hand`` (a :class:`grasp_apso.model.hands.HandModel`), cached by its
    ``source_hash``."""
    return cached("hand_tables", hand.source_hash, lambda: _build(hand))


def pad_body_links(hand, f: int) -> set[str]:
    """The links of finger ``f``'s pad body: its pad link and the links rigidly fixed to
    it (one body: the Allegro-like tip is a small link on the distal, the Revo2's thumb
    carries a marker plate). Their touching the object is the pad's."""
    tables = hand_tables(hand)
    body = {hand.links[i] for i, b in zip(tables.finger_link[f], tables.pad_body[f]) if i >= 0 and b}
    return body | {hand.fingers[f].pad_link}


def search_spheres(cover) -> tuple[np.ndarray, np.ndarray]:
    """The spheres of a link's cover the compiled search reads: the first
    :data:`SEARCH_SPHERES` (``cover_link`` picks greedily, so they are the ones that cover
    most). A complete cover of a palm with fine detail holds thousands at 2 mm; the search
    needs the link's bulk, and the exact geometry (python-fcl) decides at the end.
    Returns centres (k, 3) link frame m and radii (k,) m."""
    k = min(len(cover.radii), SEARCH_SPHERES)
    return np.asarray(cover.centers, float)[:k], np.asarray(cover.radii, float)[:k]


def _groups(centers: np.ndarray) -> list[np.ndarray]:
    """Sphere index groups of a link's cover: sorted along the principal axis, chunked."""
    c = centers
    if len(c) <= GROUP_SIZE:
        return [np.arange(len(c))]
    axis = np.linalg.svd(c - c.mean(0), full_matrices=False)[2][0]
    order = np.argsort(c @ axis, kind="stable")
    return [order[i:i + GROUP_SIZE] for i in range(0, len(order), GROUP_SIZE)]


def _build(hand) -> HandTables:
    if not hand.spheres:
        raise HandDescriptionError(f"hand {hand.name!r}: loaded without its sphere covers (load_hand(spheres=True))",
                                   field="hand_description")
    n = hand.n_joints
    layout = ParticleLayout(n)
    fingers = hand.fingers
    q_open = hand.open_configuration()
    rest = hand.link_transforms_batch(np.stack([q_open, hand.closed_configuration(0.9)]))
    finger_links = [hand.finger_links(f) for f in fingers]
    in_finger = {name for links in finger_links for name in links}
    lmax = max(len(x) for x in finger_links)
    nf = len(fingers)
    n_links = np.array([len(x) for x in finger_links])
    finger_link = -np.ones((nf, lmax), np.int64)
    parent = -np.ones((nf, lmax), np.int64)
    pre = np.tile(np.eye(4), (nf, lmax, 1, 1))
    m_start, m_count = np.zeros((nf, lmax), np.int64), np.zeros((nf, lmax), np.int64)
    g_start, g_count = np.zeros((nf, lmax), np.int64), np.zeros((nf, lmax), np.int64)
    motions: list = []
    grp_start, grp_count, grp_center, grp_radius, sph_c, sph_r = [], [], [], [], [], []

    def add_groups(link: str) -> tuple[int, int]:
        cover = hand.spheres.get(link)
        first = len(grp_start)
        if cover is None or len(cover.radii) == 0:
            return first, 0
        centers, radii = search_spheres(cover)
        for idx in _groups(centers):
            c = centers[idx]
            mid = 0.5 * (c.min(0) + c.max(0))
            grp_start.append(len(sph_r))
            grp_count.append(len(idx))
            grp_center.append(mid)
            grp_radius.append(float((np.linalg.norm(c - mid, axis=1) + radii[idx]).max()))
            sph_c.extend(c)
            sph_r.extend(radii[idx])
        return first, len(grp_start) - first

    for f, links in enumerate(finger_links):
        for l, name in enumerate(links):
            i = hand.link_index(name)
            finger_link[f, l] = i
            p = hand.link_parents[i]
            pname = hand.links[p] if p >= 0 else None
            if pname in links:
                parent[f, l] = links.index(pname)
                pre[f, l] = hand.origins[i]
            else:
                if pname in in_finger or (p >= 0 and not np.allclose(rest[0, p], rest[1, p], atol=1e-9)):
                    raise HandDescriptionError(
                        f"hand {hand.name!r}: link {name!r} hangs from {pname!r}, which another finger moves "
                        "(not supported by the general search)", field="hand_description")
                base = rest[0, p] if p >= 0 else hand.root_inverse
                pre[f, l] = base @ hand.origins[i]
            m_start[f, l] = len(motions)
            m_count[f, l] = len(hand.motions[i])
            motions.extend(hand.motions[i])
            g_start[f, l], g_count[f, l] = add_groups(name)

    palm_groups, palm_pose = [], []
    for i, name in enumerate(hand.links):
        if name in in_finger:
            continue
        first, count = add_groups(name)
        palm_groups.extend(range(first, first + count))
        palm_pose.extend([rest[0, i]] * count)

    pads = [(finger_links[f].index(fg.pad_link), pad_sphere_center(hand, fg), fg.pad_radius)
            for f, fg in enumerate(fingers)]
    jmax = max(len(fg.joints) for fg in fingers)
    j_count = np.array([len(fg.joints) for fg in fingers])
    j_index = np.zeros((nf, jmax), np.int64)
    j_target = np.full((nf, jmax), np.nan)
    for f, fg in enumerate(fingers):
        for k, (joint, sense) in enumerate(zip(fg.joints, fg.closing)):
            j = hand.actuated_joints.index(joint)
            j_index[f, k] = j
            if sense != 0:
                j_target[f, k] = hand.upper[j] if sense > 0 else hand.lower[j]

    lnk_center, lnk_radius = np.zeros((nf, lmax, 3)), -np.ones((nf, lmax))
    for f in range(nf):
        for l in range(int(n_links[f])):
            g = np.arange(g_start[f, l], g_start[f, l] + g_count[f, l])
            if len(g):
                lnk_center[f, l], lnk_radius[f, l] = _bound(np.array(grp_center)[g], np.array(grp_radius)[g])
    moving = np.zeros((nf, lmax), np.int64)
    for f in range(nf):
        for l in range(int(n_links[f])):
            i = finger_link[f, l]
            moving[f, l] = int(not np.allclose(rest[0, i], rest[1, i], atol=1e-9))
    pad_body = _pad_bodies(hand, finger_links, [p[0] for p in pads], lmax)
    # The pad body's covers stray at most this far outside its exact surface.
    pad_slack = [max(float(hand.spheres[name].max_stray) for l, name in enumerate(finger_links[f])
                     if pad_body[f, l] and name in hand.spheres) for f in range(nf)]
    if palm_groups:
        pc = np.array([p[:3, :3] @ grp_center[g] + p[:3, 3] for g, p in zip(palm_groups, palm_pose)])
        palm_bound = np.append(*_bound(pc, np.array(grp_radius)[palm_groups]))
    else:
        palm_bound = np.array([0.0, 0.0, 0.0, -1.0])
    pairs = _overlap_pairs(hand, finger_links, rest[0])
    basis, center, reach, front = _palm_frame(hand)
    standoff, closes_ahead = standoff_range(reach, front)
    shift = SHIFT_FRACTION * reach
    lower = np.concatenate([WRIST_LOWER, [0.0], hand.lower, [-shift, -shift]])
    upper = np.concatenate([WRIST_UPPER, [standoff], hand.upper, [shift, shift]])
    empty3 = np.zeros((0, 3))
    return HandTables(
        layout=layout, lower=_ro(lower), upper=_ro(upper), full_a=_ro(hand.full_matrix), full_b=_ro(hand.full_offset),
        n_links=_ro(n_links, np.int64), finger_link=_ro(finger_link, np.int64), parent=_ro(parent, np.int64),
        pre=_ro(pre), m_start=_ro(m_start, np.int64), m_count=_ro(m_count, np.int64),
        m_kind=_ro([REVOLUTE if m.kind == "revolute" else PRISMATIC for m in motions], np.int64),
        m_axis=_ro([m.axis for m in motions] or empty3), m_anchor=_ro([m.anchor for m in motions] or empty3),
        m_index=_ro([m.index for m in motions], np.int64), m_ref=_ro([m.ref for m in motions]),
        g_start=_ro(g_start, np.int64), g_count=_ro(g_count, np.int64),
        grp_start=_ro(grp_start, np.int64), grp_count=_ro(grp_count, np.int64),
        grp_center=_ro(grp_center), grp_radius=_ro(grp_radius), sph_center=_ro(sph_c), sph_radius=_ro(sph_r),
        pad_local=_ro([p[0] for p in pads], np.int64), pad_center=_ro([p[1] for p in pads]),
        pad_radius=_ro([p[2] for p in pads]), pad_point=_ro([np.asarray(f.pad_center, float) for f in fingers]),
        pad_slack=_ro(pad_slack), j_count=_ro(j_count, np.int64), j_index=_ro(j_index, np.int64),
        j_target=_ro(j_target), lnk_center=_ro(lnk_center), lnk_radius=_ro(lnk_radius),
        moving=_ro(moving, np.int64), pad_body=_ro(pad_body, np.int64),
        palm_bound=_ro(palm_bound), palm_groups=_ro(palm_groups, np.int64),
        palm_pose=_ro(np.reshape(palm_pose, (-1, 4, 4))), pairs=_ro(pairs, np.int64).reshape(-1, 4),
        basis=_ro(basis), grasp_center=_ro(center), open_q=_ro(q_open), closes_ahead=closes_ahead,
    )


def pad_sphere_center(hand, finger) -> np.ndarray:
    """The centre (3,) of a finger's pad sphere in its pad link's frame: the pad point
    (``finger.pad_center``, on the link's surface) moved ``pad_radius`` inward along the
    surface normal there (the gradient of the link's exact signed distance), so that the
    sphere's surface is the pad's: it touches the object at the pad."""
    from ..model.hands.spheres import union_signed_distance

    geoms = hand.collision[finger.pad_link]
    p = np.asarray(finger.pad_center, float)
    h = 1e-4
    grad = np.array([union_signed_distance(geoms, (p + h * e)[None])[0] - union_signed_distance(geoms, (p - h * e)[None])[0]
                     for e in np.eye(3)])
    norm = np.linalg.norm(grad)
    if norm < 1e-9:
        raise HandDescriptionError(f"hand {hand.name!r}: no surface normal at the pad of finger {finger.name!r}",
                                   field="pad_center")
    return p - finger.pad_radius * grad / norm


def _pad_bodies(hand, finger_links, pad_local, lmax: int) -> np.ndarray:
    """(F, Lmax) bool: the finger's links whose pose relative to its pad link is the same
    in three postures (fixed joints between them: a fingertip link on its phalanx). Their
    touching the object is the pad's body touching, not another link."""
    rng = np.random.default_rng(0)
    lo, hi = np.asarray(hand.lower, float), np.asarray(hand.upper, float)
    q = np.stack([hand.open_configuration(), hand.closed_configuration(0.9), rng.uniform(lo, hi)])
    poses = hand.link_transforms_batch(q)
    out = np.zeros((len(finger_links), lmax), dtype=bool)
    for f, links in enumerate(finger_links):
        pad = poses[:, hand.link_index(links[pad_local[f]])]
        inv = np.linalg.inv(pad)
        for l, name in enumerate(links):
            rel = inv @ poses[:, hand.link_index(name)]
            out[f, l] = bool(np.allclose(rel, rel[0], atol=1e-9))
    return out


def _bound(centers: np.ndarray, radii: np.ndarray) -> tuple[np.ndarray, float]:
    """A sphere (centre (3,), radius) holding spheres (k, 3), (k,)."""
    mid = 0.5 * (centers.min(0) + centers.max(0))
    return mid, float((np.linalg.norm(centers - mid, axis=1) + radii).max())


def _overlap_pairs(hand, finger_links, rest: np.ndarray) -> np.ndarray:
    """Link pairs of different fingers checked for overlap: every pair except those whose
    spheres already overlap with the hand open (neighbours by construction, e.g. knuckles)."""
    out = []
    for f1 in range(len(finger_links)):
        for f2 in range(f1 + 1, len(finger_links)):
            for l1, a in enumerate(finger_links[f1]):
                for l2, b in enumerate(finger_links[f2]):
                    ca, cb = hand.spheres.get(a), hand.spheres.get(b)
                    if ca is None or cb is None or not len(ca.radii) or not len(cb.radii):
                        continue
                    pa = rest[hand.link_index(a)]
                    pb = rest[hand.link_index(b)]
                    (a_c, a_r), (b_c, b_r) = search_spheres(ca), search_spheres(cb)
                    wa = a_c @ pa[:3, :3].T + pa[:3, 3]
                    wb = b_c @ pb[:3, :3].T + pb[:3, 3]
                    gap = np.linalg.norm(wa[:, None] - wb[None], axis=2) - np.add.outer(a_r, b_r)
                    if gap.min() > 0.0:
                        out.append((f1, l1, f2, l2))
    return np.array(out, dtype=np.int64).reshape(-1, 4)


def _opposition_point(hand, z: np.ndarray, face: float) -> np.ndarray | None:
    """Where the pads meet (3,) in the root frame, or None.

    Seeded postures (pre-shape joints anywhere in range, every closing joint the same
    fraction of the way): among those with every pad in front of the palm face, the
    :data:`OPPOSITION_SHARE` whose pads are nearest the thumb's (all pads' mean pairwise
    distance without a thumb); their pads' mean. The object is held there, so the grasp
    centre lies under it: for long fingers, over the palm rather than out along the open
    fingers (where the half-closed pads are).
    """
    rng = np.random.default_rng(0)
    n = OPPOSITION_SAMPLES
    lo, hi = np.asarray(hand.lower, float), np.asarray(hand.upper, float)
    q = np.tile(np.clip(0.0, lo, hi), (n, 1))
    fraction = rng.random(n)
    for finger in hand.fingers:
        for joint, sense in zip(finger.joints, finger.closing):
            j = hand.actuated_joints.index(joint)
            if sense == 0:
                q[:, j] = rng.uniform(lo[j], hi[j], n)
            else:
                target = hi[j] if sense > 0 else lo[j]
                q[:, j] = q[:, j] + fraction * (target - q[:, j])
    poses = hand.link_transforms_batch(q)
    pads = np.stack([poses[:, hand.link_index(f.pad_link), :3, :3] @ np.asarray(f.pad_center, float)
                     + poses[:, hand.link_index(f.pad_link), :3, 3] for f in hand.fingers], axis=1)  # (n, F, 3)
    thumb = [i for i, f in enumerate(hand.fingers) if f.is_thumb]
    if thumb and len(hand.fingers) > 1:
        others = [i for i in range(len(hand.fingers)) if i != thumb[0]]
        spread = np.linalg.norm(pads[:, others] - pads[:, thumb[0]:thumb[0] + 1], axis=2).mean(axis=1)
    else:
        spread = np.linalg.norm(pads[:, :, None] - pads[:, None], axis=3).mean(axis=(1, 2))
    spread[(pads @ z).min(axis=1) <= face] = np.inf
    keep = np.argsort(spread)[:max(1, int(OPPOSITION_SHARE * n))]
    keep = keep[np.isfinite(spread[keep])]
    if not len(keep):
        return None
    return pads[keep].mean(axis=(0, 1))


def standoff_range(reach: float, front: float) -> tuple[float, bool]:
    """The standoff's upper bound (m) and whether the hand closes ahead of its reach: the
    pads' reach (``REACH_FRACTION`` of it, within [STANDOFF_MIN, STANDOFF_MAX]), or where
    the open pads stand in front of the palm face (``front``) when that is further: a
    claw's fingers extend along the palm normal and close in front of their own tips, far
    beyond the reach of a hand's."""
    bound = float(np.clip(REACH_FRACTION * reach, STANDOFF_MIN, STANDOFF_MAX))
    return max(bound, float(front)), bool(front > bound)


def _palm_frame(hand) -> tuple[np.ndarray, np.ndarray, float, float]:
    """The palm frame (x toward the fingers, z the palm normal) in the root frame, the
    grasp centre on the palm face (under where the pads meet: :func:`_opposition_point`),
    the pads' reach (m) and the nearest open pad's height in front of the palm face (m)."""
    z = np.asarray(hand.palm_normal, float)
    z = z / np.linalg.norm(z)
    fractions = (0.0, 0.25, 0.5, 0.75, 1.0)
    poses = hand.link_transforms_batch(np.stack([hand.closed_configuration(s) for s in fractions]))
    pads = np.stack([[poses[k, hand.link_index(f.pad_link), :3, :3] @ f.pad_center
                      + poses[k, hand.link_index(f.pad_link), :3, 3] for f in hand.fingers]
                     for k in range(len(fractions))])  # (S, F, 3)
    toward = pads[0].mean(0) - (pads[0].mean(0) @ z) * z
    if np.linalg.norm(toward) < 1e-6:
        toward = np.cross(z, [1.0, 0, 0] if abs(z[0]) < 0.9 else [0, 1.0, 0])
    x = toward / np.linalg.norm(toward)
    y = np.cross(z, x)
    # The palm face: the root link's own spheres (a forearm behind the palm does not count).
    cover = hand.spheres.get(hand.root_link)
    if cover is not None and len(cover.radii):
        pose = poses[0, hand.link_index(hand.root_link)]
        centers = np.asarray(cover.centers, float) @ pose[:3, :3].T + pose[:3, 3]
        face = float((centers @ z + np.asarray(cover.radii)).max())
    else:
        face = 0.0
    lateral = _opposition_point(hand, z, face)
    if lateral is None:  # no posture puts every pad in front of the palm: the half-closed pads
        lateral = pads[2].mean(0)
    lateral = lateral - (lateral @ z) * z
    # Reach: half the longest finger (its first link's origin to its pad, open).
    bases = [poses[0, hand.link_index(hand.finger_links(f)[0]), :3, 3] for f in hand.fingers]
    reach = 0.5 * float(max(np.linalg.norm(pads[0, i] - b) for i, b in enumerate(bases)))
    front = float((pads[0] @ z).min()) - face
    return np.stack([x, y, z], axis=1), lateral + face * z, reach, front
