"""The tunables of decoding a particle (:class:`ContactSettings`, SI units): contact and
penetration tolerances, the palm clearance, the closing sweep's resolution."""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import InputError

@dataclass(frozen=True)
class ContactSettings:
    """Tunables of decoding (SI units).

    Attributes
    ----------
    tolerance : float, m
        A fingertip pad within this distance of the surface is in contact; a finger
        deeper than this into the object at its pre-shape is blocked.
    max_penetration : float, m
        A link sphere deeper than this into the object after closing makes the particle
        illegal (closing stops at the surface, so only static parts, the knuckles, can).
    clearance : float, m
        Gap between the palm face and the object for the computed wrist position; the
        knuckle spheres protrude about 7 mm above the palm face.
    standoff_max : float, m
        Upper bound of the particle's standoff offset (its lower bound is 0).
    coarse_steps : int
        Samples of the closing sweep.
    refine_steps : int
        Regula falsi steps after the sweep (the finger stops on the free side of the
        first touch, within about 0.3 mm of it).
    finger_overlap : float, m
        Overlap allowed between capsules of different fingers (soft skin).
    link_contact_tolerance : float, m
        A proximal or middle link this close to the surface touches the object.
    allow_link_contacts : bool
        False (default, the paper's precision grasps: only fingertips touch): a finger
        whose proximal or middle link touches the object is illegal.
    palm_overlap : float, m
        Depth a finger may sink into the palm box (soft skin) before it collides.
    """

    tolerance: float = 0.002
    max_penetration: float = 0.0005
    clearance: float = 0.008
    standoff_max: float = 0.05
    coarse_steps: int = 12
    refine_steps: int = 3
    finger_overlap: float = 0.002
    link_contact_tolerance: float = 0.001
    allow_link_contacts: bool = False
    palm_overlap: float = 0.003

    def __post_init__(self) -> None:
        checks = {
            "tolerance": 0 < self.tolerance <= 0.02,
            "max_penetration": 0 <= self.max_penetration <= 0.02,
            "clearance": 0 <= self.clearance <= 0.05,
            "standoff_max": 0 < self.standoff_max <= 0.5,
            "coarse_steps": 2 <= self.coarse_steps <= 200,
            "refine_steps": 0 <= self.refine_steps <= 30,
            "finger_overlap": 0 <= self.finger_overlap <= 0.01,
            "link_contact_tolerance": 0 <= self.link_contact_tolerance <= 0.01,
            "palm_overlap": 0 <= self.palm_overlap <= 0.02,
        }
        for name, ok in checks.items():
            if not ok:
                raise InputError(f"contact settings: {name} = {getattr(self, name)!r} is out of range")
