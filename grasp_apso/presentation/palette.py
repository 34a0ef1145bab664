"""One palette for every picture of a grasp: the PNGs (:mod:`grasp_apso.tools.plotting`)
and the RViz markers (:mod:`grasp_apso.ros.markers`) use the same colours.

Colours are hex strings (matplotlib takes them as they are); :func:`rgb` turns one into
an (r, g, b) triple in [0, 1] for ROS ``std_msgs/ColorRGBA``. No matplotlib, no ROS here.
"""

from __future__ import annotations

__all__ = [
    "FINGER_COLORS", "OBJECT_COLOR", "PALM_COLOR", "CONTACT_COLOR", "COM_COLOR",
    "SCENE_COLOR", "OBSTACLE_COLOR", "APPROACH_COLOR", "PRE_GRASP_ALPHA", "rgb",
]

#: One colour per finger (little, ring, middle, index, thumb); colour-blind friendly
#: (Okabe-Ito), distinct from the grey object and the tan palm.
FINGER_COLORS: dict[str, str] = {
    "little": "#CC79A7",  # reddish purple
    "ring": "#0072B2",  # blue
    "middle": "#009E73",  # bluish green
    "index": "#E69F00",  # orange
    "thumb": "#D55E00",  # vermillion
}
OBJECT_COLOR = "#9EA8B8"     # the object (grey blue)
PALM_COLOR = "#C8A27A"       # the palm (tan)
CONTACT_COLOR = "#000000"    # contact points and normals
COM_COLOR = "#444444"        # the centre of mass
SCENE_COLOR = "#8C6D46"      # support planes (a wooden table)
OBSTACLE_COLOR = "#7F7F7F"   # obstacles
APPROACH_COLOR = "#56B4E9"   # approach arrows (sky blue)
#: Opacity of the pre-grasp hand, drawn faintly behind the grasp.
PRE_GRASP_ALPHA = 0.25


def rgb(color: str) -> tuple[float, float, float]:
    """``"#RRGGBB"`` -> (r, g, b) in [0, 1]."""
    text = color.lstrip("#")
    if len(text) != 6:
        raise ValueError(f"color: expected #RRGGBB, got {color!r}")
    return tuple(int(text[i:i + 2], 16) / 255.0 for i in (0, 2, 4))  # type: ignore[return-value]
