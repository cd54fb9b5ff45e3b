"""Every manipulator operation: what goes on the wire and what comes back, against the fake arm."""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Coroutine
from typing import Any

import numpy as np
import pytest

from manip.arm.transform import Transform
from manip.codecs.errors import EncodeError
from manip.codecs.lisp import Keyword
from manip.codecs.messages import encode_reply
from manip.reference_client import JointFreedError, Manipulator, ResponseType
from manip.spec import SPEC
from manip.spec.constants import RequestOp
from tests.support.fake_arm import FORCES, GAUGES, HERE, JOINTS, run, session

TARGET = Transform.trans(300.0, 100.0, -50.0) @ Transform.rot_y(90.0)
Call = Callable[[Manipulator], Coroutine[Any, Any, Any]]

# (id, call, opcode, request fields, expected result; a Transform is compared within 1e-3)
CASES: list[tuple[str, Call, int, dict[str, Any], Any]] = [
    ("here", lambda a: a.here(), RequestOp.HERE, {}, HERE),
    ("joint_angles", lambda a: a.joint_angles(), RequestOp.JOINT_ANGLES, {}, JOINTS),
    ("calibrate", lambda a: a.calibrate(), RequestOp.CALIBRATE, {}, None),
    ("move", lambda a: a.move(TARGET), RequestOp.MOVE, {"transform": TARGET.to_floats()}, 1),
    (
        "straight_move",
        lambda a: a.straight_move(TARGET),
        RequestOp.STRAIGHT_MOVE,
        {"transform": TARGET.to_floats()},
        1,
    ),
    ("kill_power", lambda a: a.kill_power(), RequestOp.KILL_POWER, {}, None),
    ("lefty", lambda a: a.set_configuration(True), RequestOp.SET_CONFIGURATION, {"configuration": 1}, None),
    ("righty", lambda a: a.set_configuration(False), RequestOp.SET_CONFIGURATION, {"configuration": 0}, None),
    ("hand", lambda a: a.hand(0o777), RequestOp.HAND, {"amount": 0o777}, None),
    ("open_hand", lambda a: a.open_hand(), RequestOp.HAND, {"amount": 1}, None),
    ("close_hand", lambda a: a.close_hand(), RequestOp.HAND, {"amount": 0}, None),
    (
        "incremental_move",
        lambda a: a.incremental_move(1.0, 2.0, 3.0, 4.5, -5.0, 6.25),
        RequestOp.INCREMENTAL_MOVE,
        {"delta": (1.0, 2.0, 3.0, 4.5, -5.0, 6.25)},
        1,
    ),
    (
        "incremental_straight_move",
        lambda a: a.incremental_straight_move(dz=-10.0),
        RequestOp.INCREMENTAL_STRAIGHT_MOVE,
        {"delta": (0.0, 0.0, -10.0, 0.0, 0.0, 0.0)},
        1,
    ),
    ("ready", lambda a: a.ready(), RequestOp.READY, {}, 1),
    (
        "set_joint_angles",
        lambda a: a.set_joint_angles(JOINTS),
        RequestOp.SET_JOINT_ANGLES,
        {"joints": JOINTS},
        1,
    ),
    ("set_speed", lambda a: a.set_speed(0.5), RequestOp.SET_SPEED, {"factor": 0.5}, None),
    ("enable_power", lambda a: a.enable_power(), RequestOp.ENABLE_POWER, {}, None),
    (
        "solve_forwards",
        lambda a: a.solve_forwards(TARGET, JOINTS),
        RequestOp.SOLVE_FORWARDS,
        {"transform": TARGET.to_floats(), "current": JOINTS},
        JOINTS,
    ),
    (
        "solve_backwards",
        lambda a: a.solve_backwards(JOINTS),
        RequestOp.SOLVE_BACKWARDS,
        {"joints": JOINTS},
        HERE,
    ),
    ("read_forces", lambda a: a.read_forces(), RequestOp.READ_FORCES, {}, FORCES),
    ("read_raw_gauges", lambda a: a.read_raw_gauges(), RequestOp.READ_RAW_GAUGES, {}, GAUGES),
    (
        "set_gauge_offsets",
        lambda a: a.set_gauge_offsets(GAUGES),
        RequestOp.SET_GAUGE_OFFSETS,
        {"offsets": GAUGES},
        None,
    ),
    ("calibrate_wrist", lambda a: a.calibrate_wrist(), RequestOp.CALIBRATE_WRIST, {}, GAUGES),
    ("set_spring", lambda a: a.set_spring([2.0] * 6), RequestOp.SET_SPRING, {"k": (2.0,) * 6}, None),
    (
        "set_damping",
        lambda a: a.set_damping(np.eye(6) * 0.5),
        RequestOp.SET_DAMPING,
        {"b": tuple((np.eye(6) * 0.5).reshape(36))},
        None,
    ),
    (
        "set_joint_damping",
        lambda a: a.set_joint_damping([0.25] * 6),
        RequestOp.SET_JOINT_DAMPING,
        {"bji": (0.25,) * 6},
        None,
    ),
    (
        "set_frame_vector",
        lambda a: a.set_frame_vector((0.0, 0.0, 150.0)),
        RequestOp.SET_FRAME_VECTOR,
        {"offset": (0.0, 0.0, 150.0)},
        None,
    ),
    (
        "set_weight",
        lambda a: a.set_weight(16.0, (0.0, 1.0, 2.0)),
        RequestOp.SET_WEIGHT,
        {"weight": 16.0, "cg": (0.0, 1.0, 2.0)},
        None,
    ),
    (
        "set_guard_stop",
        lambda a: a.set_guard(3, (0, 0, 1, 0, 0, 0), 8.0),
        RequestOp.SET_GUARD,
        {"type_index": 0x8003, "dvec": (0.0, 0.0, 1.0, 0.0, 0.0, 0.0), "tol": 8.0},
        None,
    ),
    (
        "set_guard_continue",
        lambda a: a.set_guard(15, (1, 0, 0, 0, 0, 0), 2.0, stop=False),
        RequestOp.SET_GUARD,
        {"type_index": 15, "dvec": (1.0, 0.0, 0.0, 0.0, 0.0, 0.0), "tol": 2.0},
        None,
    ),
    ("clear_guard", lambda a: a.clear_guard(3), RequestOp.CLEAR_GUARD, {"index": 3}, None),
    (
        "compliant_move",
        lambda a: a.compliant_move(JOINTS, 1),
        RequestOp.COMPLIANT_MOVE,
        {"joints": JOINTS, "scheme": 1},
        1,
    ),
    (
        "examine_wrist",
        lambda a: a.examine_wrist(0o1000, 3),
        RequestOp.EXAMINE_WRIST,
        {"address": 0o1000, "count": 3},
        (0o1000, 0o1001, 0o1002),
    ),
    (
        "deposit_wrist",
        lambda a: a.deposit_wrist(0o1000, 0o7),
        RequestOp.DEPOSIT_WRIST,
        {"address": 0o1000, "value": 0o7},
        None,
    ),
    ("wrist_version", lambda a: a.wrist_version(), RequestOp.WRIST_VERSION, {}, 0o17),
    (
        "request_notifications",
        lambda a: a.request_notifications(3),
        RequestOp.REQUEST_NOTIFICATIONS,
        {"mask": 3},
        None,
    ),
    ("reset_abort", lambda a: a.reset_abort(), RequestOp.RESET_ABORT, {}, None),
    (
        "set_commanded_force",
        lambda a: a.set_commanded_force(FORCES),
        RequestOp.SET_COMMANDED_FORCE,
        {"force": FORCES},
        None,
    ),
]


