"""Tests for grasp_apso.model.hand: forward kinematics against poses computed by hand from the
YAML numbers, the coupling of eq. 1, batched vs single evaluation, the planar shortcut
(planar_chain + flexion_planes) against the DH frames, Table 2 limits, validation of
configurations and of hand description files, and the wrist rotation convention."""

from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from grasp_apso.model.hand import (
    FINGER_NAMES,
    JOINT_NAMES,
    HandModel,
    dh_transform,
    hand_from_dict,
    load_hand,
    rpy_matrix,
    wrist_rotation,
)

YAML_PATH = Path(__file__).resolve().parents[1] / "grasp_apso" / "data" / "hand.yaml"
LITTLE, RING, MIDDLE, INDEX, THUMB = range(5)
TIP = 3  # index of the fingertip frame in finger_frames(...)[:, f]


@pytest.fixture(scope="module")
def hand() -> HandModel:
    return load_hand()


@pytest.fixture(scope="module")
def raw() -> dict:
    """The shipped description read straight from the YAML file (independent of the code)."""
    return yaml.safe_load(YAML_PATH.read_text(encoding="utf-8"))


def q_zero() -> np.ndarray:
    return np.zeros((1, 18))


def q_with(**joints: float) -> np.ndarray:
    """(1, 18) configuration, all zero except the named joints (radians)."""
    q = q_zero()
    for name, value in joints.items():
        q[0, JOINT_NAMES.index(name)] = value
    return q


