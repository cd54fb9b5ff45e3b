"""Fault switches: each one changes the observable behaviour it claims to, and nothing is left untested.

Every test runs the same scenario against a clean session and against one with the fault switched on,
and checks that the clean one conforms and the faulted one differs in the claimed way.
"""

from __future__ import annotations

import ast
import dataclasses
import math
import struct
from collections.abc import Callable
from itertools import pairwise
from pathlib import Path
from typing import TypeVar

import numpy as np
import pytest
from click.testing import CliRunner

import manip
from manip.arm.kinematics import READY, forward
from manip.arm.sim import ArmDefects, Obstacle
from manip.arm.trajectory import TICK
from manip.arm.transform import Transform, rotation_angle_deg
from manip.codecs.errors import DecodeError
from manip.codecs.lisp import Symbol, read_alist
from manip.codecs.messages import ErrorReply, decode_async, decode_error, decode_reply, encode_request
from manip.codecs.pdp11float import F_MIN_NORMAL, pack_f, unpack_f
from manip.conformance.cli import main as conform_main
from manip.conformance.judge.checks import word
from manip.cougar import CougarSim
from manip.cougar.faults import CougarFault
from manip.ncp import ChaosDefects
from manip.reference_server import Fault, FaultSet, Output, ServerConfig, State, WorldCondition
from manip.reference_server import session as session_module
from manip.reference_server.cougar_port import SimPort
from manip.reference_server.cougar_wrist import CougarWrist
from manip.reference_server.defects import HELD_TICKS, Defects, SwitchedDefects, arm_defects, chaos_defects
from manip.reference_server.faults import WRIST_SIDE
from manip.spec import SPEC
from manip.spec.constants import RequestOp, ServerOp
from tests.support.cougar_fake import WristClient
from tests.support.session_client import GOAL, OTHER, Client
from tests.support.session_client import reply as _reply

T = TypeVar("T")
COVERED: set[Fault | WorldCondition] = set()


def covers(fault: Fault | WorldCondition) -> Callable[[Callable[[], None]], Callable[[], None]]:
    def mark(test: Callable[[], None]) -> Callable[[], None]:
        COVERED.add(fault)
        return test

    return mark


def pair(
    fault: Fault | FaultSet,
    scenario: Callable[[Client], T],
    *,
    base: FaultSet | None = None,
    powered: bool = True,
) -> tuple[T, T]:
    """The scenario's result on a clean session (``base`` faults only) and on one with ``fault`` added."""
    clean = base or FaultSet()
    faulty = clean.merged(fault if isinstance(fault, FaultSet) else FaultSet.of(fault))
    results = [scenario(Client(ServerConfig(powered_at_open=powered, faults=f))) for f in (clean, faulty)]
    return results[0], results[1]


def _packets(out: Output) -> list[tuple[int, bytes]]:
    return [(p.opcode, p.data) for p in out.packets]


def _raw(client: Client, op: str, data: bytes | None = None, **values: object) -> list[tuple[int, bytes]]:
    spec_op = SPEC.request(op)
    return _packets(client.raw(spec_op.opcode, encode_request(op, **values) if data is None else data))


# ------------------------------------------------------------------------------- the registry
def test_registry_describes_every_fault() -> None:
    for fault in Fault:
        assert fault.kind == "protocol" and fault.breaks.endswith(".")
        assert fault.clauses and all(c in SPEC.clauses for c in fault.clauses)
        assert any(SPEC.clauses[c].level in ("MUST", "SHOULD") for c in fault.clauses)
    for condition in WorldCondition:  # not faults: what a conforming server meets too
        assert condition.description.endswith(".") and condition.clauses
        assert condition.value not in {f.value for f in Fault}


def test_parse() -> None:
    faults = FaultSet.parse(["panic-button=2.5", "obstacle=2::-60", "calibrate-nzi=1,6", "no-jor"])
    assert faults.active == {Fault.NO_JOR}
    conditions = {WorldCondition.PANIC_BUTTON, WorldCondition.OBSTACLE, WorldCondition.CALIBRATE_NZI}
    assert faults.world.on == conditions
    assert faults.world.panic_delay == 2.5 and faults.world.nzi_joints == (1, 6)
    assert faults.world.obstacle == Obstacle(2, None, -60.0)
    assert Fault.NO_JOR in faults and Fault.NO_NAP not in faults and WorldCondition.OBSTACLE in faults
    assert FaultSet.parse(["panic-button", "calibrate-nzi"]).world.nzi_joints == (2, 3)
    for bad, message in [
        (["no-such-fault"], "unknown fault"),
        (["no-jor=1"], "takes no argument"),
        (["obstacle"], "needs an argument"),
        (["obstacle=2:1"], "JOINT:LOWER:UPPER"),
        (["obstacle=9::1"], "1..6"),
        (["calibrate-nzi=0"], "1..6"),
        (["panic-button=soon"], "panic-button"),
    ]:
        with pytest.raises(ValueError, match=message):
            FaultSet.parse(bad)


def test_every_fault_has_a_test() -> None:
    # The wrist side's defects show only to the suite playing Cougar: tests/conformance/puma/test_puma.py
    # has them.
    assert (set(Fault) - WRIST_SIDE) | set(WorldCondition) == COVERED


# ---------------------------------------------------------------------------- the Chaos level
CHAOS_LEVEL = frozenset(f for f in Fault if all(SPEC.clauses[c].party == "link" for c in f.clauses))


@covers(Fault.LOS_UNKNOWN_IGNORED)
@covers(Fault.ILLEGAL_OPCODE_IGNORED)
@covers(Fault.OVERSIZE_SERVED)
@covers(Fault.NO_RETRANSMISSION)
@covers(Fault.DUPLICATE_RFC_NEW)
@covers(Fault.SILENT_PEER_KEPT)
@covers(Fault.PACKET_NUMBERS_SKIP)
@covers(Fault.HEADER_SOURCE_FIRST)
@covers(Fault.HEADER_LOW_BYTE_SET)
@covers(Fault.NBYTES_WHOLE_WORDS)
@covers(Fault.DATA_BYTES_SWAPPED)
@covers(Fault.TCP_LENGTH_UNPADDED)
@covers(Fault.CHUDP_NO_HEADER)
@covers(Fault.CHUDP_ODD_BYTE_UNPADDED)
@covers(Fault.CHUDP_LSB_FIRST)
@covers(Fault.TRAILER_SOURCE_DESTINATION)
@covers(Fault.CHECKSUM_WITHOUT_TRAILER)
@covers(Fault.CHAOSD_MSB_FIRST)
def test_each_chaos_level_fault_bends_one_rule_of_the_ncp_or_the_links() -> None:
    """A fault of the Chaos level reaches the NCP and the links as one field of ChaosDefects, its own (the
    fault matrices, tests/conformance/test_faults.py, show each caught); the session's hooks stay the
    conforming ones."""
    rules = ChaosDefects()
    bent: dict[str, Fault] = {}
    for fault in CHAOS_LEVEL:
        defects = chaos_defects(FaultSet.of(fault))
        (field,) = [
            f.name for f in dataclasses.fields(defects) if getattr(defects, f.name) != getattr(rules, f.name)
        ]
        assert field not in bent, (fault, bent[field])
        bent[field] = fault
        assert arm_defects(FaultSet.of(fault)) == ArmDefects()
    assert chaos_defects(FaultSet()) == rules
    assert len(bent) == len(CHAOS_LEVEL) == len(dataclasses.fields(rules))


# ---------------------------------------------------------------------------- environment
@covers(WorldCondition.PANIC_BUTTON)
def test_panic_button() -> None:
    def scenario(c: Client) -> list[str]:
        c.one("set-joint-angles", joints=GOAL)
        return [decode_error(ServerOp.ASYNCHRONOUS_ERROR, d).error.code for _, d in _async(c, 3.0)]

    assert pair(FaultSet.parse(["panic-button=0.5"]), scenario) == ([], ["PAN"])


@covers(WorldCondition.OBSTACLE)
def test_obstacle() -> None:
    def scenario(c: Client) -> list[int]:
        c.one("set-joint-angles", joints=GOAL)
        return [op for op, _ in _async(c, 3.0)]

    clean, faulty = pair(FaultSet.parse(["obstacle=2::-85"]), scenario)
    assert clean == [] and faulty == [ServerOp.ASYNCHRONOUS_WARNING, ServerOp.ASYNCHRONOUS_ERROR]


@covers(WorldCondition.CALIBRATE_NZI)
def test_calibrate_nzi() -> None:
    def scenario(c: Client) -> tuple[list[int], bool]:
        out = c.raw(RequestOp.CALIBRATE, b"")
        return [p.opcode for p in out.packets], out.close

    assert pair(FaultSet.parse(["calibrate-nzi"]), scenario) == (
        ([ServerOp.RESPONSE], False),
        ([ServerOp.FATAL_ERROR], True),
    )


def _async(c: Client, seconds: float) -> list[tuple[int, bytes]]:
    out: list[tuple[int, bytes]] = []
    end = c.now + seconds
    while c.now < end:
        c.now += 0.016
        out += _packets(c.session.tick(c.now))
    return out


