"""Pictures of the arm in captures: /arm/hand holds foxglove.FrameTransform messages that Foxglove's own
published schema accepts and that agree with the arm's forward kinematics; /arm/joints plots."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader

from manip.arm import PUMA600, Transform, forward
from manip.arm.transform import FLOAT_ROTATION_TOL
from manip.captures import Recorder
from manip.captures.arm_view import (
    _JSON,
    _frame_transform,
    _hand_json,
    _here_hand,
    _joints_json,
    frame_transform_schema,
    joints_schema,
    quaternion,
)
from manip.codecs.messages import encode_reply
from manip.spec.constants import ServerOp
from tests.support.captures import JOINTS, record, s2c, session_packets
from tests.support.json_schema import validate as _validate
from tests.support.paths import ROOT

FOXGLOVE = json.loads((Path(__file__).parent / "data" / "foxglove" / "FrameTransform.json").read_text())


def _messages(path: Path) -> dict[str, list[tuple[int, dict[str, Any], Any]]]:
    out: dict[str, list[tuple[int, dict[str, Any], Any]]] = {}
    with path.open("rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            if channel.topic.startswith("/arm/"):
                out.setdefault(channel.topic, []).append((message.log_time, json.loads(message.data), schema))
    return out


def _pose(message: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Translation (mm) and rotation matrix of a FrameTransform message."""
    t, q = message["translation"], message["rotation"]
    x, y, z, w = q["x"], q["y"], q["z"], q["w"]
    rotation = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    return np.array([t["x"], t["y"], t["z"]]) * 1000.0, rotation


HERE = (0.0, 1.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0, -150.5, 431.75, 20.25)


def _session(tmp_path: Path) -> Path:
    packets = session_packets()
    # a here after the joint-angles reply: its transform is the second hand pose
    packets.insert(5, ("c2s", packets[3][1].with_(opcode=0o201, packet_no=9)))
    packets.insert(6, ("s2c", s2c(ServerOp.RESPONSE, 10, encode_reply("here", 9, transform=HERE))))
    path = tmp_path / "s.mcap"
    record(path, packets)
    return path


def test_our_schema_is_foxgloves() -> None:
    ours = frame_transform_schema()
    assert ours["title"] == FOXGLOVE["title"] == "foxglove.FrameTransform"

    def shape(schema: dict[str, Any]) -> Any:
        props = schema.get("properties")
        if props is None:
            return {k: schema[k] for k in ("type", "minimum", "maximum") if k in schema}
        return {k: shape(v) for k, v in props.items()}

    assert shape(ours) == shape(FOXGLOVE)