def test_every_spec_opcode_has_an_operation_case() -> None:
    covered = {case[2] for case in CASES} | {RequestOp.DESCRIBE_SELF, RequestOp.FREE_JOINT}
    assert covered == set(SPEC.requests)


@pytest.mark.parametrize(
    ("call", "opcode", "fields", "expected"), [c[1:] for c in CASES], ids=[c[0] for c in CASES]
)
def test_operation_encoding_and_decoding(
    call: Call, opcode: int, fields: dict[str, Any], expected: Any
) -> None:
    async def main() -> None:
        async with session() as (arm, fake):
            result = await call(arm)
            (sent,) = fake.peer.received
            assert sent.opcode == opcode
            decoded = fake.decoded[0]
            assert decoded is not None and set(decoded.values) == set(fields)
            for name, value in fields.items():
                assert decoded.values[name] == pytest.approx(value, rel=1e-6), name
            if isinstance(expected, Transform):
                assert isinstance(result, Transform) and result.almost_equal(expected, 1e-3)
            else:
                assert result == pytest.approx(expected)

    run(main())


def test_describe_reads_the_multi_packet_alist() -> None:
    async def main() -> None:
        async with session() as (arm, fake):
            description = await arm.describe()
            assert fake.peer.received[0].opcode == RequestOp.DESCRIBE_SELF
            assert description["brand-name"] == "Unimation Puma 600"
            assert description["degrees-of-freedom"] == 6
            assert description["protocol-version"] == 1
            assert description["software-version"] == [Keyword("puma"), 5, Keyword("manip"), 14]
            assert description["operations"] == sorted(op for op in SPEC.requests if op < 0o240)

    run(main())