# ---------------------------------------------------------------------------- request numbers
@covers(Fault.WRONG_REQUEST_NUMBER)
def test_wrong_request_number() -> None:
    def scenario(c: Client) -> int:
        (packet,) = _raw(c, "here")
        return decode_reply(packet[1]).request_number - c.packet_no

    assert pair(Fault.WRONG_REQUEST_NUMBER, scenario) == (0, 1)


@covers(Fault.ECHO_ACK_NUMBER)
def test_echo_ack_number() -> None:
    def scenario(c: Client) -> tuple[int, int]:
        (packet,) = _packets(c.raw(RequestOp.HERE, b"", ack_no=0o777))
        return decode_reply(packet[1]).request_number, c.packet_no

    (clean, sent), (faulty, _) = pair(Fault.ECHO_ACK_NUMBER, scenario)
    assert clean == sent and faulty == 0o777


@covers(Fault.NO_INITIAL_RESPONSE)
def test_no_initial_response() -> None:
    assert pair(Fault.NO_INITIAL_RESPONSE, lambda c: len(c.initial.packets)) == (1, 0)


@covers(Fault.INITIAL_RESPONSE_NUMBER)
def test_initial_response_number() -> None:
    def scenario(c: Client) -> int:
        return decode_reply(c.initial.packets[0].data).request_number - c.packet_no

    assert pair(Fault.INITIAL_RESPONSE_NUMBER, scenario) == (0, 1)


# ------------------------------------------------------------------------------ describe self
def _describe(c: Client) -> list[bytes]:
    return [d for _, d in _raw(c, "describe-self")]


@covers(Fault.NO_DESCRIBE_TERMINATOR)
def test_no_describe_terminator() -> None:
    def scenario(c: Client) -> tuple[bool, int]:
        packets = _describe(c)
        return decode_reply(packets[-1]).is_empty, len(packets)

    (clean_ends, n), (faulty_ends, m) = pair(Fault.NO_DESCRIBE_TERMINATOR, scenario)
    assert clean_ends and not faulty_ends and m == n - 1


@covers(Fault.DESCRIBE_TERMINATOR_OVERTAKEN)
def test_describe_terminator_overtaken() -> None:
    """The terminator is held back: a request sent at once is answered before it (the terminator right
    after); to a client that waits, it comes some servo ticks late, alone."""

    def scenario(c: Client) -> tuple[list[int], list[int]]:
        first = c.packet_no + 1
        numbers = [word(d) for d in _describe(c)]
        numbers += [word(d) for _, d in _raw(c, "here")]
        late = []
        for _ in range(HELD_TICKS):
            c.now += 0.016
            late += [word(p.data) for p in c.session.tick(c.now).packets if p.opcode == ServerOp.RESPONSE]
        return [n - first for n in numbers], [n - first for n in late]

    clean, faulty = pair(Fault.DESCRIBE_TERMINATOR_OVERTAKEN, scenario)
    assert clean[0][-2:] == [0, 1] and not clean[1]  # the terminator, then the reply to here
    assert faulty[0][-2:] == [1, 0] and sorted(faulty[0]) == sorted(clean[0]) and faulty[1] == []

    def waiting(c: Client) -> list[int]:
        _describe(c)
        late = []
        for _ in range(HELD_TICKS):
            c.now += 0.016
            late += [len(p.data) for p in c.session.tick(c.now).packets if p.opcode == ServerOp.RESPONSE]
        return late

    assert pair(Fault.DESCRIBE_TERMINATOR_OVERTAKEN, waiting) == ([], [2])  # the bare terminator, late


@covers(Fault.MULTI_WRONG_NUMBER)
def test_multi_wrong_number() -> None:
    def scenario(c: Client) -> set[int]:
        return {decode_reply(d).request_number - c.packet_no for d in _describe(c)}

    clean, faulty = pair(Fault.MULTI_WRONG_NUMBER, scenario)
    assert clean == {0} and faulty == {0, 1}


@covers(Fault.NO_PROTOCOL_VERSION)
def test_no_protocol_version() -> None:
    def scenario(c: Client) -> bool:
        text = "".join(str(decode_reply(d, "describe-self").values.get("text", "")) for d in _describe(c))
        return "protocol-version" in read_alist(text)

    assert pair(Fault.NO_PROTOCOL_VERSION, scenario) == (True, False)


def _alist(c: Client) -> dict[str, object]:
    text = "".join(str(decode_reply(d, "describe-self").values.get("text", "")) for d in _describe(c))
    return dict(read_alist(text))


def _refusal_code(c: Client, opcode: int, data: bytes) -> str | None:
    """The code of the non-fatal error answering the request (None: not one)."""
    ((op, answer),) = _packets(c.raw(opcode, data))
    return decode_error(op, answer).error.code if op == ServerOp.NON_FATAL_ERROR else None


@covers(Fault.DESCRIBE_EXTRA_OPERATION)
def test_describe_extra_operation() -> None:
    def scenario(c: Client) -> tuple[bool, str | None]:
        listed = _alist(c)["operations"]
        assert isinstance(listed, list)
        return 0o222 in listed, _refusal_code(c, 0o222, b"")

    assert pair(Fault.DESCRIBE_EXTRA_OPERATION, scenario) == ((False, "UOP"), (True, "UOP"))


@covers(Fault.DESCRIBE_MISSING_OPERATION)
def test_describe_missing_operation() -> None:
    def scenario(c: Client) -> tuple[bool, str | None]:
        listed = _alist(c)["operations"]
        assert isinstance(listed, list)
        return RequestOp.SOLVE_BACKWARDS in listed, _refusal_code(c, RequestOp.SOLVE_BACKWARDS, b"")

    assert pair(Fault.DESCRIBE_MISSING_OPERATION, scenario) == ((True, "BDL"), (False, "BDL"))


@covers(Fault.DESCRIBE_WRONG_DOF)
def test_describe_wrong_dof() -> None:
    def scenario(c: Client) -> tuple[object, int]:
        ((_, data),) = _raw(c, "joint-angles")
        return _alist(c)["degrees-of-freedom"], (len(data) - 2) // 4

    assert pair(Fault.DESCRIBE_WRONG_DOF, scenario) == ((6, 6), (7, 6))


@covers(Fault.DESCRIBE_NARROW_LIMITS)
def test_describe_narrow_limits() -> None:
    def scenario(c: Client) -> tuple[object, str | None]:
        limits = _alist(c)["joint-limits"]
        assert isinstance(limits, list) and isinstance(limits[0], list)
        upper = float(limits[0][1])
        beyond = [upper + 0.5, *READY[1:]]  # just beyond the stated upper limit of joint 1
        ((op, data),) = _raw(c, "set-joint-angles", joints=beyond)
        return limits[0], decode_error(op, data).error.code if op == ServerOp.NON_FATAL_ERROR else None

    clean, faulty = pair(Fault.DESCRIBE_NARROW_LIMITS, scenario)
    assert clean == ([-160.0, 160.0], "JOR")
    assert faulty == ([-155.0, 155.0], None)  # accepted: the arm's range is wider than stated


# ------------------------------------------------------------------------------ data replies
@covers(Fault.SWAPPED_FLOAT_WORDS)
def test_swapped_float_words() -> None:
    def scenario(c: Client) -> bytes:
        ((_, data),) = _raw(c, "joint-angles")
        return data[2:]

    clean, faulty = pair(Fault.SWAPPED_FLOAT_WORDS, scenario)
    assert decode_reply(b"\0\0" + clean, "joint-angles").values["joints"] == READY
    assert faulty != clean
    assert faulty == b"".join(clean[i + 2 : i + 4] + clean[i : i + 2] for i in range(0, len(clean), 4))


@covers(Fault.SEGMENT_NUMBER_STUCK)
def test_segment_number_stuck() -> None:
    def scenario(c: Client) -> list[int]:
        replies = [_raw(c, "set-joint-angles", joints=g)[0][1] for g in (GOAL, OTHER, READY)]
        return [decode_reply(data, "set-joint-angles").segment for data in replies]

    assert pair(Fault.SEGMENT_NUMBER_STUCK, scenario) == ([1, 2, 3], [1, 1, 1])


# ------------------------------------------------------------------------------ error strings
def _uop(c: Client) -> bytes:
    ((opcode, data),) = _packets(c.raw(0o230, b""))
    assert opcode == ServerOp.NON_FATAL_ERROR
    return data


@covers(Fault.WRONG_SEVERITY)
def test_wrong_severity() -> None:
    def scenario(c: Client) -> tuple[str, bool]:
        error = decode_error(ServerOp.NON_FATAL_ERROR, _uop(c)).error
        return error.severity, ServerOp.NON_FATAL_ERROR in SPEC.severities[error.severity].server_opcodes

    assert pair(Fault.WRONG_SEVERITY, scenario) == (("C", True), ("F", False))


@covers(Fault.ERROR_WITHOUT_COLON)
def test_error_without_colon() -> None:
    def scenario(c: Client) -> str | None:
        try:
            decode_error(ServerOp.NON_FATAL_ERROR, _uop(c))
        except DecodeError as exc:
            return exc.clause
        return None

    assert pair(Fault.ERROR_WITHOUT_COLON, scenario) == (None, "error-string.format")


