"""``load_hand(path, config=None) -> HandModel``: any hand from its description file.

``.urdf`` (yourdfpy), ``.xml`` (MJCF, MuJoCo's compiler), ``.yaml``/``.yml`` (the project's
own description: the paper's hand, turned into its URDF in memory by
:func:`grasp_apso.model.urdf.hand_to_urdf`, so the YAML and the generated URDF give the
same model). ``None`` loads the paper's hand shipped in the package.

Models are immutable and built once: cached (the named cache ``hand_model`` of :mod:`grasp_apso.cache`) by
the sha256 of the file's content, its folder (relative meshes) and the config.
Limits: the description file and each collision mesh at most the tunable
``max_hand_file_bytes``.
"""

from __future__ import annotations

import hashlib
from dataclasses import replace
from pathlib import Path
from types import MappingProxyType

import numpy as np

from ... import tunables
from ...cache import approximate_nbytes, cached
from ...errors import HandDescriptionError
from .config import HandConfig, read_config
from .derive import PALM_NORMAL_FRACTION, ancestors, derive_fingers, find_root, finger_label, finger_tips, subtree
from .description import RawHand, kinematics, lagging_couplings
from .model import Finger, HandModel, readonly
from .pad_cover import COVERED, covering_link

__all__ = ["load_hand", "hand_from_raw", "SUFFIXES"]

SUFFIXES = {".urdf": "URDF", ".xml": "MJCF", ".yaml": "YAML", ".yml": "YAML"}
def _hand_bytes(hand: HandModel) -> int:
    """Approximate memory of a hand: its meshes and spheres dominate."""
    return approximate_nbytes([dict(hand.collision), dict(hand.spheres), hand.origins])


#: Seed of the sphere covers (deterministic per hand).
_SEED = 20
#: A fingertip link with less collision geometry than this (m, bounding-box diagonal) is
#: noted: no real fingertip is that small, a frame marker or a sensor is.
_SMALL_TIP = 0.008
#: A pad this deep (m) inside the palm's collision geometry with its finger 70 % of the way
#: to its closing limits (``PALM_NORMAL_FRACTION``, as the derivation closes it for the palm
#: normal) is noted: the finger's limits let it close through the palm. Measured 70 % closed
#: on 33 hands: no pad of a hand with sound limits lies deeper than 4.4 mm (menagerie's LEAP
#: thumb); the Robotiq three-finger URDF whose phalanges all range over [0, pi] puts them
#: 15-18 mm inside.
_CLOSED_IN_PALM = 0.01


def _read(path: Path, limit: int) -> bytes:
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise HandDescriptionError(f"hand_description: cannot read {path}: {exc.strerror}",
                                   field="hand_description") from None
    if size > limit:
        raise HandDescriptionError(f"hand_description: {path.name} is {size} bytes, over the limit of {limit} "
                                   "(tunable max_hand_file_bytes)", field="hand_description")
    try:
        return path.read_bytes()
    except OSError as exc:
        raise HandDescriptionError(f"hand_description: cannot read {path}: {exc.strerror}",
                                   field="hand_description") from None


def load_hand(path: str | Path | None = None, config: str | Path | dict | None = None,
              spheres: bool = True, max_file_bytes: int | None = None) -> HandModel:
    """Load a hand and derive its grasp semantics.

    Parameters
    ----------
    path : .urdf, .xml (MJCF) or .yaml file; None = the paper's hand.
    config : override config (YAML path or dict, see :mod:`.config`), optional.
    spheres : cover every link with spheres (False: ``spheres`` is empty; quicker).
    max_file_bytes : size limit of the file and each collision mesh (default: the
        tunable ``max_hand_file_bytes``).

    Raises
    ------
    HandDescriptionError
        Naming the element at fault (file type, joint, link, mesh, config key).
    """
    from ..hand import default_hand_path

    path = default_hand_path() if path is None or str(path) == "" else Path(path)
    kind = SUFFIXES.get(path.suffix.lower())
    if kind is None and path.suffix.lower() == ".xacro":  # how most ROS hand packages ship
        from .urdf_loader import XACRO_HINT

        raise HandDescriptionError(f"hand_description: {path.name} is a xacro file, not a URDF: {XACRO_HINT}",
                                   field="hand_description")
    if kind is None:
        raise HandDescriptionError(f"hand_description: {path.name} is not a URDF (.urdf), MJCF (.xml) or "
                                   "YAML (.yaml) file", field="hand_description")
    limit = int(tunables.default("max_hand_file_bytes") if max_file_bytes is None else max_file_bytes)
    content = _read(path, limit)
    cfg = read_config(config)
    source_hash = hashlib.sha256(content + b"\0" + cfg.canonical.encode()).hexdigest()
    key = (source_hash, str(path.resolve().parent), bool(spheres), limit)
    return cached("hand_model", key, lambda: replace(_build(path, kind, content, cfg, source_hash, limit, spheres),
                                                     source_path=str(path.resolve())), nbytes=_hand_bytes)


