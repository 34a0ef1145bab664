"""The scene check of a general hand's decoding: its collision spheres against the
Scene's planes and obstacles (vectorised numpy over sphere groups).

At the grasp (the grasp posture at the root pose) and along the approach (the open
pre-shape at the root pose moved back along the palm normal by
:data:`APPROACH_FRACTIONS` of the approach distance), the least of ``scene distance -
radius - clearance`` over the hand's spheres. Groups of spheres are checked by their
bounding sphere first; only groups within the clearance are resolved sphere by sphere.
"""

from __future__ import annotations

import numpy as np

__all__ = ["scene_margins", "APPROACH_FRACTIONS"]

#: Where along the approach the open hand is checked (0 = at the grasp pose).
APPROACH_FRACTIONS = (0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0)


def _group_owners(t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Finger groups: (G,) group index, finger and finger-local link of each."""
    g, f, l = [], [], []
    for fi in range(t.n_fingers):
        for li in range(int(t.n_links[fi])):
            start, count = int(t.g_start[fi, li]), int(t.g_count[fi, li])
            g.extend(range(start, start + count))
            f.extend([fi] * count)
            l.extend([li] * count)
    return np.array(g, np.int64), np.array(f, np.int64), np.array(l, np.int64)


def _group_poses(t, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every group's link pose (P, G, 4, 4) in the root frame and the group indices (G,)."""
    g, f, l = _group_owners(t)
    finger = poses[:, f, l]
    palm = np.broadcast_to(t.palm_pose, (len(poses),) + t.palm_pose.shape)
    return np.concatenate([finger, palm], axis=1), np.concatenate([g, t.palm_groups])


def scene_margins(model, root: np.ndarray, grasp_poses: np.ndarray, open_poses: np.ndarray) -> np.ndarray:
    """Least ``distance - radius - clearance`` (m) of the hand to the scene, per particle (P,).

    root : (P, 4, 4) object frame; grasp_poses, open_poses : (P, F, Lmax, 4, 4) the finger
    links in the root frame at the grasp posture and the pre-shape.
    """
    t, scene, clearance = model.tables, model.scene, model.scene_clearance
    rot, trans = root[:, :3, :3], root[:, :3, 3]
    approach = rot @ t.basis[:, 2]
    best = np.full(len(root), np.inf)
    postures = [(grasp_poses, 0.0)] + [(open_poses, k * model.approach_distance) for k in APPROACH_FRACTIONS]
    for poses, back in postures:
        link, groups = _group_poses(t, poses)
        centre = np.einsum("pgij,gj->pgi", link[..., :3, :3], t.grp_center[groups]) + link[..., :3, 3]
        world = np.einsum("pij,pgj->pgi", rot, centre) + (trans - back * approach)[:, None]
        margin = scene.signed_distance(world.reshape(-1, 3)).reshape(world.shape[:2]) - t.grp_radius[groups] - clearance
        near_p, near_g = np.nonzero(margin < 0.0)
        best = np.minimum(best, np.where(margin < 0.0, np.inf, margin).min(axis=1))
        if near_p.size:
            best = np.minimum(best, _sphere_margins(t, scene, clearance, rot, trans - back * approach, link,
                                                    groups, near_p, near_g, len(root)))
    return best


def _sphere_margins(t, scene, clearance, rot, trans, link, groups, near_p, near_g, count) -> np.ndarray:
    """The groups (near_p, near_g) resolved sphere by sphere: least margin per particle (P,)."""
    g = groups[near_g]
    counts = t.grp_count[g]
    owner = np.repeat(np.arange(len(g)), counts)
    first = np.cumsum(counts) - counts
    sphere = t.grp_start[g][owner] + np.arange(counts.sum()) - first[owner]
    pose = link[near_p[owner], near_g[owner]]
    local = np.einsum("nij,nj->ni", pose[:, :3, :3], t.sph_center[sphere]) + pose[:, :3, 3]
    p = near_p[owner]
    world = np.einsum("nij,nj->ni", rot[p], local) + trans[p]
    margin = scene.signed_distance(world) - t.sph_radius[sphere] - clearance
    out = np.full(count, np.inf)
    np.minimum.at(out, p, margin)
    return out