def _bdl(c: Client) -> bytes:
    ((_, data),) = _raw(c, "set-speed", b"")
    return data


@covers(Fault.ERROR_PAD_MISPLACED)
def test_error_pad_misplaced() -> None:
    """BDL's NUL ends at an even offset: no pad is due, and the fault puts one there anyway.  Parity still
    reads it (a tolerant reader), an aligned-only reader does not."""
    clean, faulty = pair(Fault.ERROR_PAD_MISPLACED, _bdl)
    for data in (clean, faulty):
        assert decode_error(ServerOp.NON_FATAL_ERROR, data).error.args == (4, 0)
    nul = faulty.index(0, 2)
    assert (nul + 1) % 2 == 0 and (len(faulty) - nul - 1) % 2 == 1 and faulty[nul + 1] == 0
    assert (len(clean) - clean.index(0, 2) - 1) % 2 == 0
    with pytest.raises(DecodeError):
        decode_error(ServerOp.NON_FATAL_ERROR, faulty, align_args=True)


def test_error_args_packed_layout() -> None:
    """ServerConfig(error_args="packed") writes the numbers straight after the NUL (the 1985 guide's
    layout); both read back alike."""
    aligned = _uop(Client(ServerConfig()))
    packed = _uop(Client(ServerConfig(error_args="packed")))
    assert len(aligned) == len(packed) + 1  # UOP's NUL ends at an odd offset: the aligned layout pads
    for data in (aligned, packed):
        assert decode_error(ServerOp.NON_FATAL_ERROR, data).error.args == (0o230,)


def test_withdrawn_fault_switch_says_what_replaced_it() -> None:
    with pytest.raises(ValueError, match="--error-args packed"):
        FaultSet.parse(["unaligned-error-args"])


@covers(Fault.UOP_OPCODE_SWAPPED)
@covers(Fault.BDL_COUNTS_SWAPPED)
@covers(Fault.JOINT_MASK_SWAPPED)
def test_error_numbers_byte_swapped() -> None:
    def numbers(c: Client) -> tuple[tuple[int, ...], ...]:
        jor = _raw(c, "set-joint-angles", joints=[1000.0, *READY[1:3], 1000.0, *READY[4:]])
        return tuple(
            decode_error(ServerOp.NON_FATAL_ERROR, data).error.args for data in (_uop(c), _bdl(c), jor[0][1])
        )

    clean = (((0o230,), (4, 0), (0b1001,)),) * 3
    faulty = (((0x9800,), (4, 0), (0b1001,)), ((0o230,), (0x400, 0), (0b1001,)), ((0o230,), (4, 0), (0x900,)))
    for fault, clean_numbers, faulty_numbers in zip(
        (Fault.UOP_OPCODE_SWAPPED, Fault.BDL_COUNTS_SWAPPED, Fault.JOINT_MASK_SWAPPED),
        clean,
        faulty,
        strict=True,
    ):
        assert pair(fault, numbers) == (clean_numbers, faulty_numbers), fault


# ------------------------------------------------------------------------------ request handling
@covers(Fault.UNKNOWN_OPCODE_ANSWERED)
def test_unknown_opcode_answered() -> None:
    assert pair(Fault.UNKNOWN_OPCODE_ANSWERED, lambda c: [op for op, _ in _packets(c.raw(0o230, b""))]) == (
        [ServerOp.NON_FATAL_ERROR],
        [ServerOp.RESPONSE],
    )


@covers(Fault.LENGTH_UNCHECKED)
def test_length_unchecked() -> None:
    def scenario(c: Client) -> tuple[int, float]:
        ((opcode, _),) = _raw(c, "set-speed", pack_f(0.5) + b"\0\0")
        return opcode, c.session.arm.speed

    assert pair(Fault.LENGTH_UNCHECKED, scenario) == (
        (ServerOp.NON_FATAL_ERROR, 1.0),
        (ServerOp.RESPONSE, 0.5),
    )


@covers(Fault.EXTRA_REPLY_AFTER_ERROR)
def test_extra_reply_after_error() -> None:
    def scenario(c: Client) -> list[int]:
        return [op for op, _ in _raw(c, "set-joint-angles", joints=(0.0, 0.0, 0.0, 0.0, 0.0, 500.0))]

    assert pair(Fault.EXTRA_REPLY_AFTER_ERROR, scenario) == (
        [ServerOp.NON_FATAL_ERROR],
        [ServerOp.NON_FATAL_ERROR, ServerOp.RESPONSE],
    )


@covers(Fault.FATAL_WITHOUT_CLOSE)
def test_fatal_without_close() -> None:
    def scenario(c: Client) -> tuple[int, bool, State]:
        out = c.raw(RequestOp.CALIBRATE, b"")
        return out.packets[0].opcode, out.close, c.session.state

    clean, faulty = pair(Fault.FATAL_WITHOUT_CLOSE, scenario, base=FaultSet.parse(["calibrate-nzi"]))
    assert clean == (ServerOp.FATAL_ERROR, True, State.CLOSED)
    assert faulty == (ServerOp.FATAL_ERROR, False, State.READY)


@covers(Fault.FREE_JOINT_EXECUTES)
def test_free_joint_executes() -> None:
    def scenario(c: Client) -> tuple[bytes, bool]:
        c.one("free-joint", joint=1)
        ((_, data),) = _raw(c, "set-joint-angles", joints=GOAL)
        return data[2:], c.session.arm.moving

    assert pair(Fault.FREE_JOINT_EXECUTES, scenario) == ((b"", False), (b"\x01\x00", True))


# ------------------------------------------------------------------------------------ motion
def _motion_reply(c: Client, joints: tuple[float, ...] = GOAL) -> str:
    ((opcode, data),) = _raw(c, "set-joint-angles", joints=joints)
    if opcode == ServerOp.NON_FATAL_ERROR:
        return decode_error(opcode, data).error.code
    return f"segment {decode_reply(data, 'set-joint-angles').segment}"


@covers(Fault.NO_JOR)
def test_no_jor() -> None:
    assert pair(Fault.NO_JOR, lambda c: _motion_reply(c, (200.0, -90.0, 90.0, 0.0, 0.0, 0.0))) == (
        "JOR",
        "segment 1",
    )


@covers(Fault.SWAP_TOR_JOR)
def test_swap_tor_jor() -> None:
    beyond = (0.0, -90.0, 235.0, 0.0, 0.0, 0.0)  # joint 3 past its upper limit: no solution helps

    def scenario(c: Client) -> tuple[str, str]:
        ((opcode, data),) = _raw(
            c,
            "solve-forwards",
            transform=forward(beyond).to_floats(),
            current=(0.0, -90.0, 90.0, 0.0, 0.0, 0.0),
        )
        return decode_error(opcode, data).error.code, _motion_reply(c, beyond)

    assert pair(Fault.SWAP_TOR_JOR, scenario) == (("TOR", "JOR"), ("JOR", "TOR"))


@covers(Fault.NO_NAP)
def test_no_nap() -> None:
    assert pair(Fault.NO_NAP, _motion_reply, powered=False) == ("NAP", "segment 1")


@covers(Fault.AWA_IGNORED)
def test_awa_ignored() -> None:
    def scenario(c: Client) -> str:
        c.one("set-joint-angles", joints=GOAL)
        c.run(3.0)  # collides with the obstacle
        return _motion_reply(c, READY)

    assert pair(Fault.AWA_IGNORED, scenario, base=FaultSet.parse(["obstacle=2::-85"])) == ("AWA", "segment 2")


@covers(Fault.AWA_REFUSES_ALL)
def test_awa_refuses_all() -> None:
    def scenario(c: Client) -> tuple[str, int]:
        c.one("set-joint-angles", joints=GOAL)
        c.run(3.0)  # collides with the obstacle: motion aborted
        ((opcode, _),) = _raw(c, "joint-angles")
        return _motion_reply(c, READY), opcode

    assert pair(Fault.AWA_REFUSES_ALL, scenario, base=FaultSet.parse(["obstacle=2::-85"])) == (
        ("AWA", ServerOp.RESPONSE),
        ("AWA", ServerOp.NON_FATAL_ERROR),
    )


@covers(Fault.SPEED_UNCHECKED)
def test_speed_unchecked() -> None:
    def scenario(c: Client) -> tuple[int, float]:
        ((opcode, _),) = _raw(c, "set-speed", factor=2.0)
        return opcode, c.session.arm.speed

    assert pair(Fault.SPEED_UNCHECKED, scenario) == (
        (ServerOp.NON_FATAL_ERROR, 1.0),
        (ServerOp.RESPONSE, 1.0),
    )


# ------------------------------------------------------------------------------ asynchronous
@covers(Fault.UNREQUESTED_ASYNC)
def test_unrequested_async() -> None:
    def scenario(c: Client) -> list[int]:
        c.one("set-joint-angles", joints=GOAL)
        return [op for op, _ in _async(c, 3.0)]

    assert pair(Fault.UNREQUESTED_ASYNC, scenario) == ([], [ServerOp.ASYNCHRONOUS_RESPONSE])