def test_hand_and_joints_messages(tmp_path: Path) -> None:
    messages = _messages(_session(tmp_path))
    hands, joints = messages["/arm/hand"], messages["/arm/joints"]
    assert len(hands) == 2 and len(joints) == 1
    for t, message, schema in hands:
        assert schema.name == "foxglove.FrameTransform" and schema.encoding == "jsonschema"
        _validate(message, FOXGLOVE)
        _validate(message, json.loads(schema.data))
        assert message["timestamp"] == {"sec": t // 10**9, "nsec": t % 10**9}
        assert (message["parent_frame_id"], message["child_frame_id"]) == ("world", "hand")
        q = message["rotation"]
        assert math.isclose(q["x"] ** 2 + q["y"] ** 2 + q["z"] ** 2 + q["w"] ** 2, 1.0, rel_tol=1e-12)
    # the joint-angles reply: the hand where forward kinematics puts it, and each angle plottable
    expected = forward(JOINTS, PUMA600.geometry)
    p, r = _pose(hands[0][1])
    assert np.allclose(p, expected.p, atol=1e-9) and np.allclose(r, expected.rotation, atol=1e-12)
    t, flat, schema = joints[0]
    _validate(flat, joints_schema())
    assert schema.name == "manip.JointAngles" and t == hands[0][0]
    assert [flat[f"j{i}"] for i in range(1, 7)] == pytest.approx(list(JOINTS))
    # the here reply: its own transform, in metres
    p, r = _pose(hands[1][1])
    here = Transform.from_floats(HERE)
    assert np.allclose(p, here.p, atol=1e-9) and np.allclose(r, here.rotation, atol=1e-12)


def test_no_pictures_without_the_view_or_when_asked_not_to(tmp_path: Path) -> None:
    for kw in ({"decoded_view": False}, {"arm_view": False}):
        path = tmp_path / "s.mcap"
        record(path, session_packets(), **kw)
        assert _messages(path) == {}


def test_a_transform_that_is_not_a_rotation_is_left_out(tmp_path: Path) -> None:
    bad = (2.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 2.0, 3.0)
    packets = session_packets()[:3]
    request = packets[0][1].with_(opcode=0o201, packet_no=2, src_index=0x1234, dest_index=0x5678, data=b"")
    packets += [("c2s", request), ("s2c", s2c(ServerOp.RESPONSE, 3, encode_reply("here", 2, transform=bad)))]
    path = tmp_path / "s.mcap"
    with Recorder(path) as rec:
        link = rec.open_link("tcp")
        for direction, packet in packets:
            rec.packet(link, direction, packet)  # type: ignore[arg-type]
    assert "/arm/hand" not in _messages(path)


@pytest.mark.parametrize("turn", [0.0, 90.0, 179.999, 180.0, -120.0])
def test_quaternion_gives_the_rotation_back(turn: float) -> None:
    for axis in (Transform.rot_x, Transform.rot_y, Transform.rot_z):
        pose = axis(turn) @ Transform.rot_x(30.0) @ Transform.rot_z(-45.0)
        x, y, z, w = quaternion(pose.rotation)
        _, r = _pose({"translation": {"x": 0, "y": 0, "z": 0}, "rotation": {"x": x, "y": y, "z": z, "w": w}})
        assert w >= 0.0 and np.allclose(r, pose.rotation, atol=1e-12)


def test_golden_motion_capture_shows_the_hand_moving() -> None:
    messages = _messages(ROOT / "captures" / "motion.mcap")
    hands, joints = messages["/arm/hand"], messages["/arm/joints"]
    assert len(joints) == 2 and len(hands) == 3  # joint-angles before and after the move, then here
    for _, message, _ in hands:
        _validate(message, FOXGLOVE)
    before, after, here = (_pose(m) for _, m, _ in hands)
    assert np.linalg.norm(after[0] - before[0]) > 10.0  # the hand moved more than a centimetre
    # here, from the server, is where forward kinematics of the last joint angles puts the hand
    assert np.allclose(here[0], after[0], atol=0.05) and np.allclose(here[1], after[1], atol=1e-5)
    angles = [joints[1][1][f"j{i}"] for i in range(1, 7)]
    assert np.allclose(_pose(hands[1][1])[0], forward(angles, PUMA600.geometry).p, atol=1e-9)


_noise = st.floats(-3e-4, 3e-4, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(
    st.tuples(*(st.floats(-180.0, 180.0, allow_nan=False) for _ in range(3))),
    st.tuples(*(_noise for _ in range(9))),
    st.tuples(*(st.floats(-2000.0, 2000.0, allow_nan=False) for _ in range(3))),
)
def test_here_hand_is_from_floats_without_numpy(
    turns: tuple[float, float, float], noise: tuple[float, ...], p: tuple[float, float, float]
) -> None:
    """The numpy-free here path accepts what Transform.from_floats accepts and gives its nearest rotation.

    The noise reaches past the tolerance (1e-4), so both verdicts are drawn."""
    pose = Transform.rot_z(turns[0]) @ Transform.rot_y(turns[1]) @ Transform.rot_x(turns[2])
    values = [v + e for v, e in zip(pose.to_floats()[:9], noise, strict=True)] + list(p)
    try:
        want: Transform | None = Transform.from_floats(values, orthonormalise=True)
    except ValueError:
        want = None
    got = _here_hand(values)
    if want is None:
        assert got is None
        return
    assert got is not None
    rotation, position = got
    assert np.array_equal(np.array(position), want.p)
    assert np.allclose(np.array(rotation), want.rotation, rtol=0.0, atol=1e-13)


def test_here_hand_refuses_what_is_not_a_pose() -> None:
    good = Transform.rot_z(30.0).to_floats()
    assert _here_hand(good) is not None
    assert _here_hand([*good[:11], math.inf]) is None
    assert _here_hand([*good[:11], "x"]) is None
    skewed = [good[0] + 2 * FLOAT_ROTATION_TOL, *good[1:]]
    assert _here_hand(skewed) is None


_finite = st.floats(-1e6, 1e6, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(
    st.tuples(*(st.floats(-180.0, 180.0, allow_nan=False) for _ in range(3))),
    st.tuples(_finite, _finite, _finite),
    st.integers(0, 2**63 - 1),
    st.lists(_finite, min_size=6, max_size=6),
    st.integers(0, 2**16),
    st.integers(0, 2**16),
    st.one_of(st.none(), st.integers(0, 0xFFFF)),
)
def test_arm_messages_are_written_as_the_encoder_would(
    turns: tuple[float, float, float],
    p: tuple[float, float, float],
    t_ns: int,
    angles: list[float],
    link: int,
    conn: int,
    number: int | None,
) -> None:
    pose = Transform.rot_z(turns[0]) @ Transform.rot_y(turns[1]) @ Transform.rot_x(turns[2])
    for rotation in (pose.rotation, pose.rotation.tolist()):
        want = _JSON.encode(_frame_transform(rotation, p, t_ns)).encode()
        assert _hand_json(rotation, p, t_ns) == want
    message: dict[str, Any] = {"timestamp": {"sec": t_ns // 10**9, "nsec": t_ns % 10**9}}
    message |= {"link": link, "conn": conn} | ({} if number is None else {"request_number": number})
    message |= {f"j{i}": a for i, a in enumerate(angles, 1)}
    assert _joints_json(angles, link, conn, number, t_ns) == _JSON.encode(message).encode()
    assert json.loads(_hand_json(pose.rotation, (math.inf, 0.0, 0.0), t_ns))["translation"]["x"] == math.inf