def random_configurations(hand: HandModel, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform(hand.lower, hand.upper, size=(n, 18))


def finger_yaml(raw: dict, name: str) -> dict:
    return next(f for f in raw["fingers"] if f["name"] == name)


# ------------------------------------------------------------------------------------------
# forward kinematics: known poses
# ------------------------------------------------------------------------------------------
def test_middle_finger_straight_tip_by_hand(hand: HandModel) -> None:
    # base (0.100, 0.005, 0), yaw 0, links 0.046 + 0.030 + 0.021 = 0.097 along +x
    tip = hand.finger_frames(q_zero())[0, MIDDLE, TIP, :3, 3]
    np.testing.assert_allclose(tip, [0.197, 0.005, 0.0], atol=1e-12)


@pytest.mark.parametrize("name", FINGER_NAMES)
def test_zero_configuration_points_every_finger_along_its_base_x_axis(
    hand: HandModel, raw: dict, name: str
) -> None:
    f = finger_yaml(raw, name)
    base = np.array(f["base_position"], dtype=float)
    roll, pitch, yaw = np.radians(f["base_rpy_deg"])
    assert pitch == 0.0  # all shipped bases: the straight finger is (cos yaw, sin yaw, 0)
    assert roll in (math.pi, math.pi / 2)  # roll about the finger axis does not move it
    axis = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    l1, l2, l3 = f["links"]
    frames = hand.finger_frames(q_zero())[0, FINGER_NAMES.index(name)]
    np.testing.assert_allclose(frames[0, :3, 3], base, atol=1e-12)
    np.testing.assert_allclose(frames[1, :3, 3], base + l1 * axis, atol=1e-12)
    np.testing.assert_allclose(frames[2, :3, 3], base + (l1 + l2) * axis, atol=1e-12)
    np.testing.assert_allclose(frames[3, :3, 3], base + (l1 + l2 + l3) * axis, atol=1e-12)
    # the frames' x axes are the straight finger
    for k in range(4):
        np.testing.assert_allclose(frames[k, :3, 0], axis, atol=1e-12)


def test_middle_finger_proximal_flexion_90_points_up(hand: HandModel) -> None:
    frames = hand.finger_frames(q_with(middle_proximal=math.pi / 2))[0, MIDDLE]
    base = np.array([0.100, 0.005, 0.0])
    np.testing.assert_allclose(frames[1, :3, 3], base + [0, 0, 0.046], atol=1e-12)
    np.testing.assert_allclose(frames[3, :3, 3], base + [0, 0, 0.097], atol=1e-12)


@pytest.mark.parametrize("name", ["little", "ring", "middle", "index"])
def test_fingers_curl_toward_plus_z(hand: HandModel, raw: dict, name: str) -> None:
    f = finger_yaml(raw, name)
    length = sum(f["links"])
    tip = hand.finger_frames(q_with(**{f"{name}_proximal": math.pi / 2}))[0, FINGER_NAMES.index(name), TIP, :3, 3]
    np.testing.assert_allclose(tip, np.array(f["base_position"]) + [0, 0, length], atol=1e-12)
    # a small flexion already lifts the tip (curls toward +z, not -z)
    tip = hand.finger_frames(q_with(**{f"{name}_proximal": 0.2}))[0, FINGER_NAMES.index(name), TIP, :3, 3]
    assert tip[2] == pytest.approx(length * math.sin(0.2), abs=1e-12)


@pytest.mark.parametrize(
    "t2,t", [(0.0, 0.3), (0.4, 0.5), (1.2, -0.4), (math.radians(90), math.radians(90)), (0.7, -math.radians(30))]
)
def test_coupled_distal_flexion_angles(hand: HandModel, t2: float, t: float) -> None:
    """Eq. 1: theta_i1 = t turns the middle joint by 1.5 t and the distal joint by t."""
    frames = hand.finger_frames(q_with(middle_proximal=t2, middle_distal=t))[0, MIDDLE]
    p = frames[:, :3, 3]  # base, PIP, DIP, tip

    def angle(v: np.ndarray) -> float:  # direction angle in the middle finger's x-z plane
        assert abs(v[1]) < 1e-12  # middle finger at pivot 0 flexes in the plane y = 0.005
        return math.atan2(v[2], v[0])

    def wrap(a: float) -> float:
        return (a + math.pi) % (2 * math.pi) - math.pi

    assert wrap(angle(p[1] - p[0]) - t2) == pytest.approx(0.0, abs=1e-12)
    assert wrap(angle(p[2] - p[1]) - (t2 + 1.5 * t)) == pytest.approx(0.0, abs=1e-12)
    assert wrap(angle(p[3] - p[2]) - (t2 + 2.5 * t)) == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(np.linalg.norm(np.diff(p, axis=0), axis=1), [0.046, 0.030, 0.021], atol=1e-12)
    # the tip frame's x axis is the distal link direction
    a = t2 + 2.5 * t
    np.testing.assert_allclose(frames[3, :3, 0], [math.cos(a), 0.0, math.sin(a)], atol=1e-12)


def test_coupling_ratio_is_read_from_the_description(raw: dict) -> None:
    data = copy.deepcopy(raw)
    data["coupling_ratio"] = 2.0
    h = hand_from_dict(data)
    p = h.finger_frames(q_with(middle_distal=0.3))[0, MIDDLE, :, :3, 3]
    d = p[2] - p[1]
    assert math.atan2(d[2], d[0]) == pytest.approx(0.6, abs=1e-12)


@pytest.mark.parametrize("pivot_deg", [10.0, 25.0, 40.0])
def test_positive_little_pivot_abducts_toward_minus_y(hand: HandModel, pivot_deg: float) -> None:
    yaw = math.radians(-10.0)  # little finger base yaw
    p = math.radians(pivot_deg)
    tip0 = hand.finger_frames(q_zero())[0, LITTLE, TIP, :3, 3]
    tip = hand.finger_frames(q_with(little_pivot=p))[0, LITTLE, TIP, :3, 3]
    base = np.array([0.085, -0.033, 0.0])
    expected = base + 0.070 * np.array([math.cos(yaw - p), math.sin(yaw - p), 0.0])
    np.testing.assert_allclose(tip, expected, atol=1e-12)
    assert tip[1] < tip0[1] - 0.01 * pivot_deg / 10.0


@pytest.mark.parametrize("name", ["ring", "middle", "index"])
def test_positive_pivot_turns_every_finger_toward_minus_y(hand: HandModel, name: str) -> None:
    f = FINGER_NAMES.index(name)
    tip0 = hand.finger_frames(q_zero())[0, f, TIP, :3, 3]
    tip = hand.finger_frames(q_with(**{f"{name}_pivot": math.radians(10.0)}))[0, f, TIP, :3, 3]
    assert tip[1] < tip0[1] - 0.01
    assert tip[2] == pytest.approx(0.0, abs=1e-12)  # abduction stays in the palm plane


def test_thumb_pivot_90_points_the_thumb_along_plus_z(hand: HandModel) -> None:
    frames = hand.finger_frames(q_with(thumb_pivot=math.pi / 2))[0, THUMB]
    base = np.array([0.025, 0.030, 0.0])
    np.testing.assert_allclose(frames[1, :3, 3], base + [0, 0, 0.045], atol=1e-12)
    np.testing.assert_allclose(frames[3, :3, 3], base + [0, 0, 0.105], atol=1e-12)


def test_thumb_flexion_curls_it_across_the_palm_toward_the_fingers(hand: HandModel) -> None:
    tip0 = hand.finger_frames(q_with(thumb_pivot=math.radians(60)))[0, THUMB, TIP, :3, 3]
    tip = hand.finger_frames(q_with(thumb_pivot=math.radians(60), thumb_proximal=math.radians(60)))[0, THUMB, TIP, :3, 3]
    assert tip[1] < tip0[1] - 0.05  # toward the little-finger side (-y)


# ------------------------------------------------------------------------------------------
# batched kinematics, planar shortcut, frame sanity
# ------------------------------------------------------------------------------------------
def test_batched_finger_frames_equal_single_evaluations(hand: HandModel) -> None:
    q = random_configurations(hand, 40, seed=1)
    batch = hand.finger_frames(q)
    assert batch.shape == (40, 5, 4, 4, 4)
    for p in range(len(q)):
        np.testing.assert_allclose(batch[p], hand.finger_frames(q[p : p + 1])[0], atol=1e-14)
    # the wrist angles do not enter the finger frames (palm frame), and (P, 15) is accepted
    np.testing.assert_allclose(hand.finger_frames(q[:, :15]), batch, atol=0)


def test_finger_frames_equal_explicit_dh_products(hand: HandModel) -> None:
    """Recompute one finger with the textbook DH product, independently of finger_frames."""
    q = random_configurations(hand, 5, seed=2)
    frames = hand.finger_frames(q)

    def dh(theta, a, alpha):  # Rz(theta) Tx(a) Rx(alpha)
        rz = np.eye(4)
        rz[:2, :2] = [[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]]
        tx = np.eye(4)
        tx[0, 3] = a
        rx = np.eye(4)
        rx[1:3, 1:3] = [[math.cos(alpha), -math.sin(alpha)], [math.sin(alpha), math.cos(alpha)]]
        return rz @ tx @ rx

    for f in range(5):
        l1, l2, l3 = hand.link_lengths[f]
        for p in range(len(q)):
            t1, t2, t3 = q[p, 3 * f : 3 * f + 3]
            t = hand.base_transforms[f] @ dh(t3, 0.0, hand.pivot_twist[f])
            expected = [t]
            for theta, length in ((t2, l1), (1.5 * t1, l2), (t1, l3)):
                t = t @ dh(theta, length, 0.0)
                expected.append(t)
            np.testing.assert_allclose(frames[p, f], np.stack(expected), atol=1e-14)
    # and dh_transform is Rz(theta) Tz(d) Tx(a) Rx(alpha)
    tz = np.eye(4)
    tz[2, 3] = 0.7
    np.testing.assert_allclose(
        dh_transform(np.array(0.3), 0.7, 0.2, -0.4), dh(0.3, 0.0, 0.0) @ tz @ dh(0.0, 0.2, -0.4), atol=1e-15
    )


def test_frames_have_orthonormal_rotations(hand: HandModel) -> None:
    frames = hand.finger_frames(random_configurations(hand, 50, seed=3))
    rot = frames[..., :3, :3]
    eye = np.broadcast_to(np.eye(3), rot.shape)
    np.testing.assert_allclose(np.swapaxes(rot, -1, -2) @ rot, eye, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(rot), 1.0, atol=1e-12)
    np.testing.assert_allclose(frames[..., 3, :], np.broadcast_to([0, 0, 0, 1.0], frames.shape[:-2] + (4,)), atol=0)


def test_fingertip_positions_equal_dh_tips(hand: HandModel) -> None:
    q = random_configurations(hand, 60, seed=4)
    np.testing.assert_allclose(hand.fingertip_positions(q), hand.finger_frames(q)[:, :, TIP, :3, 3], atol=1e-13)


def test_planar_chain_in_flexion_planes_equals_dh_frames(hand: HandModel) -> None:
    q = random_configurations(hand, 60, seed=5)
    frames = hand.finger_frames(q)
    theta = q[:, :15].reshape(-1, 5, 3)
    origin, ex, ey = hand.flexion_planes(theta[..., 2])
    # the plane axes are orthonormal and the origin is the (pivot-invariant) finger base
    np.testing.assert_allclose(np.einsum("pfi,pfi->pf", ex, ey), 0.0, atol=1e-13)
    np.testing.assert_allclose(np.linalg.norm(ex, axis=-1), 1.0, atol=1e-13)
    np.testing.assert_allclose(np.linalg.norm(ey, axis=-1), 1.0, atol=1e-13)
    np.testing.assert_allclose(origin, frames[:, :, 0, :3, 3], atol=1e-13)
    np.testing.assert_allclose(ex, frames[:, :, 0, :3, 0], atol=1e-13)  # straight finger after the pivot
    uv = hand.planar_chain(theta[..., 0], theta[..., 1])  # (P, 5, 3, 2): PIP, DIP, tip
    pts = origin[:, :, None] + uv[..., :1] * ex[:, :, None] + uv[..., 1:] * ey[:, :, None]
    np.testing.assert_allclose(pts, frames[:, :, 1:, :3, 3], atol=1e-13)
    # fractions: the middle of the middle link and the base
    uv = hand.planar_chain(theta[..., 0], theta[..., 1], np.array([[1, 0.5], [0, 0.0]]))
    pts = origin[:, :, None] + uv[..., :1] * ex[:, :, None] + uv[..., 1:] * ey[:, :, None]
    np.testing.assert_allclose(pts[:, :, 0], 0.5 * (frames[:, :, 1, :3, 3] + frames[:, :, 2, :3, 3]), atol=1e-13)
    np.testing.assert_allclose(pts[:, :, 1], frames[:, :, 0, :3, 3], atol=1e-13)


def test_planar_chain_broadcasts_trailing_dimensions(hand: HandModel) -> None:
    q = random_configurations(hand, 4, seed=6)
    theta = q[:, :15].reshape(-1, 5, 3)
    s = np.linspace(0.0, 1.0, 7)
    distal = theta[..., 0, None] * s  # (4, 5, 7)
    proximal = theta[..., 1, None] * s
    uv = hand.planar_chain(distal, proximal)
    assert uv.shape == (4, 5, 7, 3, 2)
    for k in (0, 3, 6):
        np.testing.assert_allclose(uv[:, :, k], hand.planar_chain(distal[..., k], proximal[..., k]), atol=1e-15)


# ------------------------------------------------------------------------------------------
# limits and validation
# ------------------------------------------------------------------------------------------
# Table 2 of the paper, degrees: (distal, proximal, pivot) per finger.
TABLE_2_DEG = {
    "little": ((-30, 90), (0, 90), (-10, 40)),
    "ring": ((-30, 90), (0, 90), (-10, 20)),
    "middle": ((-30, 90), (0, 90), (-15, 15)),
    "index": ((-30, 90), (0, 90), (-20, 10)),
    "thumb": ((-10, 30), (0, 90), (-10, 100)),
}


def test_table_2_limits_in_radians(hand: HandModel) -> None:
    for i, name in enumerate(FINGER_NAMES):
        for j, (lo, hi) in enumerate(TABLE_2_DEG[name]):
            assert hand.lower[3 * i + j] == pytest.approx(math.radians(lo), abs=1e-12), JOINT_NAMES[3 * i + j]
            assert hand.upper[3 * i + j] == pytest.approx(math.radians(hi), abs=1e-12), JOINT_NAMES[3 * i + j]
    # wrist: x and z a full turn, y a half turn (no gimbal duplicates)
    np.testing.assert_allclose(hand.lower[15:], np.radians([-180, -90, -180]), atol=1e-12)
    np.testing.assert_allclose(hand.upper[15:], np.radians([180, 90, 180]), atol=1e-12)
    assert JOINT_NAMES[:3] == ("little_distal", "little_proximal", "little_pivot")
    assert JOINT_NAMES[12:] == ("thumb_distal", "thumb_proximal", "thumb_pivot", "wrist_x", "wrist_y", "wrist_z")


def test_model_constants_match_the_description(hand: HandModel) -> None:
    assert hand.coupling_ratio == 1.5
    np.testing.assert_allclose(hand.link_lengths[MIDDLE], [0.046, 0.030, 0.021])
    np.testing.assert_allclose(hand.link_lengths[THUMB], [0.045, 0.033, 0.027])
    assert hand.pad_radius == 0.008
    np.testing.assert_allclose(hand.link_radii, [0.009, 0.009, 0.008])
    with pytest.raises(ValueError):
        hand.lower[0] = 0.0  # read-only arrays


def test_validate_configuration_accepts_limits_and_returns_input(hand: HandModel) -> None:
    q = np.vstack([hand.lower, hand.upper, random_configurations(hand, 10, seed=7)])
    np.testing.assert_array_equal(hand.validate_configuration(q), q)
    np.testing.assert_array_equal(hand.validate_configuration(q[0]), q[0])


@pytest.mark.parametrize(
    "joint,value_deg",
    [("index_pivot", 10.5), ("index_pivot", -25.0), ("little_pivot", 41.0), ("thumb_distal", 31.0),
     ("middle_proximal", -1.0), ("ring_distal", 95.0), ("wrist_y", 91.0)],
)
def test_validate_configuration_names_out_of_range_joint(hand: HandModel, joint: str, value_deg: float) -> None:
    q = random_configurations(hand, 3, seed=8)
    q[2, JOINT_NAMES.index(joint)] = math.radians(value_deg)
    with pytest.raises(ValueError, match=rf"\b{joint}\b"):
        hand.validate_configuration(q)
    with pytest.raises(ValueError, match=rf"\b{joint}\b"):
        hand.validate_configuration(q[2])


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_validate_configuration_names_non_finite_joint(hand: HandModel, bad: float) -> None:
    q = np.zeros(18)
    q[JOINT_NAMES.index("index_pivot")] = bad
    with pytest.raises(ValueError, match=r"index_pivot.*finite"):
        hand.validate_configuration(q)


@pytest.mark.parametrize("shape", [(17,), (19,), (2, 17), (2, 3, 18), (), (0,)])
def test_validate_configuration_rejects_wrong_shape(hand: HandModel, shape: tuple) -> None:
    with pytest.raises(ValueError, match=r"shape"):
        hand.validate_configuration(np.zeros(shape), field="joint_positions")
    with pytest.raises(ValueError, match=r"joint_positions"):
        hand.validate_configuration(np.zeros(shape), field="joint_positions")


# ------------------------------------------------------------------------------------------
# hand description files
# ------------------------------------------------------------------------------------------
def write(tmp_path: Path, data) -> Path:
    path = tmp_path / "hand.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return path


def test_load_hand_from_a_copy_equals_the_shipped_hand(hand: HandModel, raw: dict, tmp_path: Path) -> None:
    other = load_hand(write(tmp_path, raw))
    for field in ("link_lengths", "base_transforms", "pivot_twist", "lower", "upper", "link_radii"):
        np.testing.assert_allclose(getattr(other, field), getattr(hand, field), atol=1e-15)
    assert load_hand(None).name == load_hand("").name == raw["name"]


def _missing_links(d):
    del d["fingers"][2]["links"]


def _missing_pad(d):
    del d["pad_radius"]


def _missing_wrist_axis(d):
    del d["wrist_limits_deg"]["y"]


def _swap_order(d):
    d["fingers"][1], d["fingers"][2] = d["fingers"][2], d["fingers"][1]


def _four_fingers(d):
    del d["fingers"][4]


def _negative_length(d):
    d["fingers"][3]["links"][1] = -0.025


def _zero_length(d):
    d["fingers"][0]["links"][0] = 0.0


def _equal_limits(d):
    d["fingers"][3]["limits_deg"]["pivot"] = [10.0, 10.0]


def _inverted_limits(d):
    d["fingers"][4]["limits_deg"]["distal"] = [30.0, -10.0]


def _inverted_wrist(d):
    d["wrist_limits_deg"]["z"] = [180.0, -180.0]


def _short_base(d):
    d["fingers"][0]["base_position"] = [0.085, -0.033]


def _nan_base(d):
    d["fingers"][0]["base_position"] = [0.085, float("nan"), 0.0]


def _negative_radius(d):
    d["link_radii"][1] = -0.009


def _bad_ratio(d):
    d["coupling_ratio"] = 0.0


@pytest.mark.parametrize(
    "mutate,message",
    [
        (_missing_links, r"missing 'links' in finger 'middle'"),
        (_missing_pad, r"missing 'pad_radius'"),
        (_missing_wrist_axis, r"missing 'y' in wrist_limits_deg"),
        (_swap_order, r"order.*little.*ring.*middle"),
        (_four_fingers, r"order"),
        (_negative_length, r"finger 'index' links"),
        (_zero_length, r"finger 'little' links"),
        (_equal_limits, r"finger 'index' limits_deg\.pivot needs low < high"),
        (_inverted_limits, r"finger 'thumb' limits_deg\.distal needs low < high"),
        (_inverted_wrist, r"wrist_limits_deg\.z needs low < high"),
        (_short_base, r"finger 'little' base_position"),
        (_nan_base, r"finger 'little' base_position"),
        (_negative_radius, r"link_radii"),
        (_bad_ratio, r"coupling_ratio"),
    ],
)
def test_load_hand_rejects_broken_description(raw: dict, tmp_path: Path, mutate, message: str) -> None:
    data = copy.deepcopy(raw)
    mutate(data)
    with pytest.raises(ValueError, match=message):
        load_hand(write(tmp_path, data))


def _set_top(key, value):
    return lambda d: d.__setitem__(key, value)


def _set_finger(key, value):
    return lambda d: d["fingers"][0].__setitem__(key, value)


@pytest.mark.parametrize(
    "mutate,message",
    [
        (_set_top("pad_radius", float("nan")), r"pad_radius"),
        (_set_top("pad_radius", float("inf")), r"pad_radius"),
        (_set_top("pad_radius", "8 mm"), r"pad_radius"),
        (_set_top("pad_radius", [0.008]), r"pad_radius"),
        (_set_top("coupling_ratio", "one and a half"), r"coupling_ratio"),
        (_set_finger("pivot_twist_deg", float("nan")), r"finger 'little' pivot_twist_deg"),
        (_set_finger("pivot_twist_deg", [-90.0]), r"finger 'little' pivot_twist_deg"),
        (lambda d: d["palm"].__setitem__("half_extents", [0.05, -0.045, 0.012]), r"palm\.half_extents"),
    ],
    ids=["pad-nan", "pad-inf", "pad-text", "pad-list", "ratio-text", "twist-nan", "twist-list", "palm-negative"],
)
def test_load_hand_rejects_bad_scalars(raw: dict, tmp_path: Path, mutate, message: str) -> None:
    data = copy.deepcopy(raw)
    mutate(data)
    with pytest.raises(ValueError, match=message):
        load_hand(write(tmp_path, data))


def test_load_hand_rejects_unreadable_and_invalid_files(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"cannot read"):
        load_hand(tmp_path / "does_not_exist.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("fingers: [unclosed\n", encoding="utf-8")
    with pytest.raises(ValueError, match=r"not valid YAML"):
        load_hand(bad)
    bad.write_text("- just\n- a list\n", encoding="utf-8")
    with pytest.raises(ValueError, match=r"mapping"):
        load_hand(bad)


# ------------------------------------------------------------------------------------------
# wrist rotation convention
# ------------------------------------------------------------------------------------------
def test_wrist_rotation_is_extrinsic_xyz() -> None:
    rng = np.random.default_rng(9)
    angles = rng.uniform([-math.pi, -math.pi / 2, -math.pi], [math.pi, math.pi / 2, math.pi], size=(200, 3))
    expected = Rotation.from_euler("xyz", angles).as_matrix()
    np.testing.assert_allclose(wrist_rotation(angles), expected, atol=1e-14)
    # == Rz(tz) @ Ry(ty) @ Rx(tx), spelled out for one sample
    tx, ty, tz = angles[0]
    rx = Rotation.from_rotvec([tx, 0, 0]).as_matrix()
    ry = Rotation.from_rotvec([0, ty, 0]).as_matrix()
    rz = Rotation.from_rotvec([0, 0, tz]).as_matrix()
    np.testing.assert_allclose(wrist_rotation(angles[0]), rz @ ry @ rx, atol=1e-14)
    np.testing.assert_allclose(rpy_matrix(tx, ty, tz), rz @ ry @ rx, atol=1e-14)
    # batch shapes are preserved
    assert wrist_rotation(angles.reshape(10, 20, 3)).shape == (10, 20, 3, 3)