@covers(Fault.ASYNC_STRAY_BYTE)
def test_async_stray_byte() -> None:
    def scenario(c: Client) -> tuple[int, int] | str:
        c.one("request-notifications", mask=2)
        c.one("set-joint-angles", joints=GOAL)
        ((_, data),) = _async(c, 3.0)
        try:
            response = decode_async(data)
        except DecodeError as exc:
            return exc.clause or ""
        return response.condition, response.word3

    assert pair(Fault.ASYNC_STRAY_BYTE, scenario) == ((2, 1), "async.layout")


# ------------------------------------------------------------------ the move process, seen from the wire
def _segments_reported(c: Client) -> list[int]:
    c.one("request-notifications", mask=2)
    for step in (10.0, 20.0):
        c.one("set-joint-angles", joints=(READY[0] + step, *READY[1:]))
    return [decode_async(d).word3 for op, d in _async(c, 4.0) if op == ServerOp.ASYNCHRONOUS_RESPONSE]


@covers(Fault.SEGMENT_REPORT_PREVIOUS)
def test_segment_report_previous() -> None:
    assert pair(Fault.SEGMENT_REPORT_PREVIOUS, _segments_reported) == ([1, 2], [0, 1])


def _joint_1_every_4_ms(c: Client) -> list[tuple[float, float]]:
    """(time, joint 1) every 4 ms through three queued moves of joint 1, read as Joint angles would be."""
    for step in (10.0, 20.0, 30.0):
        c.one("set-joint-angles", joints=(READY[0] + step, *READY[1:]))
    start, out = c.now, []
    while c.session.arm.moving:
        assert c.now - start < 30.0, "the arm never came to rest"
        c.now += 0.004
        c.session.tick(c.now)
        out.append((c.now - start, c.session.arm.actual[0]))
    return out


@covers(Fault.SEGMENTS_STOP)
def test_segments_stop() -> None:
    def longest_rest(c: Client) -> float:
        """Longest time joint 1 stays put between its first and its last change (ms)."""
        changes = [t for (t, a), (_, b) in pairwise(_joint_1_every_4_ms(c)) if a != b]
        return round(max(b - a for a, b in pairwise(changes)) * 1000)

    clean, faulty = pair(Fault.SEGMENTS_STOP, longest_rest)
    assert clean == 16 and faulty >= 100


@covers(Fault.SERVO_DOUBLE_RATE)
def test_servo_double_rate() -> None:
    def shortest_change(c: Client) -> float:
        """Shortest time between two changes of joint 1 (ms)."""
        changes = [t for (t, a), (_, b) in pairwise(_joint_1_every_4_ms(c)) if a != b]
        return round(min(b - a for a, b in pairwise(changes)) * 1000)

    assert pair(Fault.SERVO_DOUBLE_RATE, shortest_change) == (16, 8)


@covers(Fault.READY_LEAVES_WRIST)
def test_ready_leaves_wrist() -> None:
    def scenario(c: Client) -> tuple[float, ...]:
        c.one("set-joint-angles", joints=GOAL)
        c.one("ready")
        c.settle()
        return tuple(round(q, 6) for q in c.session.arm.actual)

    clean, faulty = pair(Fault.READY_LEAVES_WRIST, scenario)
    assert clean == READY and faulty == (*READY[:3], *GOAL[3:])


def _here(c: Client) -> tuple[float, ...]:
    (packet,) = _raw(c, "here")
    return tuple(decode_reply(packet[1], RequestOp.HERE).values["transform"])


@covers(Fault.INCREMENT_FROM_ACTUAL)
def test_increment_from_actual() -> None:
    def scenario(c: Client) -> float:
        start = _here(c)
        c.one("incremental-move", delta=(0.0, 0.0, -30.0, 0.0, 0.0, 0.0))
        c.one("incremental-move", delta=(25.0, 0.0, 0.0, 0.0, 0.0, 0.0))
        c.settle()
        return round(_here(c)[11] - start[11], 3)

    assert pair(Fault.INCREMENT_FROM_ACTUAL, scenario) == (-30.0, 0.0)


@covers(Fault.STRAIGHT_AS_JOINT)
def test_straight_as_joint() -> None:
    def scenario(c: Client) -> float:
        c.one("set-joint-angles", joints=(20.0, -60.0, 150.0, 0.0, -60.0, 0.0))
        c.settle()
        start = _here(c)
        goal = list(start)
        goal[9] += 80.0
        goal[10] -= 90.0
        c.one("straight-move", transform=goal)
        worst = 0.0
        while c.session.arm.moving:
            c.run(0.016)
            p = _here(c)[9:]
            # distance from the line through start and goal (both at the same height)
            a, b = start[9:11], goal[9:11]
            cross = (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
            worst = max(worst, abs(cross) / math.dist(a, b), abs(p[2] - start[11]))
        return worst

    clean, faulty = pair(Fault.STRAIGHT_AS_JOINT, scenario)
    assert clean < 0.01 and faulty > 1.0  # the conformance case allows 1 mm


@covers(Fault.STRAIGHT_TURN_FIRST)
def test_straight_turn_first() -> None:
    def scenario(c: Client) -> tuple[float, float]:
        """The share of its turn the hand has made when it is half way along a straight line that turns
        it by 30 degrees about the hand's z axis, and how far the position strays from the line."""
        c.one("set-joint-angles", joints=(20.0, -60.0, 150.0, 0.0, -60.0, 0.0))
        c.settle()
        start = Transform.from_floats(_here(c))
        goal = Transform.trans(80.0, -90.0, 0.0) @ start @ Transform.rot_z(30.0)
        c.one("straight-move", transform=goal.to_floats())
        share, off, a, b = 0.0, 0.0, start.p, goal.p
        while c.session.arm.moving:
            c.run(0.016)
            here = Transform.from_floats(_here(c))
            along = float(np.dot(here.p - a, b - a) / np.dot(b - a, b - a))
            off = max(off, float(np.linalg.norm(a + along * (b - a) - here.p)))
            if abs(along - 0.5) < 0.03:
                share = rotation_angle_deg(start.rotation.T @ here.rotation) / 30.0
        return share, off

    (clean, clean_off), (faulty, faulty_off) = pair(Fault.STRAIGHT_TURN_FIRST, scenario)
    assert abs(clean - 0.5) < 0.1 and faulty > 0.999  # half the turn made half way, or all of it
    assert clean_off < 0.01 and faulty_off < 0.01  # on the line either way


@covers(Fault.COLLISION_UNCHECKED)
def test_collision_unchecked() -> None:
    def scenario(c: Client) -> list[int]:
        c.one("set-joint-angles", joints=GOAL)
        return [op for op, _ in _async(c, 3.0)]

    clean, faulty = pair(Fault.COLLISION_UNCHECKED, scenario, base=FaultSet.parse(["obstacle=2::-85"]))
    assert clean == [ServerOp.ASYNCHRONOUS_WARNING, ServerOp.ASYNCHRONOUS_ERROR] and faulty == []


@covers(WorldCondition.SLUGGISH_JOINT)
def test_sluggish_joint() -> None:
    def scenario(c: Client) -> list[str]:
        c.one("set-joint-angles", joints=GOAL)
        return [decode_error(op, d).error.code for op, d in _async(c, 3.0)]

    assert pair(FaultSet.parse(["sluggish-joint=2:0.35"]), scenario) == ([], ["COL"])


@covers(Fault.WARNING_INTERRUPTS)
def test_warning_interrupts() -> None:
    def scenario(c: Client) -> list[int]:
        c.one("set-joint-angles", joints=GOAL)
        return [op for op, _ in _async(c, 3.0)]

    clean, faulty = pair(Fault.WARNING_INTERRUPTS, scenario, base=FaultSet.parse(["sluggish-joint"]))
    assert clean == [ServerOp.ASYNCHRONOUS_WARNING]
    assert faulty == [ServerOp.ASYNCHRONOUS_WARNING, ServerOp.ASYNCHRONOUS_ERROR]


# --------------------------------------------------------------------------------------- floats
def _solve_backwards_words(c: Client, joints: tuple[float, ...]) -> list[tuple[int, int]]:
    ((_, data),) = _raw(c, "solve-backwards", joints=joints)
    return [struct.unpack_from("<HH", data, i) for i in range(2, len(data), 4)]


@covers(Fault.UNDERFLOW_DIRTY_ZERO)
def test_underflow_dirty_zero() -> None:
    def scenario(c: Client) -> int:
        words = _solve_backwards_words(c, (0.0, 0.0, 0.0, 1e-38, 1e-38, 1e-38))
        return sum(1 for w0, w1 in words if not w0 & 0x7F80 and (w0 or w1))

    clean, faulty = pair(Fault.UNDERFLOW_DIRTY_ZERO, scenario)
    assert clean == 0 and faulty > 0


@covers(Fault.NOT_FINITE_RESERVED)
def test_not_finite_reserved() -> None:
    def scenario(c: Client) -> tuple[int, bytes]:
        far = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1e38, 1e38, 1e38)
        ((opcode, data),) = _raw(c, "solve-forwards", transform=far, current=READY)
        return opcode, data[2:6]

    clean, faulty = pair(Fault.NOT_FINITE_RESERVED, scenario)
    assert clean[0] == ServerOp.NON_FATAL_ERROR
    assert faulty == (ServerOp.RESPONSE, bytes([0, 0x80, 0, 0]))


