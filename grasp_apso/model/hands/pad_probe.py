"""Where a fingertip link first touches what its finger closes on: the pad, found by closing.

:func:`.pads.find_pad` places the pad geometrically (the farthest point of the tip link
toward the finger's closing motion at the open hand, in its distal part). For a tip link
that is long, angled or flat (a Barrett or LEAP fingertip, a coupled two-joint tip) the
part that meets an object first when the finger closes can lie a centimetre away, and a
precision grasp then never touches at its pad. :func:`probe_pad` finds it by closing the
finger: spheres of a few sizes (:data:`PROBE_RADII`) are put in the way of the tip link's
far end (:func:`_far_end`: the middle of a wide tip, not its corner) at points along its
closing path (ahead along its motion, also tilted toward and away from the palm normal);
the finger closes (its closing joints from the open posture to
their closing limits, couplings applied, the other fingers open) until one of its links
enters the sphere. When the tip link is the first link touched for most probes, the pad is
the point of its surface nearest the mean of its first-touch points.

Pure numpy on surface samples of the links' exact collision geometry (no search kernels,
no object): about a second per hand (0.1-0.2 s a finger). The result is kept on disk under
``<cache root>/hand_pads/`` (:func:`grasp_apso.cache.disk_arrays`), keyed by everything it is
computed from (the chain links' collision geometry, their poses along the closing, the palm
normal, this module's settings, :data:`PROBE_VERSION` and the numpy and trimesh versions),
so that a command-line run, a restarted node or a batch worker reads a hand's pads back
instead of probing them again.
"""

from __future__ import annotations

import hashlib

import numpy as np
import trimesh

from ...cache import disk_arrays
from .cover_store import hash_geometry
from .pads import outer_surface_samples

__all__ = ["probe_pad", "PROBE_RADII", "PROBE_VERSION"]

#: Bump when :func:`probe_pad` (or the surface sampling it uses) changes what it returns for
#: the same input. 2: the surface samples of a link with a folded cavity shell
#: (:func:`.geometry._union_parts`).
PROBE_VERSION = 2


#: Probe sphere radii (m): small, middling and large objects.
PROBE_RADII = (0.015, 0.03, 0.06)
#: Probe directions: the far end's motion tilted by these multiples of the palm normal.
PROBE_TILTS = (0.0, 0.5, -0.5)
#: Closing steps over the joints' closing range, and every how many steps a probe is put.
STEPS = 61
PROBE_EVERY = 4
#: Surface sample spacing (m) and count per link.
SPACING = 2e-3
MAX_SAMPLES = 1200
#: The tip link must be the first link touched in at least this share of the probes that
#: touched anything, and at least MIN_HITS times; else the geometric pad stays.
MIN_SHARE = 0.5
MIN_HITS = 6
#: Probes per block of the distance computation (bounds its memory to a few MB).
CHUNK = 32
#: The far end's path is planar when its least spread across is under this share of its
#: largest (:func:`_far_end`).
PLANAR = 0.05
#: A far end this far (m) across the finger from the middle of its width is a corner of
#: a wide tip, not where its pad is (a human fingertip is about 16 mm wide): the probes go
#: in the way of the middle instead. Nearer, the far end stays: of 31 hands measured (the
#: test hands, the published hands of docs/hands.md) only those two grippers' tips and the
#: thumb of dex-urdf's Allegro with tactile pads lie farther off (the others within 9 mm).
OFF_MIDDLE = 0.01


def _outer_samples(geoms, rng: np.random.Generator) -> np.ndarray:
    return outer_surface_samples(geoms, SPACING, rng, MAX_SAMPLES)[0]


def _closing_path(hand, joints, closing) -> np.ndarray:
    """(STEPS, n) postures: the finger's closing joints from the open posture to their
    closing limits, every other joint at the open posture."""
    lower, upper = np.asarray(hand.lower, float), np.asarray(hand.upper, float)
    q_open = np.clip(0.0, lower, upper)
    path = np.tile(q_open, (STEPS, 1))
    s = np.linspace(0.0, 1.0, STEPS)
    for joint, sense in zip(joints, closing):
        if sense == 0:
            continue
        j = hand.actuated_joints.index(joint)
        target = upper[j] if sense > 0 else lower[j]
        path[:, j] = q_open[j] + s * (target - q_open[j])
    return path


def _far_end(surface: np.ndarray, tip: np.ndarray) -> np.ndarray:
    """The far end (3,) of a tip link, link frame: its surface sample farthest from the
    link's origin; when that lies more than :data:`OFF_MIDDLE` across the finger from the
    middle of the link's width, moved to the middle. Across: the normal of the plane the
    closing moves it in (the joints' axes parallel; else the sample stays). On a wide, flat
    fingertip the farthest sample is a corner, and the probes in its way put the pad at
    that corner: 11 mm off the middle of the Robotiq three-finger gripper's 31 mm tips,
    10 mm on the Schunk SDH's, where a mirrored finger's pad then faces out of the grasp.
    ``surface`` (K, 3) link frame; ``tip`` (S, 4, 4) the link's poses along the closing
    (root frame)."""
    far = surface[np.argmax(np.linalg.norm(surface, axis=1))]
    path = np.einsum("sij,j->si", tip[:, :3, :3], far) + tip[:, :3, 3]
    _, spread, axes = np.linalg.svd(path - path.mean(axis=0), full_matrices=False)
    if spread[0] < 1e-6 or spread[2] > PLANAR * spread[0]:  # no motion, or not in a plane
        return far
    across = tip[0, :3, :3].T @ axes[2]  # the plane's normal in the link frame
    width = surface @ across
    off = 0.5 * (width.max() + width.min()) - far @ across
    return far + off * across if abs(off) > OFF_MIDDLE else far