def _build(path: Path, kind: str, content: bytes, cfg: HandConfig, source_hash: str, limit: int,
           spheres: bool) -> HandModel:
    if kind == "MJCF":
        from .mjcf_loader import read_mjcf

        raw = read_mjcf(path, limit)
    else:
        from .urdf_loader import read_urdf

        if kind == "YAML":
            from ..hand import load_hand as load_paper_hand
            from ..urdf import hand_to_urdf

            text = hand_to_urdf(load_paper_hand(path))
        else:
            try:
                text = content.decode("utf-8")
            except UnicodeDecodeError:
                raise HandDescriptionError(f"hand_description: {path.name} is not UTF-8 text",
                                           field="hand_description") from None
        raw = read_urdf(text, path.parent, limit, path.name)
    return hand_from_raw(raw, cfg, source_hash, spheres)


def hand_from_raw(raw: RawHand, cfg: HandConfig, source_hash: str = "", spheres: bool = True) -> HandModel:
    """The HandModel of a loaded description, with the derivation and ``cfg`` applied.

    Followers with play (a limited tendon's coupling) follow the edge of it that the
    closing drags them along (:func:`.description.lagging_couplings`): which edge depends
    on the leaders' closing senses, so such a hand's kinematics and semantics are derived
    again with the couplings moved there."""
    notes = list(raw.notes)  # (the derivation adds to raw's)
    bare, fingers, normal = _derived(raw, cfg, source_hash)
    lagging = lagging_couplings(raw.couplings, {j: s for f in fingers for j, s in zip(f.joints, f.closing)})
    if lagging is not None:
        raw = replace(raw, couplings=lagging[0], notes=notes + lagging[1])
        bare, fingers, normal = _derived(raw, cfg, source_hash)
    covers = _spheres(bare, cfg) if spheres else {}
    return replace(bare, fingers=fingers, palm_normal=readonly(normal), spheres=MappingProxyType(covers),
                   notes=tuple(raw.notes) + bare.notes)


def _derived(raw: RawHand, cfg: HandConfig, source_hash: str) -> tuple[HandModel, tuple, np.ndarray]:
    """The hand's kinematics (a HandModel without fingers, its ``notes`` the derivation's),
    its fingers and its palm normal."""
    names = [link.name for link in raw.links]
    for link in raw.links:
        for geom in link.geoms:
            geom.check_hand_part()
    root = cfg.get("root_link") or find_root(raw)
    if root not in names:
        raise HandDescriptionError(f"hand_config.root_link: {root!r} is not a link", field="hand_config.root_link")
    held = _outside(raw, root)
    for joint in cfg.get("hold", {}):
        if joint not in held:
            raise HandDescriptionError(f"hand_config.hold.{joint}: not a joint above the root link {root} "
                                       "(or beside it, outside the hand)", field="hand_config.hold")
    kin = kinematics(raw, held, cfg.get("hold", {}))
    root_index = kin.links.index(root)
    bare = HandModel(
        name=raw.name, root_link=root, actuated_joints=kin.actuated, lower=kin.lower, upper=kin.upper,
        fingers=(), palm_normal=readonly(np.zeros(3)), links=kin.links, link_parents=kin.parents,
        collision=MappingProxyType({link.name: tuple(link.geoms) for link in raw.links if link.geoms}),
        spheres=MappingProxyType({}), couplings=kin.couplings, held_joints=MappingProxyType(dict(kin.held)),
        notes=(), source_hash=source_hash,
        joint_names=kin.joint_names, origins=kin.origins, motions=kin.motions, full_matrix=kin.matrix,
        full_offset=kin.offset, root_inverse=readonly(np.eye(4)))
    top = bare.link_transforms_batch(np.zeros((1, len(kin.actuated))))[0]
    bare = replace(bare, root_inverse=readonly(np.linalg.inv(top[root_index])))
    tips, labels = _fingers(raw, root, cfg)
    overrides = {"closing": cfg.get("closing", {}), "palm_normal": cfg.get("palm_normal")}
    if "thumb" in cfg:
        if cfg["thumb"] not in labels:
            raise HandDescriptionError(f"hand_config.thumb: {cfg['thumb']!r} is not a finger ({', '.join(labels)})",
                                       field="hand_config.thumb")
        overrides["thumb"] = tips[labels.index(cfg["thumb"])]
    for joint in overrides["closing"]:
        if joint not in kin.actuated:
            raise HandDescriptionError(f"hand_config.closing.{joint}: not an actuated joint",
                                       field="hand_config.closing")
    semantics, normal, notes = derive_fingers(bare, tips, overrides)
    fingers = tuple(_finger(bare, label, sem, cfg, normal) for label, sem in zip(labels, semantics))
    hand = replace(bare, fingers=fingers)
    notes.extend(_small_tips(hand) + _closing_into_palm(hand) + _covered_pads(hand, cfg))
    return replace(bare, notes=tuple(notes)), fingers, normal