@covers(Fault.DESCRIBE_LIMITS_SHORT)
def test_describe_limits_short() -> None:
    def scenario(c: Client) -> tuple[object, int]:
        alist = _alist(c)
        limits = alist["joint-limits"]
        assert isinstance(limits, list)
        return alist["degrees-of-freedom"], len(limits)

    assert pair(Fault.DESCRIBE_LIMITS_SHORT, scenario) == ((6, 6), (6, 5))


@covers(Fault.DESCRIBE_READY_OFF)
def test_describe_ready_off() -> None:
    def scenario(c: Client) -> tuple[float, ...]:
        c.one("set-joint-angles", joints=GOAL)
        c.settle()
        c.one("ready")
        c.settle()
        stated = _alist(c)["ready-position"]
        assert isinstance(stated, list)
        return tuple(round(float(s) - a, 6) for s, a in zip(stated, c.session.arm.actual, strict=True))

    assert pair(Fault.DESCRIBE_READY_OFF, scenario) == ((0.0,) * 6, (0.0, 10.0, 0.0, 0.0, 0.0, 0.0))


@covers(Fault.INCREMENT_O_T_SWAPPED)
def test_increment_o_t_swapped() -> None:
    def scenario(c: Client) -> tuple[float, ...]:
        c.one("set-joint-angles", joints=(20.0, -60.0, 150.0, 0.0, -60.0, 0.0))
        c.settle()
        c.one("incremental-move", delta=(0.0, 0.0, 0.0, 12.0, 0.0, 0.0))
        c.settle()
        return tuple(round(v, 3) for v in _here(c)[:9])

    clean, faulty = pair(Fault.INCREMENT_O_T_SWAPPED, scenario)
    assert clean != faulty


@covers(Fault.CONFIGURATION_IGNORED)
def test_configuration_ignored() -> None:
    seed = (20.0, -60.0, 150.0, 0.0, -60.0, 0.0)
    pose = forward(seed).to_floats()

    def scenario(c: Client) -> bool:
        solutions = []
        for value in (1, 0):
            c.one("set-configuration", configuration=value)
            solutions.append(_reply(c.one("solve-forwards", transform=pose, current=seed)).values["joints"])
        return solutions[0] != solutions[1]

    assert pair(Fault.CONFIGURATION_IGNORED, scenario) == (True, False)


@covers(Fault.KEEPS_SPEED)
@covers(Fault.KEEPS_CONFIGURATION)
@covers(Fault.KEEPS_NOTIFICATIONS)
def test_connection_keeps_state() -> None:
    """What a session takes over from the one before it: nothing, unless a connection-keeps-* fault is on
    (the driver calls inherit for each new connection)."""

    def carried(*faults: Fault) -> tuple[float, bool | None, int]:
        config = ServerConfig(powered_at_open=True, faults=FaultSet.of(*faults))
        first = Client(config)
        first.one("set-speed", factor=0.25)
        first.one("set-configuration", configuration=0)
        first.one("request-notifications", mask=3)
        second = Client(config)
        second.session.inherit(first.session)
        return second.session.arm.speed, second.session.arm.lefty, second.session.notifications

    assert carried() == (1.0, None, 0)
    assert carried(Fault.KEEPS_SPEED) == (0.25, None, 0)
    assert carried(Fault.KEEPS_CONFIGURATION) == (1.0, False, 0)
    assert carried(Fault.KEEPS_NOTIFICATIONS) == (1.0, None, 3)


# ------------------------------------------------------------------- the driver and the wrist
@covers(WorldCondition.WRIST_SILENT)
@covers(Fault.WRIST_TIMEOUT_SILENT)
def test_wrist_silent_and_timeout() -> None:
    def read_forces(*faults: str) -> str:
        sim = CougarSim(seed=1)
        client = WristClient(CougarWrist(SimPort(sim)), config=ServerConfig(faults=FaultSet.parse(faults)))
        client.run(0.1)
        try:
            answer = client.call("read-forces", limit=2.0)
        except AssertionError:
            return "no answer"
        return answer.error.code if isinstance(answer, ErrorReply) else "forces"

    assert read_forces() == "forces"
    assert read_forces("wrist-silent") == "WNR"
    assert read_forces("wrist-silent", "wrist-timeout-silent") == "no answer"


def _conform(select: str, *faults: str) -> int:
    args = ["run", "--select", select, "--seed", "7"]
    for fault in faults:
        args += ["--server-fault", fault]
    return CliRunner().invoke(conform_main, args).exit_code


@covers(Fault.CLOSE_KEEPS_MOVING)
@covers(Fault.GUARD_HIT_WORD_SWAPPED)
def test_driver_and_wrist_faults_against_their_cases() -> None:
    """Faults of the driver (what outlives a connection) and of the wrist's reports: the embedded run
    of their case passes clean and fails with the fault."""
    for fault, select in (
        ("close-keeps-moving", "server.connect.close-stops-arm"),
        ("guard-hit-word-swapped", "server.async.guard-hit"),
    ):
        assert (_conform(select), _conform(select, fault)) == (0, 1), fault


PROTOCOL_PACKAGES = ("reference_server", "arm", "cougar")
"""The packages whose code reads as the protocol: the reference server, the arm and the Cougar."""
REGISTRIES = {"reference_server/faults.py", "reference_server/defects.py", "cougar/faults.py"}
"""Where fault switches are declared, and turned into hook points and defect values."""
SWITCH_CLASSES = {"Fault", "CougarFault", "ClientFault"}


def test_no_protocol_module_tests_a_fault() -> None:
    """The protocol code reads as the protocol: no module of the reference server, the arm or the Cougar
    tests a fault switch (``Fault.X in ...``, ``is``, ``==``, or a switch's name as a string) but those
    that declare them and those that turn them into hook points and defect values
    (:data:`REGISTRIES`); the session names none at all.  A defect reaches the arm, the wrist and the
    Cougar as a value they are given (``ArmDefects``, ``WristDefects``, ``CougarDefects``,
    ``LinkDefects``), never as a flag set on them afterwards."""
    root = Path(manip.__file__).parent
    names = {f.value for f in Fault} | {f.value for f in CougarFault}
    defect_fields = {f.name for f in dataclasses.fields(ArmDefects)}
    tests, flags = [], []
    for package in PROTOCOL_PACKAGES:
        for path in sorted((root / package).glob("*.py")):
            where = f"{package}/{path.name}"
            if where in REGISTRIES:
                continue
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if isinstance(node, ast.Compare) and any(
                    _names_a_fault(n, names) for n in (node.left, *node.comparators)
                ):
                    tests.append(f"{where}:{node.lineno}")
                if isinstance(node, ast.Assign | ast.AugAssign):
                    targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                    flags += [
                        f"{where}:{node.lineno}"
                        for t in targets
                        if isinstance(t, ast.Attribute) and t.attr in defect_fields
                    ]
    assert not tests, tests
    assert not flags, flags
    assert "Fault." not in (root / "reference_server" / "session.py").read_text(encoding="utf-8")


def test_the_guard_sees_a_fault_tested() -> None:
    """The scan of :func:`test_no_protocol_module_tests_a_fault` finds each way of testing a switch."""
    names = {"rst-ignored"}
    for source in ('"rst-ignored" in faults', "Fault.NO_JOR in on", "x is CougarFault.RST_IGNORED"):
        (compare,) = [n for n in ast.walk(ast.parse(source)) if isinstance(n, ast.Compare)]
        assert any(_names_a_fault(n, names) for n in (compare.left, *compare.comparators)), source
    assert not _names_a_fault(ast.parse('"relocated-map"', mode="eval").body, names)


def _names_a_fault(node: ast.expr, names: set[str]) -> bool:
    if isinstance(node, ast.Constant):
        return node.value in names
    return (
        isinstance(node, ast.Attribute)
        and isinstance(node.value, ast.Name)
        and node.value.id in SWITCH_CLASSES
    )


def _tour(client: Client) -> list[tuple[int, bytes]]:
    """A session's every packet through a tour of its paths: initial response, describe self, replies
    of each form, refusals (unknown opcode, bad length, bad value, JOR, TOR), motion with segment
    reports, free joint and the packet after it, calibrate."""
    out = [(p.opcode, p.data) for p in client.initial.packets]
    steps: list[tuple[str, bytes | None, dict[str, object]]] = [
        ("describe-self", None, {}),
        ("request-notifications", None, {"mask": 3}),
        ("set-speed", None, {"factor": 0.5}),
        ("set-speed", None, {"factor": 2.0}),
        ("set-configuration", None, {"configuration": 1}),
        ("set-joint-angles", None, {"joints": GOAL}),
        ("incremental-move", None, {"delta": (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)}),
        ("set-joint-angles", None, {"joints": (400.0, 0.0, 0.0, 0.0, 0.0, 0.0)}),
        (
            "solve-forwards",
            None,
            {"transform": (*forward(GOAL).to_floats()[:9], 9e3, 9e3, 9e3), "current": READY},
        ),
        ("here", b"\0\0", {}),
        ("ready", None, {}),
        ("free-joint", None, {"joint": 2}),
        ("here", None, {}),
        ("joint-angles", None, {}),
    ]
    for name, data, values in steps:
        out += _packets(
            client.raw(SPEC.request(name).opcode, encode_request(name, **values) if data is None else data)
        )
        for _ in range(40):
            client.now += TICK
            out += _packets(client.session.tick(client.now))
    out += _packets(client.raw(0o277, b""))
    out += _packets(client.raw(SPEC.request("calibrate").opcode, b""))
    return out