def probe_pad(hand, tip_link: str, joints, closing, palm_normal) -> np.ndarray | None:
    """The pad centre (3,) on ``tip_link``'s surface, link frame, m; None when closing does
    not tell (the tip link rarely touches first, or the finger does not move).

    hand : a :class:`~.model.HandModel` with kinematics and collision geometry (fingers
        not needed). joints, closing : the finger's actuated joints and closing senses.
    palm_normal : (3,) root frame.
    """
    if not hand.collision.get(tip_link) or not any(closing):
        return None
    path = hand.chain(tip_link)
    links = [l for l in path[path.index(hand.root_link) + 1:] if hand.collision.get(l)]
    poses = hand.link_transforms_batch(_closing_path(hand, joints, closing))  # (S, L, 4, 4)
    normal = np.asarray(palm_normal, float) / np.linalg.norm(palm_normal)

    def probe() -> dict[str, np.ndarray]:
        pad = _probe(hand, links, tip_link, poses, normal)
        return {"pad": np.zeros(0) if pad is None else pad}  # (0,): the probe did not tell

    def check(arrays) -> bool:
        pad = arrays.get("pad")
        return pad is not None and pad.shape in ((0,), (3,)) and bool(np.all(np.isfinite(pad)))

    pad = np.asarray(disk_arrays("hand_pads", _key(hand, links, tip_link, poses, normal), probe, check)["pad"],
                     dtype=float)
    return pad if len(pad) else None


def _key(hand, links, tip_link: str, poses: np.ndarray, normal: np.ndarray) -> str:
    """sha256 of what :func:`_probe` computes from."""
    settings = (PROBE_RADII, PROBE_TILTS, STEPS, PROBE_EVERY, SPACING, MAX_SAMPLES, MIN_SHARE, MIN_HITS, CHUNK,
                PLANAR, OFF_MIDDLE)
    # trimesh draws the surface samples (numpy's generator): another version may draw others
    versions = (np.__version__, trimesh.__version__)
    digest = hashlib.sha256(f"v{PROBE_VERSION};{versions!r};{settings!r};{links!r};{tip_link!r}".encode())
    hash_geometry(digest, {l: hand.collision[l] for l in links})
    index = [hand.link_index(l) for l in links]
    digest.update(np.ascontiguousarray(poses[:, index], dtype=np.float64).tobytes())
    digest.update(np.ascontiguousarray(normal, dtype=np.float64).tobytes())
    return digest.hexdigest()


def _probe(hand, links, tip_link: str, poses: np.ndarray, normal: np.ndarray) -> np.ndarray | None:
    """:func:`probe_pad` computed: ``links`` the tip's chain links with collision geometry,
    ``poses`` (S, L, 4, 4) every link's along the closing, ``normal`` (3,) unit."""
    rng = np.random.default_rng(0)
    samples = {l: _outer_samples(hand.collision[l], rng) for l in links}
    world = {l: np.einsum("sij,kj->ski", poses[:, hand.link_index(l), :3, :3], samples[l])
             + poses[:, hand.link_index(l), None, :3, 3] for l in links}  # (S, K, 3)
    tip = poses[:, hand.link_index(tip_link)]
    far = _far_end(samples[tip_link], tip)
    far_path = np.einsum("sij,j->si", tip[:, :3, :3], far) + tip[:, :3, 3]  # (S, 3)
    centers, radii = [], []
    for k in range(PROBE_EVERY, STEPS - 1, PROBE_EVERY):
        motion = far_path[k + 1] - far_path[k - 1]
        if np.linalg.norm(motion) < 1e-9:
            continue
        motion /= np.linalg.norm(motion)
        for tilt in PROBE_TILTS:
            way = motion + tilt * normal
            way /= np.linalg.norm(way)
            for radius in PROBE_RADII:
                centers.append(far_path[k] + radius * way)
                radii.append(radius)
    if not centers:
        return None
    centers, radii = np.asarray(centers), np.asarray(radii)
    m = len(centers)
    # Per probe and link: the first closing step at which the link is inside the sphere.
    first = np.full((m, len(links)), STEPS, dtype=np.int64)
    for i, l in enumerate(links):
        w = world[l].reshape(-1, 3)  # (S K, 3)
        w2 = (w * w).sum(axis=1)
        for a in range(0, m, CHUNK):  # |w - c|^2 <= r^2, a block of probes at a time
            c = centers[a:a + CHUNK]
            d2 = w2[:, None] - 2.0 * (w @ c.T) + (c * c).sum(axis=1)[None]  # (S K, M')
            inside = (d2 <= radii[a:a + CHUNK] ** 2).reshape(STEPS, -1, len(c)).any(axis=1).T  # (M', S)
            first[a:a + CHUNK, i] = np.where(inside.any(axis=1), inside.argmax(axis=1), STEPS)
    step = first.min(axis=1)
    touched = (step > 0) & (step < STEPS)  # a probe already inside the open finger is not in its way
    tip_i = links.index(tip_link)
    alone = (first[:, tip_i] == step) & ((first == step[:, None]).sum(axis=1) == 1)
    hits = []
    for p in np.flatnonzero(touched & alone):
        w = world[tip_link][step[p]]
        gap = np.linalg.norm(w - centers[p], axis=1) - radii[p]
        hits.append(samples[tip_link][gap <= max(0.0, float(gap.min())) + 1e-9].mean(axis=0))
    touched = int(touched.sum())
    if len(hits) < MIN_HITS or len(hits) < MIN_SHARE * touched:
        return None
    mean = np.mean(hits, axis=0)
    surface = samples[tip_link]
    return surface[np.argmin(np.linalg.norm(surface - mean, axis=1))].copy()