def test_motion_replies_carry_increasing_segment_numbers() -> None:
    async def main() -> None:
        async with session() as (arm, _):
            assert [await arm.ready(), await arm.move(TARGET), await arm.incremental_move(dx=1.0)] == [
                1,
                2,
                3,
            ]

    run(main())


def test_free_joint_refuses_other_requests_until_released() -> None:
    async def main() -> None:
        async with session() as (arm, fake):
            async with arm.joint_freed(3):
                assert arm.freed_joint == 3
                with pytest.raises(JointFreedError, match="joint 3"):
                    await arm.here()
            assert arm.freed_joint is None
            assert (await arm.here()).almost_equal(HERE, 1e-3)
            ops = [r.opcode for r in fake.peer.received]
            assert ops == [RequestOp.FREE_JOINT, RequestOp.HERE, RequestOp.HERE]
            assert fake.peer.received[0].data == struct.pack("<H", 3)
            await arm.release_joint()  # nothing freed: no packet
            assert len(fake.peer.received) == 3

    run(main())


def test_arguments_are_checked_before_anything_is_sent() -> None:
    async def main() -> None:
        async with session() as (arm, fake):
            bad: list[tuple[Call, type[Exception]]] = [
                (lambda a: a.set_speed(0.0), ValueError),
                (lambda a: a.set_speed(1.5), ValueError),
                (lambda a: a.hand(-1), ValueError),
                (lambda a: a.hand(0x10000), ValueError),
                (lambda a: a.set_guard(16, [0.0] * 6, 1.0), ValueError),
                (lambda a: a.set_joint_angles(JOINTS[:5]), ValueError),
                (lambda a: a.set_spring([math.nan] * 6), ValueError),
                (lambda a: a.set_gauge_offsets([0] * 7), ValueError),
                (lambda a: a.free_joint(0), ValueError),
                (lambda a: a.clear_guard(True), TypeError),
                (lambda a: a.move(Transform.trans(1e39, 0.0, 0.0)), EncodeError),
            ]
            for call, error in bad:
                with pytest.raises(error):
                    await call(arm)
            assert fake.peer.received == []

    run(main())


def test_raw_requests_by_copy_manipulator_request_data_and_by_fields() -> None:
    async def main() -> None:
        async with session() as (arm, fake):
            assert await arm.request("hand", [5]) is None
            assert await arm.request(RequestOp.SET_SPEED, fields={"factor": 0.75}) is None
            words = await arm.request("joint-angles", extractor="words")
            assert words == struct.unpack("<12H", encode_reply("joint-angles", 0, joints=JOINTS)[2:])
            raw = await arm.request("read-raw-gauges", extractor="raw")
            assert raw == (struct.pack("<8h", *GAUGES),)
            assert await arm.request("here", extractor=None) is None
            received = fake.peer.received
            assert received[0].data == struct.pack("<H", 5)
            assert received[1].data == bytes.fromhex("4040 0000")
            with pytest.raises(EncodeError, match="float"):
                arm.make_request("set-speed", fields={"factor": 1})
            with pytest.raises(EncodeError, match="missing field"):
                arm.make_request("set-speed")
            with pytest.raises(ValueError, match="not both"):
                arm.make_request("hand", [1], fields={"amount": 1})
            with pytest.raises(EncodeError):
                arm.make_request("hand", [True])
            request = arm.make_request("describe-self", response_type=ResponseType.MULTI, extractor="text")
            assert "Unimation" in await arm.send_request(request)

    run(main())