def test_switched_defects_with_nothing_on_bend_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every hook of SwitchedDefects passes the protocol through unchanged while its faults are off: a
    session made to use it with an empty fault set sends what a conforming one (plain Defects) sends;
    and one switch does change the tour (so the comparison can fail)."""
    clean = _tour(Client(ServerConfig(powered_at_open=True)))
    assert type(Client().session.defects) is Defects
    monkeypatch.setattr(session_module, "defects_for", SwitchedDefects)
    switched = Client(ServerConfig(powered_at_open=True))
    assert type(switched.session.defects) is SwitchedDefects
    assert _tour(switched) == clean
    bent = Client(ServerConfig(powered_at_open=True, faults=FaultSet.of(Fault.SEGMENT_REPORT_PREVIOUS)))
    assert _tour(bent) != clean


# ------------------------------------------------------------------- defects on the world's paths
def _fatal_of_calibrate(c: Client) -> tuple[int, str]:
    c.one("enable-power")
    out = c.raw(RequestOp.CALIBRATE, b"")
    error = decode_error(out.packets[0].opcode, out.packets[0].data)
    return error.request_number, error.error.severity


@covers(Fault.FATAL_NUMBER_PREVIOUS)
@covers(Fault.FATAL_SEVERITY_E)
def test_fatal_error_number_and_severity() -> None:
    nzi = FaultSet.parse(["calibrate-nzi"])
    clean, previous = pair(Fault.FATAL_NUMBER_PREVIOUS, _fatal_of_calibrate, base=nzi)
    assert previous == (clean[0] - 1, "F") and clean[1] == "F"
    _, severity_e = pair(Fault.FATAL_SEVERITY_E, _fatal_of_calibrate, base=nzi)
    assert severity_e == (clean[0], "E")


@covers(Fault.ASYNC_NUMBER_PREVIOUS)
def test_warning_number_previous() -> None:
    def scenario(c: Client) -> tuple[int, int]:
        c.one("enable-power")
        c.one("set-joint-angles", joints=GOAL)
        processed = c.session.last_processed or 0
        ((_, data),) = [p for p in _async(c, 3.0) if p[0] == ServerOp.ASYNCHRONOUS_WARNING][:1]
        return int.from_bytes(data[:2], "little"), processed

    base = FaultSet.parse(["sluggish-joint"])
    (clean, processed), (faulty, _) = pair(Fault.ASYNC_NUMBER_PREVIOUS, scenario, base=base)
    assert clean == processed and faulty == processed - 1


@covers(Fault.WRIST_ERROR_FATAL)
def test_wrist_error_fatal() -> None:
    def read_forces(*faults: str) -> tuple[int, str]:
        client = WristClient(
            CougarWrist(SimPort(CougarSim(seed=1))), config=ServerConfig(faults=FaultSet.parse(faults))
        )
        client.run(0.1)
        answer = client.call("read-forces", limit=2.0)
        assert isinstance(answer, ErrorReply)
        return answer.opcode, answer.error.severity

    assert read_forces("wrist-silent") == (ServerOp.NON_FATAL_ERROR, "E")
    assert read_forces("wrist-silent", "wrist-error-fatal") == (ServerOp.FATAL_ERROR, "F")


@covers(Fault.ABORT_KEEPS_QUEUE)
def test_abort_keeps_queue() -> None:
    def scenario(c: Client) -> bool:
        c.one("enable-power")
        for goal in (GOAL, OTHER, GOAL):
            c.one("set-joint-angles", joints=goal)
        c.run(0.2)
        c.session.arm.press_panic(at=c.now)
        c.run(0.1)
        c.one("enable-power")
        c.run(0.5)
        return c.session.arm.moving

    assert pair(Fault.ABORT_KEEPS_QUEUE, scenario) == (False, True)


@covers(Fault.FATAL_DROPS_LINK)
def test_fatal_drops_link_against_its_case() -> None:
    """A fault of the driver: the embedded run of the fatal-error case passes clean and fails with it."""
    select = "server.error.fatal-then-close"
    assert (_conform(select), _conform(select, "fatal-drops-link")) == (0, 1)


# ------------------------------------------------------------------------- found from outside (issue 32)
@covers(Fault.FATAL_EOF_WITHOUT_CLS)
def test_fatal_eof_without_cls_against_its_case() -> None:
    """A fault of the driver: EOF then the link dropped; the fatal-error case passes clean and fails
    with it (the EOF alone was taken for the CLS before)."""
    select = "server.error.fatal-then-close"
    assert (_conform(select), _conform(select, "fatal-eof-without-cls")) == (0, 1)


@covers(Fault.KEEPS_ABORT)
def test_connection_keeps_abort() -> None:
    def carried(*faults: Fault) -> str:
        config = ServerConfig(powered_at_open=True, faults=FaultSet.of(*faults))
        first = Client(config)
        first.one("set-joint-angles", joints=GOAL)
        first.one("kill-power")
        first.run(0.1)
        assert _motion_reply(first) == "AWA"
        second = Client(config)
        second.session.inherit(first.session)
        return _motion_reply(second)

    assert (carried(), carried(Fault.KEEPS_ABORT)) == ("segment 1", "AWA")


@covers(Fault.NZI_MASK_SHIFTED)
def test_nzi_mask_shifted() -> None:
    def scenario(c: Client) -> tuple[int, ...]:
        ((opcode, data),) = _packets(c.raw(RequestOp.CALIBRATE, b""))
        return decode_error(opcode, data).error.args

    assert pair(Fault.NZI_MASK_SHIFTED, scenario, base=FaultSet.parse(["calibrate-nzi=2,3"])) == ((6,), (12,))


@covers(Fault.CONFIGURATION_SWAPPED)
def test_configuration_swapped() -> None:
    seed = (20.0, -60.0, 150.0, 0.0, -60.0, 0.0)  # a lefty solution
    pose = forward(seed).to_floats()

    def scenario(c: Client) -> float:
        c.one("set-configuration", configuration=1)
        return float(_reply(c.one("solve-forwards", transform=pose, current=seed)).values["joints"][0])

    clean, faulty = pair(Fault.CONFIGURATION_SWAPPED, scenario)
    assert round(clean, 3) == 20.0 and round(faulty, 3) != 20.0


@covers(Fault.JOINTS_REVERSED)
def test_joints_reversed() -> None:
    def scenario(c: Client) -> tuple[tuple[float, ...], tuple[float, ...]]:
        c.one("set-joint-angles", joints=GOAL)
        c.settle()
        (packet,) = _raw(c, "joint-angles")
        return tuple(decode_reply(packet[1], RequestOp.JOINT_ANGLES).values["joints"]), c.session.arm.actual

    (said, actual), (said_faulty, actual_faulty) = pair(Fault.JOINTS_REVERSED, scenario)
    assert said == actual == tuple(GOAL)
    assert actual_faulty == tuple(reversed(GOAL)) and said_faulty == tuple(GOAL)  # consistent on the wire


def _forces(*faults: str) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Read forces at rest, then again after set weight of a 64 oz object the hand does not hold."""
    client = WristClient(
        CougarWrist(SimPort(CougarSim(seed=1))), config=ServerConfig(faults=FaultSet.parse(faults))
    )
    client.run(0.1)
    rest = client.call("read-forces", limit=2.0)
    client.call("set-weight", weight=64.0, cg=(0.0, 0.0, 0.0))
    client.run(0.1)
    loaded = client.call("read-forces", limit=2.0)
    assert not isinstance(rest, ErrorReply) and not isinstance(loaded, ErrorReply)
    return tuple(rest.values["forces"]), tuple(loaded.values["forces"])


@covers(Fault.FORCES_IN_POUNDS)
@covers(Fault.FORCES_STALE)
def test_forces_in_pounds_and_stale() -> None:
    rest, loaded = _forces()
    assert round(math.dist(rest[:3], loaded[:3])) == 64
    rest, loaded = _forces("forces-in-pounds")
    assert round(math.dist(rest[:3], loaded[:3])) == 4
    rest, loaded = _forces("forces-stale")
    assert rest == loaded


@covers(Fault.ASYNC_SPLITS_MULTI)
def test_async_splits_multi() -> None:
    def scenario(c: Client) -> tuple[int, list[int]]:
        c.one("request-notifications", mask=2)
        c.one("set-joint-angles", joints=GOAL)
        during = len(c.run(8.0))  # the segment completes: its report goes out, or waits
        return during, [op for op, _ in _raw(c, "describe-self")]

    (clean_during, clean), (faulty_during, faulty) = pair(Fault.ASYNC_SPLITS_MULTI, scenario)
    assert clean_during == 1 and set(clean) == {ServerOp.RESPONSE}
    assert faulty_during == 0 and faulty[0] == faulty[-1] == ServerOp.RESPONSE
    assert ServerOp.ASYNCHRONOUS_RESPONSE in faulty[1:-1]