def _small_tips(hand) -> list[str]:
    """Notes for the fingers whose tip link has less than :data:`_SMALL_TIP` of collision
    geometry (a frame marker or a sensor left where the fingertip's geometry is missing)."""
    notes = []
    for finger in hand.fingers:
        span = _span(hand.collision[finger.tip_link])
        if span < _SMALL_TIP:
            notes.append(f"finger {finger.name}: its tip link {finger.tip_link} has only {1000 * span:.1f} mm of "
                         "collision geometry (a frame marker or a sensor, the fingertip's own geometry missing?): "
                         "give the fingertip link in hand_config.fingers if this is not it")
    return notes


def _closing_into_palm(hand) -> list[str]:
    """Notes for the fingers whose pads lie more than :data:`_CLOSED_IN_PALM` inside the
    root link's collision geometry ``PALM_NORMAL_FRACTION`` of the way to their closing
    limits: limits that let a finger close through the palm (a file's error) mislead the
    derived palm normal."""
    from .spheres import union_signed_distance

    palm = hand.collision.get(hand.root_link)
    if not palm:
        return []
    poses = hand.link_transforms_batch(hand.closed_configuration(PALM_NORMAL_FRACTION)[None])[0]
    into_root = np.linalg.inv(poses[hand.link_index(hand.root_link)])
    notes = []
    for finger in hand.fingers:
        pose = into_root @ poses[hand.link_index(finger.pad_link)]
        pad = pose[:3, :3] @ np.asarray(finger.pad_center, float) + pose[:3, 3]
        depth = -float(union_signed_distance(palm, pad[None])[0])
        if depth > _CLOSED_IN_PALM:
            notes.append(f"finger {finger.name}: {100 * PALM_NORMAL_FRACTION:.0f} % of the way to its closing "
                         f"limits its pad lies {1000 * depth:.0f} mm inside the palm ({hand.root_link}): are its "
                         "joint limits right? The palm normal is derived from the fingers closed that far (give "
                         "palm_normal in hand_config if the limits are)")
    return notes


def _span(geoms) -> float:
    """The diagonal of the bounding box of a link's collision geometry (m)."""
    corners = np.concatenate([g.bounds for g in geoms])
    return float(np.linalg.norm(np.ptp(corners, axis=0)))


def _fingers(raw: RawHand, root: str, cfg: HandConfig) -> tuple[list[str], list[str]]:
    names = [link.name for link in raw.links]
    if "fingers" in cfg:
        labels, tips = list(cfg["fingers"]), list(cfg["fingers"].values())
        by_name = {link.name: link for link in raw.links}
        for label, tip in zip(labels, tips):
            if tip not in names:
                raise HandDescriptionError(f"hand_config.fingers.{label}: {tip!r} is not a link",
                                           field="hand_config.fingers")
            if not by_name[tip].geoms:
                raise HandDescriptionError(f"hand_config.fingers.{label}: link {tip!r} has no collision geometry",
                                           field="hand_config.fingers")
            if root not in ancestors(raw, tip):
                raise HandDescriptionError(f"hand_config.fingers.{label}: link {tip!r} is not below the root "
                                           f"link {root}", field="hand_config.fingers")
    else:
        tips = finger_tips(raw, root)
        by_name = {link.name: link for link in raw.links}
        firsts = []
        for tip in tips:
            link = by_name[tip]
            while link.parent != root:
                link = by_name[link.parent]
            firsts.append(link.name)
        labels = finger_label(tips, firsts)
    if len(tips) < 2:
        raise HandDescriptionError(f"hand_description: {len(tips)} finger(s) below {root}; a hand needs at least two",
                                   field="hand_description")
    return tips, labels


