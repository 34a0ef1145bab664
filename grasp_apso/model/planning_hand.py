"""The hand a node, a command or a batch plans with, chosen by its description file.

:func:`load_planning_hand` is the one place that turns the ``hand_description`` /
``hand_config`` pair (node parameters, ``--hand`` / ``--hand-config`` options) into what
:func:`grasp_apso.search.planner.plan` takes:

- no description or a ``.yaml`` / ``.yml``: the paper's hand
  (:class:`grasp_apso.model.hand.HandModel`, today's path);
- a ``.urdf`` or ``.xml`` (MJCF): a general :class:`grasp_apso.model.hands.HandModel`
  with its sphere cover, built once (cached by content).

Either way the description (and the config) is checked with the general loader first, so
a bad file stops the caller with a :class:`~grasp_apso.errors.HandDescriptionError` whose
``field`` is ``hand_description`` or ``hand_config``.

The hand's identity, what the grasp database keys on (:class:`PlanningHand`): ``name``
and ``hash`` -- a general hand's ``source_hash`` (sha256 of its description and config),
the paper hand's sha256 of its YAML file.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import GraspApsoError, HandDescriptionError

__all__ = ["PlanningHand", "load_planning_hand", "paper_hand_hash", "is_general_hand", "PAPER_SUFFIXES"]

#: Description suffixes of the paper hand's own format.
PAPER_SUFFIXES = (".yaml", ".yml")


@dataclass(frozen=True)
class PlanningHand:
    """A loaded hand and its identity.

    Attributes
    ----------
    hand : grasp_apso.model.hand.HandModel or grasp_apso.model.hands.HandModel
    name : str
    hash : str -- sha256 hex digest (see the module text)
    path : str -- the description file ("" = the shipped paper hand)
    """

    hand: Any
    name: str
    hash: str
    path: str = ""

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The names a reply's JointState carries (the paper hand: its 18)."""
        if is_general_hand(self.hand):
            return tuple(self.hand.actuated_joints)
        from .hand import JOINT_NAMES

        return JOINT_NAMES


def is_general_hand(hand: Any) -> bool:
    """True for a general :class:`grasp_apso.model.hands.HandModel` (not the paper's)."""
    from .hands.model import HandModel as AnyHand

    return isinstance(hand, AnyHand)


def paper_hand_hash(path: str | Path | None = None) -> str:
    """sha256 of the paper hand's YAML file (None or "" = the shipped one)."""
    from .hand import default_hand_path

    file = default_hand_path() if path is None or str(path) == "" else Path(path)
    try:
        return hashlib.sha256(file.read_bytes()).hexdigest()
    except OSError as exc:
        raise HandDescriptionError(f"hand_description: cannot read {file}: {exc.strerror}",
                                   field="hand_description") from None


def _named(exc: BaseException) -> HandDescriptionError:
    text = str(exc)
    name = "hand_config" if text.startswith("hand_config") else "hand_description"
    if not text.startswith(name):
        text = f"{name}: {text}"
    return HandDescriptionError(text, name)


def load_planning_hand(description: str | Path | None = None, config: str | Path | None = None) -> PlanningHand:
    """The hand to plan with (see the module text); ``""`` or None = the paper's hand.

    Raises
    ------
    HandDescriptionError
        ``field`` ``hand_description`` or ``hand_config``; the file's content is never quoted.
    """
    from .hand import load_hand as load_paper_hand
    from .hands.load import load_hand as load_any_hand

    text = "" if description is None else str(description)
    cfg = None if config is None or str(config) == "" else str(config)
    paper = not text or text.lower().endswith(PAPER_SUFFIXES)
    try:
        general = load_any_hand(text or None, cfg, spheres=not paper)
    except (GraspApsoError, ValueError) as exc:
        raise _named(exc) from None
    if not paper:
        return PlanningHand(general, general.name, general.source_hash, text)
    try:
        hand = load_paper_hand(text or None)
    except (GraspApsoError, ValueError) as exc:
        raise HandDescriptionError(f"hand_description: {exc}", "hand_description") from None
    return PlanningHand(hand, hand.name, paper_hand_hash(text or None), text)