@covers(Fault.JOINT_MOVES_STRAIGHT)
def test_joint_moves_straight() -> None:
    seed = (20.0, -60.0, 150.0, 0.0, -60.0, 0.0)
    goal = list(forward(seed).to_floats())
    goal[9:12] = [goal[9] + 60.0, goal[10] + 150.0, goal[11] - 80.0]

    def spread(c: Client) -> float:
        """How far apart the joints' fractions of their ways get during a Move."""
        c.one("set-joint-angles", joints=seed)
        c.settle()
        c.one("move", transform=goal)
        path = []
        while c.session.arm.moving:
            c.run(0.05)
            path.append(c.session.arm.actual)
        end = path[-1]
        return max(
            max(fractions) - min(fractions)
            for q in path
            if (
                fractions := [
                    (q[i] - seed[i]) / (end[i] - seed[i]) for i in range(6) if abs(end[i] - seed[i]) > 2
                ]
            )
        )

    clean, faulty = pair(Fault.JOINT_MOVES_STRAIGHT, spread)
    assert clean < 1e-6 and faulty > 0.1


@covers(Fault.SPEED_IGNORED)
def test_speed_ignored() -> None:
    def seconds_to_goal(c: Client) -> float:
        """How long a move to GOAL takes after set speed 0.25 (the factor itself is still checked)."""
        refused = c.one("set-speed", factor=2.0)
        assert isinstance(refused, ErrorReply) and refused.error.code == "BVA"
        c.one("set-speed", factor=0.25)
        c.one("set-joint-angles", joints=GOAL)
        start = c.now
        while c.session.arm.moving:
            c.run(0.1)
        return round(c.now - start, 1)

    clean, faulty = pair(Fault.SPEED_IGNORED, seconds_to_goal)
    assert clean > 3 * faulty > 0


@covers(Fault.QUEUE_REVERSED)
def test_queue_reversed() -> None:
    def completed(c: Client) -> list[int]:
        """The segments reported complete, in order, of three moves queued at once."""
        c.one("request-notifications", mask=0b10)
        for goal in (GOAL, OTHER, GOAL):
            c.one("set-joint-angles", joints=goal)
        return [int.from_bytes(d[6:8], "little") for _, d in _async(c, 20.0)]

    assert pair(Fault.QUEUE_REVERSED, completed) == ([1, 2, 3], [1, 3, 2])


# ----------------------------------------------------------- clauses no fault proved before (issue 32)
@covers(Fault.CALIBRATE_REPLIES_MASK)
@covers(Fault.KILL_POWER_REPLIES_STATE)
@covers(Fault.ENABLE_POWER_REPLIES_STATE)
def test_done_replies_carry_a_word() -> None:
    def scenario(c: Client) -> list[bytes]:
        return [_raw(c, op)[0][1][2:] for op in ("calibrate", "kill-power", "enable-power")]

    assert pair(Fault.CALIBRATE_REPLIES_MASK, scenario) == ([b""] * 3, [b"\x3f\x00", b"", b""])
    assert pair(Fault.KILL_POWER_REPLIES_STATE, scenario) == ([b""] * 3, [b"", b"\x00\x00", b""])
    assert pair(Fault.ENABLE_POWER_REPLIES_STATE, scenario) == ([b""] * 3, [b"", b"", b"\x01\x00"])


@covers(Fault.NZI_MASK_IN_TEXT)
def test_nzi_mask_in_text() -> None:
    def scenario(c: Client) -> tuple[tuple[int, ...], bool, str]:
        ((opcode, data),) = _packets(c.raw(RequestOp.CALIBRATE, b""))
        error = decode_error(opcode, data).error
        return error.args, error.has_nul, error.message

    clean, faulty = pair(Fault.NZI_MASK_IN_TEXT, scenario, base=FaultSet.parse(["calibrate-nzi=2,3"]))
    assert clean[:2] == ((6,), True) and "$" in clean[2]
    assert faulty == ((), False, "No zero index found on joints 2 3")


@covers(Fault.SET_CONFIGURATION_WORD_ONLY)
@covers(Fault.HAND_FLAG_ONLY)
def test_request_data_read_narrowly() -> None:
    done, error = ServerOp.RESPONSE, ServerOp.NON_FATAL_ERROR

    def configurations(c: Client) -> list[int]:
        return [_raw(c, "set-configuration", data)[0][0] for data in (b"\x01", b"\x01\x00", b"\x00")]

    assert pair(Fault.SET_CONFIGURATION_WORD_ONLY, configurations) == ([done] * 3, [error, done, error])

    def hands(c: Client) -> list[int]:
        return [_raw(c, "hand", amount=amount)[0][0] for amount in (0, 1, 2, 0o400, 0o177777)]

    assert pair(Fault.HAND_FLAG_ONLY, hands) == ([done] * 5, [done, done, error, error, error])


@covers(Fault.FREE_JOINT_FROM_ZERO)
def test_free_joint_from_zero() -> None:
    def scenario(c: Client) -> list[tuple[int, int | None]]:
        out = []
        for joint in (0, 1, 6):
            ((opcode, _),) = _raw(c, "free-joint", joint=joint)
            out.append((opcode, c.session.arm.free_joint))
            if opcode == ServerOp.RESPONSE:
                _raw(c, "here")  # the packet after free joint, discarded
        return out

    done, error = ServerOp.RESPONSE, ServerOp.NON_FATAL_ERROR
    assert pair(Fault.FREE_JOINT_FROM_ZERO, scenario) == (
        [(error, None), (done, 1), (done, 6)],
        [(done, 1), (done, 2), (error, None)],
    )


@covers(Fault.INCREMENT_ANGLES_FIRST)
def test_increment_angles_first() -> None:
    def scenario(c: Client) -> tuple[float, ...]:
        c.one("set-joint-angles", joints=(20.0, -60.0, 150.0, 0.0, -60.0, 0.0))
        c.settle()
        before = _here(c)
        c.one("incremental-straight-move", delta=(0.0, 0.0, 0.0, 3.0, 0.0, 0.0))
        c.settle()
        return tuple(round(b - a, 3) for a, b in zip(before[9:], _here(c)[9:], strict=True))

    clean, faulty = pair(Fault.INCREMENT_ANGLES_FIRST, scenario)
    assert clean == (0.0, 0.0, 0.0) and faulty == (3.0, 0.0, 0.0)  # dO read as dX (millimetres)


@covers(Fault.MOTION_REPLY_AT_REST)
def test_motion_reply_at_rest() -> None:
    def scenario(c: Client) -> tuple[int, bool]:
        answered = len(_raw(c, "set-joint-angles", joints=GOAL)) + len(_raw(c, "here"))
        for _ in range(1000):  # 16 s
            if answered == 2:
                break
            c.now += 0.016
            answered += sum(op == ServerOp.RESPONSE for op, _ in _packets(c.session.tick(c.now)))
        return answered, c.session.arm.moving

    assert pair(Fault.MOTION_REPLY_AT_REST, scenario) == ((2, True), (2, False))


@covers(Fault.POWER_KEEPS_ABORT)
def test_power_keeps_abort() -> None:
    def scenario(c: Client) -> str:
        c.one("set-joint-angles", joints=GOAL)
        c.one("kill-power")
        c.run(0.1)
        c.one("enable-power")
        return _motion_reply(c)

    assert pair(Fault.POWER_KEEPS_ABORT, scenario) == ("segment 2", "AWA")


@covers(Fault.ASYNC_CODES_FROM_BITS)
def test_async_codes_from_bits() -> None:
    def scenario(c: Client) -> list[int]:
        c.one("request-notifications", mask=3)
        c.one("set-joint-angles", joints=GOAL)
        return [
            decode_async(data).condition
            for op, data in _async(c, 5.0)
            if op == ServerOp.ASYNCHRONOUS_RESPONSE
        ]

    assert pair(Fault.ASYNC_CODES_FROM_BITS, scenario) == ([2], [1])


@covers(Fault.SECOND_CLIENT_ADMITTED)
def test_second_client_admitted_against_its_case() -> None:
    """A fault of the driver: the one-server-per-robot case (a SHOULD: --strict counts it) passes clean
    and fails with it."""
    select = "server.connect.one-server-per-robot"
    runs = [
        CliRunner().invoke(conform_main, ["run", "--select", select, "--seed", "7", "--strict", *faults])
        for faults in ((), ("--server-fault", "second-client-admitted"))
    ]
    assert [run.exit_code for run in runs] == [0, 1], [run.output for run in runs]


@covers(Fault.COMMAND_LEAD)
def test_command_lead() -> None:
    def scenario(c: Client) -> tuple[float, float]:
        start = c.session.arm.actual
        goal = (start[0] + 30.0, *start[1:])
        c.one("set-joint-angles", joints=goal)
        past = 0.0
        for _ in range(400):
            c.run(0.016)
            past = max(past, c.session.arm.actual[0] - goal[0])
        return round(past, 3), round(c.session.arm.actual[0] - goal[0], 6)

    clean, faulty = pair(Fault.COMMAND_LEAD, scenario)
    assert clean == (0.0, 0.0) and faulty[0] > 0.1 and faulty[1] == 0.0