def _outside(raw: RawHand, root: str) -> set[str]:
    """The joints the hand holds: those above ``root`` (the root link's own included) and
    those of every link outside its subtree (a humanoid's legs and other arm when the root
    is one palm: they move no finger)."""
    inside = subtree(raw, root)
    by_name = {link.name: link for link in raw.links}
    out = {j.name for j in by_name[root].joints}
    return out | {j.name for link in raw.links if link.name not in inside for j in link.joints}


def _finger(hand: HandModel, label: str, sem, cfg: HandConfig, palm_normal: np.ndarray) -> Finger:
    pad = cfg.get("pads", {}).get(label)
    if pad is not None:
        if pad["link"] not in hand.links:
            raise HandDescriptionError(f"hand_config.pads.{label}.link: {pad['link']!r} is not a link",
                                       field="hand_config.pads")
        finger = Finger(label, sem.tip_link, sem.joints, sem.closing, pad["link"], readonly(pad["center"]),
                        float(pad["radius"]), sem.is_thumb)
        _check_pad_link(hand, finger)
        return finger
    from .pad_probe import probe_pad
    from .pads import find_pad

    at = probe_pad(hand, sem.tip_link, sem.joints, sem.closing, palm_normal)
    center, radius = find_pad(hand.collision[sem.tip_link], sem.palmar, sem.distal, at=at)
    cover = covering_link(hand, sem.tip_link, center)
    if cover is None:
        return Finger(label, sem.tip_link, sem.joints, sem.closing, sem.tip_link, readonly(center), float(radius),
                      sem.is_thumb)
    # a skin or cover fixed over the pad is what touches: the pad is on it, where the
    # pad's normal leaves it (the directions turned into its frame)
    name, point, _, pose = cover
    turn = pose[:3, :3].T
    center, radius = find_pad(hand.collision[name], turn @ sem.palmar, turn @ sem.distal, at=point)
    return Finger(label, sem.tip_link, sem.joints, sem.closing, name, readonly(center), float(radius), sem.is_thumb)


def _check_pad_link(hand: HandModel, finger: Finger) -> None:
    """Refuse a ``hand_config.pads`` link that the finger does not move (a link of another
    finger or of the palm: the pad must move with the fingertip)."""
    links = hand.finger_links(finger)
    if finger.pad_link not in links:
        raise HandDescriptionError(
            f"hand_config.pads.{finger.name}.link: {finger.pad_link!r} does not move with finger {finger.name} "
            f"(its links: {', '.join(links)}); give its tip link {finger.tip_link!r} or a link fixed to it",
            field=f"hand_config.pads.{finger.name}")


def _covered_pads(hand, cfg: HandConfig) -> list[str]:
    """Notes for the fingers whose pad moved onto a link covering it (:mod:`.pad_cover`)."""
    return [f"finger {f.name}: a link of its tip link {f.tip_link}'s body covers the pad there by more than "
            f"{1000 * COVERED:.0f} mm: the pad is on {f.pad_link} (give hand_config.pads.{f.name} if it is not)"
            for f in hand.fingers if f.pad_link != f.tip_link and f.name not in cfg.get("pads", {})]


def _spheres(hand: HandModel, cfg: HandConfig) -> dict:
    from .cover_store import covers_from_disk
    from .spheres import cover_link

    tolerance = cfg.get("sphere_tolerance", 0.002)
    kwargs = {"max_spheres": cfg["max_spheres"]} if "max_spheres" in cfg else {}
    if cfg.get("capsules"):
        kwargs["capsules"] = True
    settings = {"tolerance": float(tolerance), "seed": _SEED, **kwargs}
    return covers_from_disk(hand.collision, settings, lambda link: cover_link(
        hand.collision[link], tolerance, np.random.default_rng(_SEED), **kwargs))
