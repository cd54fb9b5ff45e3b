"""The reference server's session: every opcode's reply, motion, errors, asynchronous packets, states.

The session is driven with a fake clock; every reply is decoded with manip.codecs.messages.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pytest

from manip.arm.kinematics import READY, forward
from manip.arm.trajectory import TICK
from manip.arm.transform import Transform
from manip.codecs.error_string import ErrorMessage
from manip.codecs.lisp import Keyword, read_alist
from manip.codecs.messages import (
    AsyncResponse,
    ErrorReply,
    Reply,
    ServerMessage,
    decode_server_packet,
    encode_request,
)
from manip.codecs.pdp11float import pack_f
from manip.reference_server import (
    HANDLERS,
    TRANSITIONS,
    WRIST_OPERATIONS,
    FaultSet,
    Input,
    Output,
    ServerConfig,
    ServerSession,
    SessionUsageError,
    State,
)
from manip.reference_server.session import server_config
from manip.spec import SPEC
from manip.spec.constants import AsyncCondition, RequestOp, ServerOp
from tests.support.session_client import GOAL, OTHER, Client
from tests.support.session_client import reply as _reply

POWERED = ServerConfig(powered_at_open=True)
SERVED = frozenset(SPEC.request(name).opcode for name in HANDLERS)


def _error(msg: ServerMessage, opcode: int = ServerOp.NON_FATAL_ERROR) -> ErrorMessage:
    assert isinstance(msg, ErrorReply), msg
    assert msg.opcode == opcode
    assert not msg.error.problems, msg.error.problems
    return msg.error


def _floats(n: int, value: float = 0.0) -> tuple[float, ...]:
    return (value,) * n


# ------------------------------------------------------------------------------------- tables
def test_every_spec_request_is_served_or_handed_to_the_wrist() -> None:
    names = {op.name for op in SPEC.requests.values()}
    assert set(HANDLERS) | WRIST_OPERATIONS == names
    assert not set(HANDLERS) & WRIST_OPERATIONS
    assert {op for op in range(0o200, 0o222)} <= SERVED
    assert {RequestOp.REQUEST_NOTIFICATIONS, RequestOp.RESET_ABORT} <= SERVED


def test_state_table_shape() -> None:
    assert (State.AWAITING_INITIAL, Input.OPEN) in TRANSITIONS
    assert all((s, Input.OPEN) not in TRANSITIONS for s in State if s is not State.AWAITING_INITIAL)
    assert (State.AWAITING_INITIAL, Input.REQUEST) not in TRANSITIONS
    assert all((State.CLOSED, i) in TRANSITIONS for i in Input if i is not Input.OPEN)


# ------------------------------------------------------------------------------ connection
def test_initial_response_carries_the_rfc_packet_number() -> None:
    client = Client(rfc=0o4321)
    (packet,) = client.initial.packets
    assert packet.opcode == ServerOp.RESPONSE and packet.data == (0o4321).to_bytes(2, "little")
    assert not client.initial.close and client.session.state is State.READY


def test_driver_misuse_is_refused() -> None:
    session = ServerSession()
    with pytest.raises(SessionUsageError):
        session.on_request(0.0, RequestOp.HERE, 1, b"")
    assert session.tick(0.0) == Output()
    session.on_open(1.0, 1)
    with pytest.raises(SessionUsageError):
        session.on_open(1.0, 1)
    with pytest.raises(ValueError, match="backwards"):
        session.tick(0.5)


def test_close_ends_the_session() -> None:
    client = Client()
    assert client.session.on_close(client.now) == Output()
    assert client.session.state is State.CLOSED
    assert client.raw(RequestOp.HERE, b"") == Output()
    assert client.session.tick(client.now + 1) == Output()


# -------------------------------------------------------------------------- every opcode
EXAMPLES: Mapping[str, dict[str, Any]] = {
    "describe-self": {},
    "here": {},
    "joint-angles": {},
    "calibrate": {},
    "move": {"transform": forward(GOAL).to_floats()},
    "straight-move": {"transform": (Transform.trans(0.0, 0.0, -20.0) @ forward(READY)).to_floats()},
    "kill-power": {},
    "set-configuration": {"configuration": 1},
    "hand": {"amount": 0},
    "incremental-move": {"delta": (0.0, 0.0, -10.0, 0.0, 0.0, 0.0)},
    "incremental-straight-move": {"delta": (0.0, 0.0, -10.0, 0.0, 0.0, 0.0)},
    "free-joint": {"joint": 3},
    "ready": {},
    "set-joint-angles": {"joints": GOAL},
    "set-speed": {"factor": 0.5},
    "enable-power": {},
    "solve-forwards": {"transform": forward(GOAL).to_floats(), "current": GOAL},
    "solve-backwards": {"joints": GOAL},
    "request-notifications": {"mask": 2},
    "reset-abort": {},
}


def test_examples_cover_every_served_opcode() -> None:
    assert set(EXAMPLES) == set(HANDLERS)


@pytest.mark.parametrize("name", sorted(HANDLERS))
def test_reply_shape_and_request_number(name: str) -> None:
    client = Client(POWERED, rfc=0xFFFE)
    op = SPEC.request(name)
    msgs = client.send(name, **EXAMPLES[name])
    assert client.packet_no == 0xFFFF
    assert all(isinstance(m, Reply) and m.request_number == client.packet_no for m in msgs), msgs
    replies = [_reply(m) for m in msgs]
    match op.response.form:
        case "done":
            assert len(replies) == 1 and replies[0].is_empty
        case "segment":
            assert len(replies) == 1 and replies[0].segment == 1
        case "data":
            (reply,) = replies
            assert set(reply.values) == {f.name for f in op.response.data.fields}
        case "multi":
            assert len(replies) >= 3 and replies[-1].is_empty
            assert not any(r.is_empty for r in replies[:-1])


def test_request_number_echo_ignores_the_ack_field() -> None:
    client = Client()
    out = client.raw(RequestOp.HERE, b"", ack_no=0o7777)
    assert decode_server_packet(out.packets[0].opcode, out.packets[0].data).request_number == client.packet_no


# ------------------------------------------------------------------------------ describe self
def test_describe_self_reads_back_as_the_alist() -> None:
    client = Client()
    replies = [_reply(m) for m in client.send("describe-self")]
    text = "".join(str(r.values["text"]) for r in replies[:-1])
    alist = read_alist(text)
    assert {
        "brand-name",
        "unique-name",
        "degrees-of-freedom",
        "operations",
        "software-version",
        "protocol-version",
    } <= set(alist)
    assert alist["brand-name"] == "Unimation Puma 600"
    assert isinstance(alist["unique-name"], str)
    assert alist["degrees-of-freedom"] == 6
    assert alist["protocol-version"] == 1
    assert set(alist["operations"]) == SERVED  # type: ignore[arg-type]
    assert list(alist["operations"]) == sorted(SERVED)  # type: ignore[arg-type]
    assert " 200 " in text and "(:OPERATIONS 200" in text  # octal, as the Lisp Machine reads it
    version = alist["software-version"]
    assert isinstance(version, list) and isinstance(version[0], Keyword) and isinstance(version[1], int)
    assert alist["ready-position"] == list(READY)


# ------------------------------------------------------------------------------------ motion
def test_motion_needs_power_by_default() -> None:
    client = Client()
    error = _error(client.one("set-joint-angles", joints=GOAL))
    assert (error.where, error.severity, error.code) == ("set-joint-angles", "E", "NAP")
    assert _reply(client.one("enable-power")).is_empty
    assert _reply(client.one("set-joint-angles", joints=GOAL)).segment == 1


def test_motion_requests_are_answered_before_the_arm_moves() -> None:
    client = Client(POWERED)
    segments = [_reply(client.one("set-joint-angles", joints=g)).segment for g in (GOAL, OTHER, READY)]
    assert segments == [1, 2, 3]
    assert _reply(client.one("joint-angles")).values["joints"] == READY  # not moved yet
    assert client.run(0.3) == []
    moving = _reply(client.one("joint-angles")).values["joints"]
    assert moving != READY


def test_arm_reaches_the_commanded_pose() -> None:
    client = Client(POWERED)
    target = forward(GOAL)
    client.one("move", transform=target.to_floats())
    client.settle()
    here = Transform.from_floats(_reply(client.one("here")).values["transform"])  # type: ignore[arg-type]
    assert here.almost_equal(target, 1e-3)
    joints = _reply(client.one("joint-angles")).values["joints"]
    assert np.allclose(joints, GOAL, atol=1e-3)


def test_straight_and_incremental_moves_reach_their_targets() -> None:
    client = Client(POWERED)
    client.one("set-joint-angles", joints=GOAL)
    client.settle()
    start = forward(client.session.arm.actual)
    client.one("incremental-move", delta=(0.0, 0.0, -20.0, 0.0, 0.0, 0.0))
    client.one("incremental-straight-move", delta=(10.0, 0.0, 0.0, 0.0, 0.0, 0.0))
    goal = Transform.trans(-20.0, 10.0, -60.0) @ start
    assert [_reply(client.one("straight-move", transform=goal.to_floats())).segment] == [4]
    client.settle()
    here = Transform.from_floats(_reply(client.one("here")).values["transform"])  # type: ignore[arg-type]
    assert here.almost_equal(goal, 1e-3)
    client.one("ready")
    client.settle()
    assert np.allclose(_reply(client.one("joint-angles")).values["joints"], READY, atol=1e-4)


def test_segment_completed_only_when_requested_and_in_order() -> None:
    client = Client(POWERED)
    client.one("set-joint-angles", joints=GOAL)
    assert client.settle() == []  # not requested: silence
    assert _reply(client.one("request-notifications", mask=2)).is_empty
    numbers = [_reply(client.one("set-joint-angles", joints=g)).segment for g in (OTHER, READY, GOAL)]
    last = client.packet_no
    notes = client.settle()
    assert all(isinstance(n, AsyncResponse) for n in notes)
    assert [(n.request_number, n.condition, n.word2, n.word3) for n in notes] == [  # type: ignore[union-attr]
        (last, AsyncCondition.SEGMENT_COMPLETED, 0, n) for n in numbers
    ]
    client.one("request-notifications", mask=0)
    client.one("set-joint-angles", joints=OTHER)
    assert client.settle() == []


def test_notification_mask_with_undefined_bits_is_a_command_error() -> None:
    error = _error(Client().one("request-notifications", mask=0o4))
    assert (error.severity, error.code) == ("C", "BVA")


def _completion_time(speed: float) -> float:
    client = Client(POWERED)
    client.one("set-speed", factor=speed)
    client.one("set-joint-angles", joints=GOAL)
    start = client.now
    client.settle()
    return client.now - start


def test_speed_factor_scales_durations() -> None:
    assert _completion_time(0.25) == pytest.approx(4 * _completion_time(1.0), abs=2 * TICK)


@pytest.mark.parametrize("factor", [0.0, -0.5, 1.5, 1e30])
def test_speed_out_of_range_is_a_command_error(factor: float) -> None:
    error = _error(Client().one("set-speed", factor=factor))
    assert (error.where, error.severity, error.code) == ("set-speed", "C", "BVA")


def test_jor_tor_and_nothing_queued() -> None:
    client = Client(POWERED)
    error = _error(client.one("set-joint-angles", joints=(0.0, -90.0, 300.0, 0.0, 0.0, 0.0)))
    assert (error.code, error.args, error.render_message()) == ("JOR", (4,), "Joint(s) 3 out of range")
    far = Transform.trans(2000.0, 0.0, 0.0).to_floats()
    for op in ("move", "straight-move"):
        error = _error(client.one(op, transform=far))
        assert (error.where, error.severity, error.code) == (op, "E", "TOR")
    error = _error(client.one("solve-forwards", transform=far, current=READY))
    assert error.code == "TOR"
    assert not client.session.arm.moving
    assert _reply(client.one("ready")).segment == 1  # refusals used no segment number


def test_not_a_rotation_is_a_bad_value() -> None:
    bad = (2.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 100.0, 0.0, 500.0)
    error = _error(Client(POWERED).one("move", transform=bad))
    assert (error.severity, error.code) == ("C", "BVA")


def test_solve_forwards_and_backwards_round_trip() -> None:
    client = Client()
    pose = _reply(client.one("solve-backwards", joints=GOAL)).values["transform"]
    assert Transform.from_floats(pose).almost_equal(forward(GOAL), 1e-4)  # type: ignore[arg-type]
    joints = _reply(client.one("solve-forwards", transform=pose, current=GOAL)).values["joints"]
    assert np.allclose(joints, GOAL, atol=1e-3)


def test_set_configuration_byte_or_word_and_bad_bits() -> None:
    client = Client()
    assert _reply(client.one("set-configuration", b"\x01")).is_empty
    assert client.session.arm.lefty is True
    assert _reply(client.one("set-configuration", b"\x00\x7f")).is_empty  # high byte ignored
    assert client.session.arm.lefty is False
    error = _error(client.one("set-configuration", configuration=2))
    assert (error.severity, error.code) == ("C", "BVA")


def test_set_configuration_other_bits_answered_done_when_chosen() -> None:
    client = Client(ServerConfig(configuration_bits="done"))
    assert _reply(client.one("set-configuration", configuration=3)).is_empty  # the 1985 guide: "done"
    assert client.session.arm.lefty is True  # bit 0 still chooses
    assert _reply(client.one("set-configuration", configuration=0o376)).is_empty
    assert client.session.arm.lefty is False


def test_async_in_the_guides_layout_when_chosen() -> None:
    client = Client(ServerConfig(powered_at_open=True, async_layout="guide"))
    client.one("request-notifications", mask=2)
    segment = _reply(client.one("set-joint-angles", joints=GOAL)).segment
    out = []
    while client.now < 140.0 and not out:
        out = [
            p for p in client.session.tick(client.now).packets if p.opcode == ServerOp.ASYNCHRONOUS_RESPONSE
        ]
        client.now += TICK
    (packet,) = out
    assert packet.data == bytes([2, 0, 0, 0, segment or 0, 0])  # condition, reserved, segment: 6 bytes


def test_lengths_in_inches_at_the_boundary_only() -> None:
    inches = Client(ServerConfig(powered_at_open=True, length_unit="inch"))
    mm = Client(POWERED)
    here_in = _reply(inches.one("here")).values["transform"]
    here_mm = _reply(mm.one("here")).values["transform"]
    assert isinstance(here_in, tuple) and isinstance(here_mm, tuple)
    assert np.allclose(np.array(here_in[9:]) * 25.4, here_mm[9:], atol=1e-3)
    assert np.allclose(here_in[:9], here_mm[:9])  # the rotation has no unit
    backwards = _reply(inches.one("solve-backwards", joints=GOAL)).values["transform"]
    assert Transform.from_floats(
        list(backwards)
    ).almost_equal(  # type: ignore[arg-type]
        Transform.from_floats(list(forward(GOAL).to_floats()[:9]) + [x / 25.4 for x in forward(GOAL).p]), 1e-4
    )
    joints = _reply(inches.one("solve-forwards", transform=backwards, current=GOAL)).values["joints"]
    assert np.allclose(joints, GOAL, atol=1e-3)
    inches.one("set-joint-angles", joints=GOAL)
    inches.settle()
    start = forward(inches.session.arm.actual)
    inches.one("incremental-straight-move", delta=(1.0, 0.0, -1.0, 0.0, 0.0, 0.0))  # inches
    inches.settle()
    assert np.allclose(
        forward(inches.session.arm.actual).p, np.array(start.p) + np.array([25.4, 0.0, -25.4]), atol=1e-2
    )
    goal = Transform.trans(0.0, 0.0, -20.0) @ start  # millimetres inside
    wire = list(goal.to_floats()[:9]) + [x / 25.4 for x in goal.p]
    inches.one("straight-move", transform=tuple(wire))
    inches.settle()
    assert forward(inches.session.arm.actual).almost_equal(goal, 1e-2)


def test_guide_profile() -> None:
    config = ServerConfig.guide_profile(powered_at_open=True)
    assert (config.extensions, config.length_unit, config.async_layout, config.configuration_bits) == (
        False,
        "inch",
        "guide",
        "done",
    )
    assert config.powered_at_open
    assert server_config("guide") == ServerConfig.guide_profile()
    assert server_config("manip") == ServerConfig()
    with pytest.raises(ValueError, match="unknown server profile"):
        server_config("val")
    client = Client(config)
    assert _reply(client.one("set-configuration", configuration=2)).is_empty
    error = _error(client.one("request-notifications", mask=2))
    assert (error.severity, error.code) == ("C", "UOP")


def test_hand_and_power() -> None:
    client = Client()
    assert _error(client.one("hand", amount=0)).code == "NAP"
    client.one("enable-power")
    client.one("hand", amount=0)
    assert client.session.arm.hand_open is False
    client.one("hand", amount=0o377)
    assert client.session.arm.hand_open is True
    client.one("kill-power")
    assert not client.session.arm.powered


def test_calibrate_answers_done() -> None:
    assert _reply(Client().one("calibrate")).is_empty


# ---------------------------------------------------------------------- malformed requests
def test_unknown_opcode() -> None:
    client = Client()
    out = client.raw(0o230, b"\x01\x02")
    (msg,) = [decode_server_packet(p.opcode, p.data) for p in out.packets]
    error = _error(msg)
    assert error.text == "dispatch: C UOP Unknown opcode ~" and error.args == (0o230,)
    assert msg.request_number == client.packet_no and client.session.state is State.READY


GUIDE_ONLY = ServerConfig(powered_at_open=True, extensions=False)
EXTENSIONS = frozenset(op.opcode for op in SPEC.requests.values() if op.extension)


@pytest.mark.parametrize("opcode", sorted(EXTENSIONS))
def test_without_extensions_an_extension_opcode_is_refused_as_unknown(opcode: int) -> None:
    size = SPEC.requests[opcode].request.fixed_size or 0
    answers = []
    for config in (GUIDE_ONLY, POWERED):
        client = Client(config)
        for code in (opcode, 0o230):  # an extension opcode, then one no spec assigns
            out = client.raw(code, b"\0" * size)
            answers.append([decode_server_packet(p.opcode, p.data) for p in out.packets])
    refused, unknown, served, _ = answers
    assert len(refused) == 1 and _error(refused[0]).text == "dispatch: C UOP Unknown opcode ~"
    assert _error(refused[0]).args == (opcode,)
    assert [type(m) for m in refused] == [type(m) for m in unknown]
    assert not (len(served) == 1 and isinstance(served[0], ErrorReply) and served[0].error.code == "UOP")


def test_without_extensions_describe_self_lists_the_guide_opcodes_only() -> None:
    client = Client(GUIDE_ONLY)
    replies = [_reply(m) for m in client.send("describe-self")]
    alist = read_alist("".join(str(r.values["text"]) for r in replies[:-1]))
    assert set(alist["operations"]) == SERVED - EXTENSIONS  # type: ignore[arg-type]
    assert set(range(0o200, 0o222)) <= set(alist["operations"])  # type: ignore[arg-type]
    assert not EXTENSIONS & set(alist["operations"])  # type: ignore[arg-type]


def test_without_extensions_the_guide_requests_still_move_the_arm() -> None:
    client = Client(GUIDE_ONLY)
    assert _reply(client.one("set-joint-angles", joints=GOAL)).segment == 1
    client.run(5.0)
    assert _reply(client.one("joint-angles")).values["joints"] == pytest.approx(GOAL, abs=1e-3)


@pytest.mark.parametrize(
    ("op", "data", "expected"),
    [
        ("here", b"\0\0", 0),
        ("set-joint-angles", b"\0" * 23, 24),
        ("set-joint-angles", b"\0" * 25, 24),
        ("set-speed", b"", 4),
        ("set-configuration", b"\0\0\0", 2),
    ],
)
def test_bad_data_length(op: str, data: bytes, expected: int) -> None:
    client = Client(POWERED)
    error = _error(client.one(op, data))
    assert (error.where, error.severity, error.code) == ("dispatch", "C", "BDL")
    assert error.args == (expected, len(data))
    assert not client.session.arm.moving


def test_reserved_operand_float() -> None:
    client = Client(POWERED)
    data = b"".join(pack_f(x) for x in GOAL[:2]) + b"\x00\x80\x00\x00" + b"".join(pack_f(x) for x in GOAL[3:])
    error = _error(client.one("set-joint-angles", data))
    assert (error.severity, error.code, error.args) == ("C", "BFL", (4,))
    assert not client.session.arm.moving


def test_wrist_opcodes_without_a_wrist() -> None:
    client = Client()
    for name in sorted(WRIST_OPERATIONS):
        op = SPEC.request(name)
        # not served: refused as such whatever the data, before its length is looked at
        for data in (b"\0" * (op.request.fixed_size or 0), b"\0" * ((op.request.fixed_size or 0) + 1)):
            error = _error(client.one(name, data))
            assert (error.where, error.severity, error.code, error.args) == (
                "wrist",
                "C",
                "UIM",
                (op.opcode,),
            )


def test_handler_failure_is_a_non_fatal_bug(monkeypatch: pytest.MonkeyPatch) -> None:
    client = Client()

    def boom(*args: object) -> dict[str, Any]:
        raise ZeroDivisionError

    monkeypatch.setitem(HANDLERS, "here", boom)
    error = _error(client.one("here"))
    assert (error.severity, error.code, error.args) == ("BE", "BUG", (RequestOp.HERE,))
    assert client.session.state is State.READY


# ------------------------------------------------------------------------------ free joint
def test_free_joint_discards_the_next_packet() -> None:
    client = Client(POWERED)
    assert _reply(client.one("free-joint", joint=2)).is_empty
    assert client.session.state is State.FREE_JOINT_WAIT and client.session.arm.free_joint == 2
    out = client.raw(RequestOp.SET_JOINT_ANGLES, encode_request("set-joint-angles", joints=GOAL))
    (discarded,) = [_reply(decode_server_packet(p.opcode, p.data)) for p in out.packets]
    assert discarded.is_empty and discarded.request_number == client.packet_no
    assert not client.session.arm.moving and client.session.arm.free_joint is None
    assert client.session.state is State.READY
    assert _reply(client.one("set-joint-angles", joints=GOAL)).segment == 1


def test_free_joint_discards_even_unknown_opcodes() -> None:
    client = Client(POWERED)
    client.one("free-joint", b"\x06")
    out = client.raw(0o277, b"junk")
    (msg,) = [decode_server_packet(p.opcode, p.data) for p in out.packets]
    assert _reply(msg).is_empty


@pytest.mark.parametrize("joint", [0, 7, 0o377])
def test_free_joint_out_of_range(joint: int) -> None:
    client = Client(POWERED)
    error = _error(client.one("free-joint", joint=joint))
    assert (error.severity, error.code) == ("C", "BVA")
    assert client.session.state is State.READY


# --------------------------------------------------------------------------------- aborts
def _aborted(config: ServerConfig, seconds: float) -> tuple[Client, list[ServerMessage], int]:
    client = Client(config)
    client.one("request-notifications", mask=2)
    client.one("set-joint-angles", joints=GOAL)
    client.one("set-joint-angles", joints=OTHER)
    last = client.packet_no
    return client, client.run(seconds), last


def test_panic_button() -> None:
    config = ServerConfig(powered_at_open=True, faults=FaultSet.parse(["panic-button=0.4"]))
    client, msgs, last = _aborted(config, 3.0)
    (msg,) = msgs
    error = _error(msg, ServerOp.ASYNCHRONOUS_ERROR)
    assert (error.where, error.severity, error.code) == ("move", "E", "PAN")
    assert msg.request_number == last
    assert client.settle() == [] and not client.session.arm.powered
    assert _error(client.one("ready")).code == "AWA"
    client.one("reset-abort")
    assert _error(client.one("ready")).code == "NAP"
    client.one("enable-power")
    assert _reply(client.one("ready")).segment == 3


def test_collision() -> None:
    config = ServerConfig(powered_at_open=True, faults=FaultSet.parse(["obstacle=2::-85"]))
    client, msgs, last = _aborted(config, 3.0)
    warning, abort = msgs
    assert _error(warning, ServerOp.ASYNCHRONOUS_WARNING).code == "COL"
    error = _error(abort, ServerOp.ASYNCHRONOUS_ERROR)
    assert (error.code, error.args, abort.request_number) == ("COL", (0b10,), last)
    assert "joint(s) 2;" in error.render_message()
    assert _error(client.one("set-joint-angles", joints=READY)).code == "AWA"
    client.one("enable-power")  # clears the abort as well
    assert _reply(client.one("set-joint-angles", joints=READY)).segment == 3


def test_killing_power_while_moving_aborts() -> None:
    client = Client(POWERED)
    client.one("set-joint-angles", joints=GOAL)
    client.run(0.2)
    client.one("kill-power")
    (msg,) = client.run(0.1)
    assert _error(msg, ServerOp.ASYNCHRONOUS_ERROR).code == "NAP"
    assert _error(client.one("ready")).code == "AWA"


def test_calibrate_nzi_is_fatal_and_closes() -> None:
    config = ServerConfig(faults=FaultSet.parse(["calibrate-nzi=2,3"]))
    client = Client(config)
    client.one("here")
    out = client.raw(RequestOp.CALIBRATE, b"")
    assert out.close and client.session.state is State.CLOSED
    (msg,) = [decode_server_packet(p.opcode, p.data) for p in out.packets]
    error = _error(msg, ServerOp.FATAL_ERROR)
    assert msg.request_number == client.packet_no
    assert error.text == "During calibration: F NZI No zero index found on joint(s) $."
    assert error.args == (6,)
    assert error.render() == "During calibration: F NZI No zero index found on joint(s) 2 and 3."
    assert client.raw(RequestOp.HERE, b"") == Output()


def test_every_error_string_conforms() -> None:
    """Drive many refusals; every error string must pass ErrorMessage.problems (checked by _error)."""
    client = Client()
    cases: list[tuple[str, dict[str, Any]]] = [
        ("set-joint-angles", {"joints": GOAL}),
        ("hand", {"amount": 1}),
        ("free-joint", {"joint": 9}),
        ("set-speed", {"factor": 2.0}),
        ("set-configuration", {"configuration": 4}),
        ("request-notifications", {"mask": 0o10}),
    ]
    for name, values in cases:
        _error(client.one(name, **values))