# ------------------------------------------------------------ the wire's layouts (issue 32)
def _floats(data: bytes) -> list[float]:
    """The floats of a reply's data after the request number."""
    return [unpack_f(data[i : i + 4]) for i in range(2, len(data) - 3, 4)]


def _description(c: Client) -> str:
    return "".join(str(decode_reply(d, "describe-self").values.get("text", "")) for d in _describe(c))


def _read_clause(text: str, base: int = 8) -> str | None:
    """The clause reading ``text`` as an alist breaks (None: it reads)."""
    try:
        read_alist(text, base=base)
    except DecodeError as exc:
        return exc.clause
    return None


@covers(Fault.RESERVED_FLOAT_AS_ZERO)
def test_reserved_float_as_zero() -> None:
    reserved = struct.pack("<HH", 0x8000, 0) + encode_request("solve-backwards", joints=READY)[4:]
    clean, faulty = pair(Fault.RESERVED_FLOAT_AS_ZERO, lambda c: _raw(c, "solve-backwards", reserved)[0])
    assert clean[0] == ServerOp.NON_FATAL_ERROR and decode_error(*clean).error.code == "BFL"
    ((_, zero),) = _raw(Client(), "solve-backwards", joints=(0.0, *READY[1:]))
    assert faulty[0] == ServerOp.RESPONSE and faulty[1][2:] == zero[2:]


@covers(Fault.REQUEST_NUMBER_HIGH_FIRST)
def test_request_number_high_byte_first() -> None:
    def scenario(c: Client) -> tuple[bytes, int]:
        ((_, data),) = _raw(c, "here")
        return data[:2], c.packet_no

    (clean, number), (faulty, _) = pair(Fault.REQUEST_NUMBER_HIGH_FIRST, scenario)
    assert clean == number.to_bytes(2, "little") != faulty == number.to_bytes(2, "big")


@covers(Fault.DATA_REPLIES_DWD)
def test_data_replies_dwd() -> None:
    def scenario(c: Client) -> list[int]:
        return [opcode for op in ("here", "enable-power", "describe-self") for opcode, _ in _raw(c, op)[:1]]

    assert pair(Fault.DATA_REPLIES_DWD, scenario) == ([0o200] * 3, [0o300, 0o200, 0o200])


@covers(Fault.DONE_WITH_WORD)
def test_done_with_zero_word() -> None:
    clean, faulty = pair(Fault.DONE_WITH_WORD, lambda c: _raw(c, "enable-power")[0][1])
    assert len(clean) == 2 and faulty == clean + b"\0\0"


@covers(Fault.DATA_LENGTH_WORD)
def test_data_length_word() -> None:
    clean, faulty = pair(Fault.DATA_LENGTH_WORD, lambda c: _raw(c, "joint-angles")[0][1])
    assert len(clean) == 26 and faulty == clean[:2] + (24).to_bytes(2, "little") + clean[2:]


@covers(Fault.MOTION_REPLY_DONE)
def test_motion_reply_done() -> None:
    clean, faulty = pair(Fault.MOTION_REPLY_DONE, lambda c: _raw(c, "set-joint-angles", joints=GOAL)[0][1])
    assert decode_reply(clean, "set-joint-angles").segment == 1 and faulty == clean[:2]


@covers(Fault.DESCRIBE_DONE)
def test_describe_self_done() -> None:
    clean, faulty = pair(Fault.DESCRIBE_DONE, _describe)
    assert len(clean) > 1 and faulty == clean[-1:] and len(faulty[0]) == 2


@covers(Fault.DESCRIBE_UNCLOSED)
def test_describe_unclosed() -> None:
    clean, faulty = pair(Fault.DESCRIBE_UNCLOSED, _description)
    assert _read_clause(clean) is None and _read_clause(faulty) == "describe.alist-readable"
    assert read_alist(faulty + ")") == read_alist(clean)


@covers(Fault.DESCRIBE_KEY_TWICE)
def test_describe_key_twice() -> None:
    clean, faulty = pair(Fault.DESCRIBE_KEY_TWICE, _description)
    assert _read_clause(clean) is None and _read_clause(faulty) == "describe.alist-shape"
    assert faulty.count(":SOFTWARE-VERSION") == 2


@covers(Fault.DESCRIBE_DECIMAL)
def test_describe_decimal() -> None:
    clean, faulty = pair(Fault.DESCRIBE_DECIMAL, _description)
    assert _read_clause(clean) is None and _read_clause(faulty) == "describe.numbers-octal"
    assert read_alist(faulty, base=10) == read_alist(clean)


DESCRIBE_TYPES = [
    (Fault.DESCRIBE_BRAND_SYMBOL, "brand-name", Symbol),
    (Fault.DESCRIBE_UNIQUE_NUMBER, "unique-name", int),
    (Fault.DESCRIBE_DOF_STRING, "degrees-of-freedom", str),
]
"""Each fault that writes a describe-self value as another type: the key, and the type it is written as."""
COVERED.update(fault for fault, *_ in DESCRIBE_TYPES)


@pytest.mark.parametrize(("fault", "key", "kind"), DESCRIBE_TYPES, ids=[f.value for f, *_ in DESCRIBE_TYPES])
def test_describe_key_written_as_another_type(fault: Fault, key: str, kind: type) -> None:
    clean, faulty = pair(fault, lambda c: _alist(c)[key])
    assert not isinstance(clean, kind) and isinstance(faulty, kind)


@covers(Fault.DESCRIBE_OPERATION_NAMES)
def test_describe_operation_names() -> None:
    clean, faulty = pair(Fault.DESCRIBE_OPERATION_NAMES, lambda c: _alist(c)["operations"])
    assert isinstance(clean, list) and isinstance(faulty, list) and len(clean) == len(faulty)
    assert SPEC.request("here").opcode in clean and Symbol("here") in faulty
    assert all(isinstance(o, Symbol) for o in faulty)


ERROR_PARTS = [
    (Fault.WHERE_WITH_COLON, "where", "PUMA:dispatch"),
    (Fault.SEVERITY_LOWER_CASE, "severity", "c"),
    (Fault.ERROR_CODE_NUMBERS, "code", f"{list(SPEC.error_codes).index('UOP'):03o}"),
]
"""Each fault that writes a part of an error string otherwise: the part, and how C UOP's is written."""
COVERED.update(fault for fault, *_ in ERROR_PARTS)


@pytest.mark.parametrize(("fault", "part", "written"), ERROR_PARTS, ids=[f.value for f, *_ in ERROR_PARTS])
def test_error_string_part_written_otherwise(fault: Fault, part: str, written: str) -> None:
    clean, faulty = pair(
        fault, lambda c: getattr(decode_error(ServerOp.NON_FATAL_ERROR, _uop(c)).error, part)
    )
    assert clean == {"where": "dispatch", "severity": "C", "code": "UOP"}[part] and faulty == written


@covers(Fault.ERROR_ARGS_BYTES)
def test_error_args_bytes() -> None:
    clean, faulty = pair(Fault.ERROR_ARGS_BYTES, _uop)
    assert decode_error(ServerOp.NON_FATAL_ERROR, clean).error.args == (0o230,)
    assert faulty[faulty.index(0, 2) :] == bytes([0, 0o230])


@covers(Fault.HERE_ROW_MAJOR)
def test_here_row_major() -> None:
    clean, faulty = pair(Fault.HERE_ROW_MAJOR, lambda c: _floats(_raw(c, "here")[0][1]))
    assert faulty == [clean[column * 3 + row] for row in range(3) for column in range(4)] != clean


@covers(Fault.SOLVE_FORWARDS_RADIANS)
def test_solve_forwards_radians() -> None:
    def scenario(c: Client) -> list[float]:
        ((_, here),) = _raw(c, "here")
        return _floats(_raw(c, "solve-forwards", transform=_floats(here), current=READY)[0][1])

    clean, faulty = pair(Fault.SOLVE_FORWARDS_RADIANS, scenario)
    assert faulty == pytest.approx([math.radians(q) for q in clean], rel=1e-6) and clean != faulty


@covers(Fault.SOLVE_BACKWARDS_RADIANS)
def test_solve_backwards_radians() -> None:
    angles = (0.1, -0.5, 0.6, 0.0, 0.2, 0.0)
    clean, faulty = pair(
        Fault.SOLVE_BACKWARDS_RADIANS, lambda c: _floats(_raw(c, "solve-backwards", joints=angles)[0][1])
    )
    degrees = _floats(_raw(Client(), "solve-backwards", joints=[math.degrees(q) for q in angles])[0][1])
    assert faulty == pytest.approx(degrees, abs=1e-3) and faulty != pytest.approx(clean, abs=1e-3)


@covers(Fault.UNDERFLOW_CLAMPED)
def test_underflow_clamped() -> None:
    def scenario(c: Client) -> int:
        tiny = _floats(_raw(c, "solve-backwards", joints=(0.0, 0.0, 0.0, 1e-38, 1e-38, 1e-38))[0][1])
        return sum(1 for v in tiny if abs(v) == F_MIN_NORMAL)

    clean, faulty = pair(Fault.UNDERFLOW_CLAMPED, scenario)
    assert clean == 0 and faulty > 0
