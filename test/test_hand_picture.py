"""The picture that checks a loaded hand (grasp_apso.tools.hand_picture, issue 20).

The paper's hand through the general loader: the PNG is written, has four panels' worth
of drawing, and every finger's pad shows in its own colour (the pads are the only opaque
marks in a finger's colour, so finding the colour finds the pad).
"""

from __future__ import annotations

import matplotlib.image as mpimg
import numpy as np
import pytest

from grasp_apso.errors import InputError
from grasp_apso.model.hands.load import load_hand
from grasp_apso.tools.hand_picture import draw_hand, finger_color
from grasp_apso.presentation.palette import rgb


@pytest.fixture(scope="module")
def paper_hand():
    return load_hand()


def _has_color(image: np.ndarray, color: str, tolerance: float = 0.02) -> int:
    return int((np.abs(image[..., :3] - np.array(rgb(color))).max(axis=2) < tolerance).sum())


def test_picture_of_the_paper_hand_shows_every_pad_in_its_finger_colour(paper_hand, tmp_path):
    path = draw_hand(paper_hand, tmp_path / "hand.png")
    image = mpimg.imread(path)
    assert image.shape[0] > 800 and image.shape[1] > 800
    ink = (image[..., :3].min(axis=2) < 0.9).mean()
    assert ink > 0.05  # a drawing, not a blank page
    for i, finger in enumerate(paper_hand.fingers):
        assert _has_color(image, finger_color(finger.name, i)) >= 10, finger.name


def test_given_postures_are_checked(paper_hand, tmp_path):
    with pytest.raises(InputError) as err:
        draw_hand(paper_hand, tmp_path / "bad.png", q_open=np.zeros(3))
    assert err.value.field == "q_open"
    q = np.clip(np.zeros(len(paper_hand.actuated_joints)), paper_hand.lower, paper_hand.upper)
    assert draw_hand(paper_hand, tmp_path / "same.png", q_open=q, q_closed=q).endswith("same.png")


def test_unknown_finger_names_get_distinct_colours():
    names = ["finger_a", "finger_b", "finger_c", "index", "thumb"]
    colors = [finger_color(n, i) for i, n in enumerate(names)]
    assert len(set(colors)) == len(colors)


def test_the_table_label_goes_to_the_corner_nothing_drawn_covers():
    """The label of the table sits at the corner the camera sees farthest from the object
    and the hand (it used to sit at the first corner, under a Shadow hand's forearm)."""
    from grasp_apso.tools.scene_drawing import label_corner

    corners = np.array([[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [100.0, 100.0, 0.0], [0.0, 100.0, 0.0]])
    obj = np.array([[50.0, 50.0, 10.0], [55.0, 45.0, 30.0]])
    forearm = np.array([[x, x, 60.0] for x in np.linspace(50.0, 95.0, 10)])
    top = np.array([0.0, 0.0, 1.0])
    assert label_corner(corners, np.vstack([obj, forearm]), top) == 0        # away from the forearm
    assert label_corner(corners, np.vstack([obj, forearm[::-1] * [-1, -1, 1] + [100, 100, 0]]), top) == 2
