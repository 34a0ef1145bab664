"""What a general hand's selection saw (:func:`grasp_apso.search.any_hand_select.select_any`),
and the reply's message when fewer grasps than asked for come back."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Selection", "SelectionCounts", "shortfall_message", "append_note"]


@dataclass(frozen=True)
class SelectionCounts:
    """What one or more searches' selections saw: ``distinct`` grasps with two or more
    contacts (groups of like wrists:
    :func:`grasp_apso.search.any_hand_select._first_groups`), ``rejected`` by the
    verification (legality, contacts, python-fcl, the scene and the approach) and verified
    but below the class of the others (``fallback``: not force closure, or not robust, next
    to ones that are). The others were not verified: near a grasp verified before them, or
    unable to rank above the grasps verified (no force closure, not robust or not balanced)."""

    distinct: int = 0
    rejected: int = 0
    fallback: int = 0

    def __add__(self, other: "SelectionCounts") -> "SelectionCounts":
        return SelectionCounts(self.distinct + other.distinct, self.rejected + other.rejected,
                               self.fallback + other.fallback)


@dataclass(frozen=True)
class Selection:
    """The outcome of one search's selection next to its grasps: the counts and the best
    grasp's note (e.g. its pads closed onto the surface), for the reply's message."""

    counts: SelectionCounts
    note: str = ""
    unchanged: bool = False  # a later search that added no grasp: the earlier ones stand as they were


def shortfall_message(returned: int, options, counts: SelectionCounts, searches: int) -> str:
    """Why only ``returned`` of the ``options.max_grasps`` grasps asked for come back, from
    the selections' ``counts`` over the plan's ``searches`` ("" when all of them do)."""
    if returned >= options.max_grasps:
        return ""
    searched = "the search" if searches == 1 else f"{searches} searches"
    fallback = ""
    if counts.fallback:
        fallback = (f", {counts.fallback} were not (robust) force closure next to ones that are "
                    + ("(simulated last)" if options.simulate else "(left out)"))
    return (f"{returned} of {options.max_grasps} grasps: {searched} found {counts.distinct} distinct grasps with "
            f"two or more contacts (wrists the orientation or position gap apart); of those verified, "
            f"{counts.rejected} failed (legality, contacts, the scene and the approach){fallback}; the others lie "
            "near a verified one or rank lower (no force closure, not robust or not balanced); more particles or "
            "iterations find more")


def append_note(message: str, note: str) -> str:
    """``message`` and ``note`` joined by "; " (either may be empty)."""
    return f"{message}; {note}" if message and note else message or note
