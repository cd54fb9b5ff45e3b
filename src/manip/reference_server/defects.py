"""Where the reference server's fault switches bend the protocol: the session's hook points.

The session (:mod:`manip.reference_server.session`) is written as the protocol reads.  At a few named
points it hands what it is about to do to its :class:`Defects` and does what comes back: the number a
reply carries, the packets of a reply, the error an error packet says, what follows a fatal error...
:class:`Defects` itself is the conforming server: every hook is the identity (or does nothing).
:class:`SwitchedDefects` overrides each hook as the fault switches of a
:class:`~manip.reference_server.faults.FaultSet` say, and :func:`defects_for` chooses one of the two once,
when a session is made.  The protocol code never tests a fault; only this module does.

The hook points, by what they decide:

* the connection: :attr:`~Defects.arm` and :attr:`~Defects.wrist` (the defects the move process and the
  wrist a connection runs with are given, as values), :meth:`~Defects.inherit` (what a new connection
  keeps of the last), :attr:`~Defects.keeps_arm_after_close` and :attr:`~Defects.admits_second_client`
  (the driver's);
* request numbers: :meth:`~Defects.initial_numbers`, :meth:`~Defects.reply_number`;
* when a held-back reply packet goes out: :meth:`~Defects.held_back` (at the servo tick, given the arm);
* serving a request: :meth:`~Defects.decode`, :meth:`~Defects.check`, :meth:`~Defects.refused`,
  :meth:`~Defects.wrist_failure`, :attr:`~Defects.discards_after_free_joint`;
* what a request does: :meth:`~Defects.describe`, :meth:`~Defects.describe_text`, :meth:`~Defects.increment`,
  :meth:`~Defects.move_ready`,
  :meth:`~Defects.configuration`,

  :meth:`~Defects.set_speed`,
  :attr:`~Defects.straight_lines`, :attr:`~Defects.joint_moves`, :attr:`~Defects.checks_joint_limits`,
  :attr:`~Defects.applies_configuration`;
* replies: :meth:`~Defects.payload`, :meth:`~Defects.reply`, :meth:`~Defects.reply_opcode`;
* errors: :meth:`~Defects.error_number`, :meth:`~Defects.error`, :meth:`~Defects.error_string`,
  :meth:`~Defects.after_error`, :attr:`~Defects.after_fatal` (the driver's too);
* asynchronous packets: :meth:`~Defects.notifications`, :meth:`~Defects.async_response`,
  :meth:`~Defects.reports_guard`, :meth:`~Defects.after_warning`;
* the packets sent: :meth:`~Defects.sent` (their order, one step of the session at a time).

The conditions of the arm's world (the panic button, an obstacle, a calibration failure, a sluggish joint,
a silent wrist) are not defects: the session meets them through
:class:`~manip.reference_server.conditions.WorldConditions`, conforming or not.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any, Final, Literal

from manip.arm.sim import AbortCause, ArmDefects, ArmEvent, ArmSim, Refused
from manip.codecs.error_string import ErrorMessage
from manip.codecs.errors import DecodeError
from manip.codecs.lisp import Keyword, LispValue, Symbol, alist_to_dict, cons, print_lisp, read_lisp
from manip.codecs.lispm_text import encode_lispm
from manip.codecs.messages import Value, decode_request, encode_async
from manip.codecs.pdp11float import F_MIN_NORMAL, pack_f
from manip.ncp.defects import ChaosDefects
from manip.reference_server import errors
from manip.reference_server.describe import Statement, alist_text
from manip.reference_server.errors import RequestError
from manip.reference_server.faults import Fault, FaultSet
from manip.reference_server.wrist import GuardHit, WristDefects
from manip.spec import SPEC, Field, RequestName, RequestOpcode
from manip.spec.constants import (
    ASYNC_ERROR_OPS,
    ASYNC_OPS,
    AsyncCondition,
    ChaosOp,
    ServerOp,
)

if TYPE_CHECKING:
    from manip.reference_server.session import Outgoing, ServerSession

__all__ = ["AfterFatal", "Defects", "SwitchedDefects", "arm_defects", "chaos_defects", "defects_for"]

AfterFatal = Literal["close", "stay-open", "drop-link", "eof-drop-link"]
"""What follows a fatal error: the connection closes (the protocol), it stays open, the driver drops
the link under it without closing it, or the driver sends EOF and drops the link before the CLS."""
Encoder = Callable[[RequestOpcode, Mapping[str, Any]], bytes]
"""The session's encoder of a reply's values (after the request number)."""

WORD_MASK: Final = 0xFFFF
MISSING_OPERATION: Final[RequestName] = "solve-backwards"
"""The served opcode describe self leaves out under the ``describe-missing-operation`` fault."""
NARROWED_DEG: Final = 5.0
"""How much narrower than the arm's each joint range is stated under ``describe-narrow-limits``."""
READY_OFF_DEG: Final = 10.0
"""How far from where move to ready goes joint 2 of :ready-position is stated under ``describe-ready-off``."""
COMMAND_LEAD_CYCLES: Final = 4.0
"""Servo cycles of the path's velocity the command-lead fault adds to each command (about 0.2 degrees
past a 30-degree move's goal)."""
SEGMENTS_STOP_REST_S: Final = 0.1
"""How long the segments-stop fault rests between queued segments: clearly more than a blend's pause."""
TURN_FIRST_SHARE: Final = 0.1
"""The share of a straight line's way over which the straight-turn-first fault turns the hand to its goal
orientation (the rest of the line carries it unturned)."""
CALIBRATED_MASK: Final = 0o77
"""The word calibrate-replies-mask appends to calibrate's done: every joint found its zero index."""
OUNCES_PER_POUND: Final = 16.0
"""What the forces-in-pounds fault divides read forces' answer by."""
RESERVED_OPERAND: Final = 0x8000
"""First word of a reserved-operand float: sign 1, exponent 0."""
GUARD_STOP: Final = 1
"""Word 2 of a guard-hit response: 1 = the trajectory was stopped, 2 = it continues (E.3)."""
GUARD_CONTINUE: Final = 2
_ALL_NOTIFICATIONS: Final = sum(1 << code.notification_bit for code in SPEC.async_codes.values())
_SWAPPED_ARGS: Final[Mapping[Fault, frozenset[str]]] = {
    Fault.UOP_OPCODE_SWAPPED: frozenset({"UOP"}),
    Fault.BDL_COUNTS_SWAPPED: frozenset({"BDL"}),
    Fault.JOINT_MASK_SWAPPED: frozenset({"JOR", "TOR"}),
}
"""The error codes whose numbers each byte-swapping fault sends high byte first."""
_FLOAT_FAULTS: Final = frozenset(
    {Fault.UNDERFLOW_DIRTY_ZERO, Fault.UNDERFLOW_CLAMPED, Fault.NOT_FINITE_RESERVED}
)
_SWAPPED_CODES: Final = {"TOR": "JOR", "JOR": "TOR"}
WHERE_SERVER: Final = "PUMA"
"""What the where part of an error string starts with, before a colon, under ``where-with-colon``."""
SERIAL_NUMBER: Final = 600
""":unique-name under ``describe-unique-number``."""
_DESCRIBE_TEXT_FAULTS: Final = frozenset(
    {
        Fault.DESCRIBE_UNCLOSED,
        Fault.DESCRIBE_KEY_TWICE,
        Fault.DESCRIBE_DECIMAL,
        Fault.DESCRIBE_BRAND_SYMBOL,
        Fault.DESCRIBE_UNIQUE_NUMBER,
        Fault.DESCRIBE_DOF_STRING,
        Fault.DESCRIBE_OPERATION_NAMES,
    }
)
"""The faults that change how the describe-self text is written, not what it states."""


HELD_TICKS: Final = 25
"""Servo ticks describe self's terminator waits with describe-terminator-overtaken: a client that waits
for it gets it 0.4 s late (well within any reply timeout), a request sent behind it is answered first."""


def _word(n: int) -> bytes:
    return (n & WORD_MASK).to_bytes(2, "little")


class Defects:
    """The hook points of a session, as a conforming server has them: nothing is bent."""

    keeps_arm_after_close: bool = False
    """The driver hands the arm of a closed connection, still moving, to the next one."""
    admits_second_client: bool = False
    """The driver accepts a connection while another is open (one server per robot: it refuses it)."""
    discards_after_free_joint: bool = True
    """The packet after free joint is answered done without being executed."""
    straight_lines: bool = True
    """Straight-line moves are interpolated in Cartesian space."""
    joint_moves: bool = True
    """Move and incremental move are interpolated in joint space."""
    checks_joint_limits: bool = True
    """Set joint angles refuses out-of-range joints with JOR."""
    applies_configuration: bool = True
    """Set configuration changes the configuration transforms are solved in."""
    after_fatal: AfterFatal = "close"
    """What follows a fatal error: the connection closes (clause error.fatal-then-close)."""
    arm: ArmDefects = ArmDefects()
    """The defects the connection's move process is made with: none."""
    wrist: WristDefects = WristDefects()
    """The defects the (shared) wrist takes for the connection: none."""

    # ---------------------------------------------------------------------------- the connection
    def inherit(self, session: ServerSession, previous: ServerSession) -> None:
        """Take over what ``previous``, the connection before, set (a conforming session takes nothing:
        erratum server-robot)."""

    # ---------------------------------------------------------------------------- request numbers
    def initial_numbers(self, rfc_packet_no: int) -> tuple[int, ...]:
        """The numbers of the RESPONSE packets sent when the connection opens (erratum
        ``initial-response``: one, the RFC's packet number)."""
        return (rfc_packet_no,)

    def reply_number(self, packet_no: int, ack_no: int | None) -> int:
        """The request number the answers to a request carry: its packet number."""
        return packet_no

    # ---------------------------------------------------------------------------- serving a request
    def decode(self, op: RequestOpcode, data: bytes) -> Mapping[str, Value]:
        """The request's values by the spec layout (DecodeError when the data do not fit it)."""
        return decode_request(op.opcode, data).values

    def check(self, op: RequestOpcode, arm: ArmSim) -> None:
        """Refuse the request (raise RequestError) before it is served; a conforming server leaves every
        refusal to the request's handler."""

    def refused(self, op: RequestOpcode | None, error: RequestError) -> RequestError | dict[str, Any]:
        """The error that answers a refused request (``op`` None: an unknown opcode), or the values of
        a normal reply to send instead."""
        return error

    def wrist_failure(self, error: RequestError) -> RequestError:
        """The error that answers a wrist request Cougar failed (silent, its link down): non-fatal."""
        return error

    # ---------------------------------------------------------------------------- what requests do
    def describe(self, statement: Statement) -> Statement:
        """What describe self states (the truth about the arm)."""
        return statement

    def describe_text(self, text: str) -> str:
        """The describe-self text as written: the alist of what :meth:`describe` states, as printed."""
        return text

    def increment(self, delta: tuple[float, ...]) -> tuple[float, ...]:
        """The dX dY dZ dO dA dT an incremental move adds to the pose."""
        return delta

    def move_ready(self, arm: ArmSim, now: float) -> int:
        """Queue the move to the ready position; its segment number."""
        return arm.move_ready(now)

    def configuration(self, lefty: bool) -> bool:
        """The configuration set configuration puts in force when asked for ``lefty`` (or righty)."""
        return lefty

    def set_speed(self, arm: ArmSim, factor: float) -> None:
        """Set the speed factor of the segments queued from now on (BVA out of range)."""
        arm.set_speed(factor)

    # ---------------------------------------------------------------------------- replies
    def payload(self, op: RequestOpcode, values: Mapping[str, Any], encode: Encoder) -> bytes:
        """A reply's data after the request number, as ``encode`` (the spec codec) writes them."""
        return encode(op, values)

    def reply(self, op: RequestOpcode | None, packets: list[bytes]) -> Sequence[bytes]:
        """The RESPONSE packets (data) that answer a request, the terminator of a multi-packet reply
        included."""
        return packets

    def reply_opcode(self, op: RequestOpcode | None) -> int:
        """The Chaos opcode of the packets that answer a request normally: RESPONSE (0200)."""
        return ServerOp.RESPONSE

    def held_back(self, arm: ArmSim) -> tuple[bytes, ...]:
        """Reply packets held back from an earlier request, sent at the servo tick before ``arm`` runs
        (none: a reply goes out whole, at once)."""
        return ()

    # ---------------------------------------------------------------------------- errors
    def error_number(self, opcode: int, number: int, before: int | None) -> int:
        """The request number an error packet of ``opcode`` carries: ``number``, the protocol's (for a
        fatal error the packet last received, for an asynchronous one the last request processed;
        ``before`` is the request processed before that one)."""
        return number

    def error(self, opcode: int, error: ErrorMessage) -> ErrorMessage:
        """What an error packet of ``opcode`` (0201, 0202, 0204, 0205) says."""
        return error

    def error_string(self, error: ErrorMessage, encoded: bytes) -> bytes:
        """The error string's bytes as sent (``encoded``: as the codec lays them out)."""
        return encoded

    def after_error(self, number: int) -> tuple[bytes, ...]:
        """RESPONSE packets (data) sent after a non-fatal error, which is the reply: none."""
        return ()

    # ---------------------------------------------------------------------------- asynchronous packets
    def notifications(self, mask: int) -> int:
        """The request-notifications mask the asynchronous responses are sent by: the client's."""
        return mask

    def async_response(
        self, number: int, condition: int, word2: int, word3: int, *, numbered: bool = True
    ) -> bytes:
        """The data of an asynchronous response (0203), with the request number first (``numbered``,
        manip's layout) or without (the 1985 guide's): erratum ``async-request-number``."""
        return encode_async(number, condition, word2, word3, async_has_request_number=numbered)

    def reports_guard(self, hit: GuardHit) -> bool:
        """Whether a guard hit is told to the client at all (as a guard-hit response, or an error)."""
        return True

    def after_warning(self, arm: ArmSim) -> list[ArmEvent]:
        """What the move process does after warning of a joint lagging its command: it goes on."""
        return []

    # ---------------------------------------------------------------------------- the packets sent
    def sent(self, request: bool, packets: list[Outgoing]) -> list[Outgoing]:
        """The packets of one step of the session, in the order they go out (``request``: the step served
        a request; otherwise it ran the move and wrist processes): as they were made."""
        return packets


class SwitchedDefects(Defects):
    """The hook points bent as the fault switches of ``faults`` say."""

    def __init__(self, faults: FaultSet) -> None:
        self.faults = faults
        self._held_terminator: bytes | None = None
        """Describe self's terminator, held back until the next reply (describe-terminator-overtaken)."""
        self._held_ticks = 0
        self._first_forces: tuple[float, ...] | None = None
        """The connection's first read forces answer (fault forces-stale)."""
        self._held_async: list[Outgoing] = []
        """Asynchronous packets waiting for the next request (fault async-splits-multi)."""
        self._held_replies: list[bytes] = []
        """Replies waiting for the arm to come to rest (fault motion-reply-at-rest)."""
        on = faults.active
        self.arm = arm_defects(faults)
        self.wrist = _wrist_defects(faults)
        self.keeps_arm_after_close = Fault.CLOSE_KEEPS_MOVING in on
        self.admits_second_client = Fault.SECOND_CLIENT_ADMITTED in on
        self.discards_after_free_joint = Fault.FREE_JOINT_EXECUTES not in on
        self.straight_lines = Fault.STRAIGHT_AS_JOINT not in on
        self.joint_moves = Fault.JOINT_MOVES_STRAIGHT not in on
        self.checks_joint_limits = Fault.NO_JOR not in on
        self.applies_configuration = Fault.CONFIGURATION_IGNORED not in on
        self.after_fatal = (
            "stay-open"
            if Fault.FATAL_WITHOUT_CLOSE in on
            else "drop-link"
            if Fault.FATAL_DROPS_LINK in on
            else "eof-drop-link"
            if Fault.FATAL_EOF_WITHOUT_CLS in on
            else "close"
        )

    def _on(self, fault: Fault) -> bool:
        return fault in self.faults.active

    # ---------------------------------------------------------------------------- the connection
    def inherit(self, session: ServerSession, previous: ServerSession) -> None:
        if self._on(Fault.KEEPS_SPEED):
            session.arm.set_speed(previous.arm.speed)
        if self._on(Fault.KEEPS_CONFIGURATION) and previous.arm.lefty is not None:
            session.arm.set_configuration(previous.arm.lefty)
        if self._on(Fault.KEEPS_NOTIFICATIONS):
            session.notifications = previous.notifications
        if self._on(Fault.KEEPS_ABORT):
            session.arm.aborted, session.arm.abort_cause = previous.arm.aborted, previous.arm.abort_cause

    # ---------------------------------------------------------------------------- request numbers
    def initial_numbers(self, rfc_packet_no: int) -> tuple[int, ...]:
        if self._on(Fault.NO_INITIAL_RESPONSE):
            return ()
        return (rfc_packet_no + (1 if self._on(Fault.INITIAL_RESPONSE_NUMBER) else 0),)

    def reply_number(self, packet_no: int, ack_no: int | None) -> int:
        if self._on(Fault.ECHO_ACK_NUMBER):
            return ack_no if ack_no is not None else 0
        if self._on(Fault.WRONG_REQUEST_NUMBER):
            return (packet_no + 1) & WORD_MASK
        if self._on(Fault.REQUEST_NUMBER_HIGH_FIRST):
            return _byte_swapped(packet_no)
        return packet_no

    # ---------------------------------------------------------------------------- serving a request
    def decode(self, op: RequestOpcode, data: bytes) -> Mapping[str, Value]:
        if op.name == "set-configuration" and len(data) == 1 and self._on(Fault.SET_CONFIGURATION_WORD_ONLY):
            raise errors.bad_length(2, 1)
        try:
            values = super().decode(op, data)
        except DecodeError as exc:
            if exc.clause == "float.reserved-operand" and self._on(Fault.RESERVED_FLOAT_AS_ZERO):
                at = exc.offset or 0
                return self.decode(op, data[:at] + bytes(4) + data[at + 4 :])  # read as a zero
            if exc.clause != "request.data-length" or not self._on(Fault.LENGTH_UNCHECKED):
                raise
            expected = op.request.fixed_size or 0
            values = super().decode(op, data[:expected].ljust(expected, b"\0"))
        if op.name == "hand" and values["amount"] not in (0, 1) and self._on(Fault.HAND_FLAG_ONLY):
            raise errors.bad_value("hand", f"amount {values['amount']} is neither 0 (close) nor 1 (open)")
        joint = values.get("joint") if op.name == "free-joint" else None
        if isinstance(joint, int) and self._on(Fault.FREE_JOINT_FROM_ZERO):
            values = {**values, "joint": (joint & 0xFF) + 1}  # byte n taken as joint n+1
        if op.name == "solve-backwards" and self._on(Fault.SOLVE_BACKWARDS_RADIANS):
            values = {**values, "joints": tuple(math.degrees(float(q)) for q in _floats_of(values["joints"]))}
        return _joints_reversed(op.request.fields, values) if self._on(Fault.JOINTS_REVERSED) else values

    def check(self, op: RequestOpcode, arm: ArmSim) -> None:
        if self._on(Fault.AWA_REFUSES_ALL) and arm.aborted and op.name not in ("enable-power", "reset-abort"):
            raise errors.refusal_error(op.name, Refused("AWA", "motion aborted; reset first"))

    def refused(self, op: RequestOpcode | None, error: RequestError) -> RequestError | dict[str, Any]:
        code, name = error.error.code, op.name if op is not None else None
        if op is None and self._on(Fault.UNKNOWN_OPCODE_ANSWERED):
            return {}
        if name == "set-speed" and code == "BVA" and self._on(Fault.SPEED_UNCHECKED):
            return {}  # the factor ignored
        if name == "solve-forwards" and code == "TOR" and self._on(Fault.NOT_FINITE_RESERVED):
            return {"joints": (math.nan,) * 6}
        if code in _SWAPPED_CODES and op is not None and self._on(Fault.SWAP_TOR_JOR):
            return RequestError(replace(error.error, code=_SWAPPED_CODES[code]), fatal=error.fatal)
        return error

    def wrist_failure(self, error: RequestError) -> RequestError:
        if self._on(Fault.WRIST_ERROR_FATAL):
            return RequestError(replace(error.error, severity="F"), fatal=True)
        return error

    # ---------------------------------------------------------------------------- what requests do
    def describe(self, statement: Statement) -> Statement:
        on = self._on
        operations = set(statement.operations)
        if on(Fault.DESCRIBE_EXTRA_OPERATION):
            operations.add(min(set(range(0o200, 0o300)) - operations))  # listed, answered C UOP
        if on(Fault.DESCRIBE_MISSING_OPERATION):
            operations.discard(SPEC.request(MISSING_OPERATION).opcode)  # answered, not listed
        limits = statement.joint_limits
        if on(Fault.DESCRIBE_NARROW_LIMITS):
            limits = tuple((lo + NARROWED_DEG, hi - NARROWED_DEG) for lo, hi in limits)
        if on(Fault.DESCRIBE_LIMITS_SHORT):
            limits = limits[:-1]
        ready = list(statement.ready_position)
        if on(Fault.DESCRIBE_READY_OFF):
            ready[1] += READY_OFF_DEG
        if on(Fault.JOINTS_REVERSED):
            limits, ready = limits[::-1], ready[::-1]
        return Statement(
            frozenset(operations),
            statement.degrees_of_freedom + (1 if on(Fault.DESCRIBE_WRONG_DOF) else 0),
            limits,
            tuple(ready),
            protocol_version=statement.protocol_version and not on(Fault.NO_PROTOCOL_VERSION),
        )

    def describe_text(self, text: str) -> str:
        on = self.faults.active & _DESCRIBE_TEXT_FAULTS
        if not on:
            return text
        entries = alist_to_dict(read_lisp(text))
        if Fault.DESCRIBE_BRAND_SYMBOL in on:
            entries["brand-name"] = Symbol(str(entries["brand-name"]).replace(" ", "-"))
        if Fault.DESCRIBE_UNIQUE_NUMBER in on:
            entries["unique-name"] = SERIAL_NUMBER
        if Fault.DESCRIBE_DOF_STRING in on:
            entries["degrees-of-freedom"] = str(entries["degrees-of-freedom"])
        if Fault.DESCRIBE_OPERATION_NAMES in on:
            entries["operations"] = [_operation_name(o) for o in _list_of(entries["operations"])]
        pairs = [cons(Keyword(key), value) for key, value in entries.items()]
        if Fault.DESCRIBE_KEY_TWICE in on:
            pairs.append(cons(Keyword("software-version"), 1))
        decimal = Fault.DESCRIBE_DECIMAL in on
        text = alist_text(print_lisp(p, base=10 if decimal else 8, nopoint=decimal) for p in pairs)
        return text.removesuffix(")\n") + "\n" if Fault.DESCRIBE_UNCLOSED in on else text

    def increment(self, delta: tuple[float, ...]) -> tuple[float, ...]:
        if self._on(Fault.INCREMENT_ANGLES_FIRST):  # the floats on the wire read as dO dA dT dX dY dZ
            delta = (*delta[3:], *delta[:3])
        if self._on(Fault.INCREMENT_O_T_SWAPPED):
            dx, dy, dz, do, da, dt = delta
            return (dx, dy, dz, dt, da, do)
        return delta

    def configuration(self, lefty: bool) -> bool:
        return not lefty if self._on(Fault.CONFIGURATION_SWAPPED) else lefty

    def set_speed(self, arm: ArmSim, factor: float) -> None:
        arm.set_speed(factor)  # refused out of range, as the protocol says
        if self._on(Fault.SPEED_IGNORED):
            arm.set_speed(1.0)

    def move_ready(self, arm: ArmSim, now: float) -> int:
        if self._on(Fault.READY_LEAVES_WRIST):
            return arm.move_joints(arm.model.ready[:3] + arm.planned[3:], now)
        return arm.move_ready(now)

    # ---------------------------------------------------------------------------- replies
    def payload(self, op: RequestOpcode, values: Mapping[str, Any], encode: Encoder) -> bytes:
        fields = op.response.data.fields
        if self._on(Fault.JOINTS_REVERSED):
            values = _joints_reversed(fields, values)
        if op.name == "read-forces":
            values = self._forces(values)
        if op.name == "here" and self._on(Fault.HERE_ROW_MAJOR):
            t = _floats_of(values["transform"])
            rows = tuple(t[column * 3 + row] for row in range(3) for column in range(4))
            values = {**values, "transform": rows}
        if op.name == "solve-forwards" and self._on(Fault.SOLVE_FORWARDS_RADIANS):
            values = {**values, "joints": tuple(math.radians(q) for q in _floats_of(values["joints"]))}
        if self.faults.active & _FLOAT_FAULTS and fields and all(f.type.element == "float" for f in fields):
            return b"".join(self._float(float(x)) for f in fields for x in values[f.name])
        return self._relaid(op, encode(op, values))

    def _relaid(self, op: RequestOpcode, data: bytes) -> bytes:
        """A reply's data after the request number as the layout faults lay it out."""
        form = op.response.form
        extra = self._done_word(op) if form == "done" else None
        if extra is not None:
            return data + _word(extra)
        if form == "segment" and self._on(Fault.MOTION_REPLY_DONE):
            return b""
        if form == "data" and self._on(Fault.DATA_LENGTH_WORD):
            return _word(len(data)) + data
        return data

    def _done_word(self, op: RequestOpcode) -> int | None:
        """The word a done-word fault appends to ``op``'s empty done: the op's own fault's, else
        done-with-zero-word's 0 (None: nothing)."""
        if op.name == "calibrate" and self._on(Fault.CALIBRATE_REPLIES_MASK):
            return CALIBRATED_MASK
        if op.name == "kill-power" and self._on(Fault.KILL_POWER_REPLIES_STATE):
            return 0
        if op.name == "enable-power" and self._on(Fault.ENABLE_POWER_REPLIES_STATE):
            return 1
        return 0 if self._on(Fault.DONE_WITH_WORD) else None

    def _forces(self, values: Mapping[str, Any]) -> Mapping[str, Any]:
        """Read forces' answer as the force faults bend it."""
        forces = tuple(values["forces"])
        if self._on(Fault.FORCES_STALE):
            if self._first_forces is None:
                self._first_forces = forces
            forces = self._first_forces
        if self._on(Fault.FORCES_IN_POUNDS):
            forces = tuple(f / OUNCES_PER_POUND for f in forces)
        return {**values, "forces": forces}

    def _float(self, x: float) -> bytes:
        """``x`` as a float encoder with the float faults switched on writes it."""
        if not math.isfinite(x) and self._on(Fault.NOT_FINITE_RESERVED):
            return struct.pack("<HH", RESERVED_OPERAND, 0)  # what an unchecked encoder makes of NaN
        if 0.0 < abs(x) < F_MIN_NORMAL and self._on(Fault.UNDERFLOW_DIRTY_ZERO):
            fraction = max(1, int(abs(x) / F_MIN_NORMAL * (1 << 23)))  # exponent 0, the bits kept
            return struct.pack("<HH", fraction >> 16 & 0x7F, fraction & 0xFFFF)
        if 0.0 < abs(x) < F_MIN_NORMAL and self._on(Fault.UNDERFLOW_CLAMPED):
            return pack_f(math.copysign(F_MIN_NORMAL, x))  # the least exponent, not zero
        return pack_f(x)

    def reply(self, op: RequestOpcode | None, packets: list[bytes]) -> Sequence[bytes]:
        packets = self._overtaking(op, packets)
        if self._on(Fault.MOTION_REPLY_AT_REST) and (
            self._held_replies or (op is not None and op.response.form == "segment")
        ):
            self._held_replies += packets  # the main process waits for the arm before it answers
            return []
        if op is None:
            return packets
        if op.response.form == "multi":
            if self._on(Fault.MULTI_WRONG_NUMBER) and len(packets) > 1:  # the terminator keeps its own
                packets = [packets[0], *(_renumbered(p, 1) for p in packets[1:-1]), packets[-1]]
            if self._on(Fault.NO_DESCRIBE_TERMINATOR):
                packets = packets[:-1]
            if self._on(Fault.DESCRIBE_DONE):
                packets = packets[-1:]  # the terminator alone
            return packets
        floats_only = all(f.type.element == "float" for f in op.response.data.fields)
        if self._on(Fault.SWAPPED_FLOAT_WORDS) and op.response.form == "data" and floats_only:
            return [_float_words_swapped(p) for p in packets]
        return packets

    def reply_opcode(self, op: RequestOpcode | None) -> int:
        if op is not None and op.response.form == "data" and self._on(Fault.DATA_REPLIES_DWD):
            return ChaosOp.DWD  # Chaos's opcode of 16-bit word data
        return ServerOp.RESPONSE

    # ---------------------------------------------------------------------------- errors
    def error_number(self, opcode: int, number: int, before: int | None) -> int:
        if opcode == ServerOp.FATAL_ERROR and self._on(Fault.FATAL_NUMBER_PREVIOUS):
            return (number - 1) & WORD_MASK
        if opcode in ASYNC_ERROR_OPS and self._on(Fault.ASYNC_NUMBER_PREVIOUS) and before is not None:
            return before
        return number

    def error(self, opcode: int, error: ErrorMessage) -> ErrorMessage:
        if opcode == ServerOp.FATAL_ERROR and self._on(Fault.FATAL_SEVERITY_E):
            error = replace(error, severity="E")
        if self._on(Fault.WRONG_SEVERITY):
            error = replace(error, severity="E" if opcode == ServerOp.FATAL_ERROR else "F")
        if error.code == "NZI" and error.args and self._on(Fault.NZI_MASK_IN_TEXT):
            joints = " ".join(str(j) for j in range(1, 17) if error.args[0] >> (j - 1) & 1)
            error = replace(error, message=f"No zero index found on joints {joints}", args=(), has_nul=False)
        if error.code == "NZI" and error.args and self._on(Fault.NZI_MASK_SHIFTED):
            error = replace(error, args=(error.args[0] << 1 & WORD_MASK, *error.args[1:]))
        if any(self._on(fault) and error.code in codes for fault, codes in _SWAPPED_ARGS.items()):
            error = replace(error, args=tuple(_byte_swapped(a) for a in error.args))
        if self._on(Fault.WHERE_WITH_COLON):
            error = replace(error, where=f"{WHERE_SERVER}:{error.where}")
        if self._on(Fault.SEVERITY_LOWER_CASE):
            error = replace(error, severity=error.severity.lower())
        if self._on(Fault.ERROR_CODE_NUMBERS):
            error = replace(error, code=_code_number(error.code))
        return error

    def error_string(self, error: ErrorMessage, encoded: bytes) -> bytes:
        if self._on(Fault.ERROR_PAD_MISPLACED) and error.args:
            after_nul = encoded.index(0) + 1
            if after_nul % 2 == 0:  # no pad is due: one here puts the numbers at an odd offset
                encoded = encoded[:after_nul] + b"\0" + encoded[after_nul:]
        if self._on(Fault.ERROR_WITHOUT_COLON):
            encoded = encoded.replace(b": ", b" ", 1)
        if self._on(Fault.ERROR_ARGS_BYTES) and error.args:
            encoded = encode_lispm(error.text) + b"\0" + bytes(a & 0xFF for a in error.args)
        return encoded

    def after_error(self, number: int) -> tuple[bytes, ...]:
        return (_word(number),) if self._on(Fault.EXTRA_REPLY_AFTER_ERROR) else ()

    # ---------------------------------------------------------------------------- asynchronous packets
    def notifications(self, mask: int) -> int:
        return _ALL_NOTIFICATIONS if self._on(Fault.UNREQUESTED_ASYNC) else mask

    def async_response(
        self, number: int, condition: int, word2: int, word3: int, *, numbered: bool = True
    ) -> bytes:
        if condition == AsyncCondition.GUARD_HIT and self._on(Fault.GUARD_HIT_WORD_SWAPPED):
            word2 = GUARD_STOP + GUARD_CONTINUE - word2
        if condition == AsyncCondition.SEGMENT_COMPLETED and self._on(Fault.SEGMENT_REPORT_PREVIOUS):
            word3 = (word3 - 1) & WORD_MASK
        if self._on(Fault.ASYNC_CODES_FROM_BITS):
            condition = SPEC.async_codes[condition].notification_bit
        data = encode_async(number, condition, word2, word3, async_has_request_number=numbered)
        return data + b"\0" if self._on(Fault.ASYNC_STRAY_BYTE) else data

    def reports_guard(self, hit: GuardHit) -> bool:
        return not self._on(Fault.GUARD_UNREPORTED)

    def after_warning(self, arm: ArmSim) -> list[ArmEvent]:
        return arm.halt(AbortCause.COLLISION) if self._on(Fault.WARNING_INTERRUPTS) else []

    def held_back(self, arm: ArmSim) -> tuple[bytes, ...]:
        if self._held_replies and not arm.moving:
            replies, self._held_replies = tuple(self._held_replies), []
            return replies
        if self._held_terminator is None:
            return ()
        self._held_ticks += 1
        if self._held_ticks < HELD_TICKS:
            return ()
        held, self._held_terminator = self._held_terminator, None
        return (held,)

    def _overtaking(self, op: RequestOpcode | None, packets: list[bytes]) -> list[bytes]:
        """describe-terminator-overtaken: a multi-packet reply's terminator waits :data:`HELD_TICKS` servo
        ticks; a request already there by then is answered before it (a request loop that re-enters
        itself)."""
        if not self._on(Fault.DESCRIBE_TERMINATOR_OVERTAKEN):
            return packets
        held, self._held_terminator = self._held_terminator, None
        if op is not None and op.response.form == "multi" and len(packets) > 1:
            self._held_terminator, self._held_ticks = packets[-1], 0
            packets = packets[:-1]
        return packets if held is None else [*packets, held]

    # ---------------------------------------------------------------------------- the packets sent
    def sent(self, request: bool, packets: list[Outgoing]) -> list[Outgoing]:
        if not self._on(Fault.ASYNC_SPLITS_MULTI):
            return packets
        if not request:  # the other processes' reports wait for the main process
            self._held_async += [p for p in packets if p.opcode in ASYNC_OPS]
            return [p for p in packets if p.opcode not in ASYNC_OPS]
        held, self._held_async = self._held_async, []
        replies = [i for i, p in enumerate(packets) if p.opcode == ServerOp.RESPONSE]
        at = replies[0] + 1 if len(replies) > 1 else 0  # after a multi-packet reply's first packet
        return [*packets[:at], *held, *packets[at:]]


def _joints_reversed(fields: Sequence[Field], values: Mapping[str, Any]) -> dict[str, Any]:
    """``values`` with every joint vector among ``fields`` in the reverse order (fault joints-reversed)."""
    joints = {f.name for f in fields if f.type.name == "joints"}
    return {name: tuple(value)[::-1] if name in joints else value for name, value in values.items()}


def _byte_swapped(word: int) -> int:
    """A 16-bit word with its two bytes exchanged (as a high-byte-first writer sends it)."""
    return int.from_bytes(word.to_bytes(2, "little"), "big")


def _floats_of(value: Any) -> tuple[float, ...]:
    return tuple(float(x) for x in value)


def _list_of(value: LispValue) -> list[LispValue]:
    return value if isinstance(value, list) else [value]


def _operation_name(opcode: LispValue) -> LispValue:
    """An :operations entry by name (describe-operation-names); one the spec does not name stays."""
    op = SPEC.requests.get(opcode) if isinstance(opcode, int) else None
    return opcode if op is None else Symbol(op.name)


def _code_number(code: str) -> str:
    """An error code as the error's place in the spec's table, three octal digits (error-code-numbers)."""
    codes = list(SPEC.error_codes)
    return f"{codes.index(code) if code in codes else len(codes):03o}"


def _renumbered(packet: bytes, by: int) -> bytes:
    number = int.from_bytes(packet[:2], "little")
    return _word(number + by) + packet[2:]


def _float_words_swapped(packet: bytes) -> bytes:
    body = packet[2:]
    return packet[:2] + b"".join(body[i + 2 : i + 4] + body[i : i + 2] for i in range(0, len(body), 4))


def arm_defects(faults: FaultSet) -> ArmDefects:
    """The defects of the move process the switches of ``faults`` give it."""
    on = faults.active
    return ArmDefects(
        enforce_power=Fault.NO_NAP not in on,
        enforce_abort=Fault.AWA_IGNORED not in on,
        power_resets_abort=Fault.POWER_KEEPS_ABORT not in on,
        collision_test=Fault.COLLISION_UNCHECKED not in on,
        collision_test_compliant=Fault.COMPLIANT_COLLISION_TEST in on,
        hold_compliant_end=Fault.COMPLIANT_SNAP_BACK not in on,
        increment_from_actual=Fault.INCREMENT_FROM_ACTUAL in on,
        stop_between_segments=SEGMENTS_STOP_REST_S
        if Fault.SEGMENTS_STOP in on
        else 0.0
        if Fault.QUEUE_REVERSED in on
        else None,
        reverse_waiting=Fault.QUEUE_REVERSED in on,
        keep_queue_on_abort=Fault.ABORT_KEEPS_QUEUE in on,
        segment_step=0 if Fault.SEGMENT_NUMBER_STUCK in on else 1,
        servo_rate=2.0 if Fault.SERVO_DOUBLE_RATE in on else 1.0,
        command_lead=COMMAND_LEAD_CYCLES if Fault.COMMAND_LEAD in on else 0.0,
        turn_share=TURN_FIRST_SHARE if Fault.STRAIGHT_TURN_FIRST in on else 1.0,
    )


def _wrist_defects(faults: FaultSet) -> WristDefects:
    """The defects of the wrist processes the switches of ``faults`` give them."""
    on = faults.active
    return WristDefects(
        answer_timeouts=Fault.WRIST_TIMEOUT_SILENT not in on,
        npr_every_cycle=Fault.NPR_SKIPPED not in on,
        command_floats_swapped=Fault.WRIST_FLOAT_WORDS_SWAPPED in on,
        user_commands_first=Fault.WRIST_USER_FIRST in on,
        guard_stops_arm=Fault.GUARD_IGNORED not in on,
        read_forces_sends_angles=Fault.READ_FORCES_NO_ANGLES not in on,
        read_forces_waits=Fault.WRIST_NO_WAIT not in on,
        calibrate_two_poses=Fault.CALIBRATE_ONE_POSE not in on,
        calibrate_moves_back=Fault.CALIBRATE_STAYS_AWAY not in on,
        user_while_moving=Fault.WRIST_CONFIG_AFTER_MOTION not in on,
        user_while_compliant=Fault.WRIST_USER_HELD_COMPLIANT not in on,
        handles_out_of_sync=Fault.OUT_OF_SYNC_IGNORED not in on,
        clears_old_guards=Fault.GUARDS_OUTLIVE_CONNECTION not in on,
        compliant_follows_nominal=Fault.COMPLIANT_NOMINAL_IGNORED not in on,
        move_queue_before_user=Fault.WRIST_USER_BEFORE_MOVE_QUEUE not in on,
    )


_CHAOS_RULES: Final[Mapping[str, Fault]] = {
    "los_unknown_connection": Fault.LOS_UNKNOWN_IGNORED,
    "los_illegal_opcode": Fault.ILLEGAL_OPCODE_IGNORED,
    "bounds_data": Fault.OVERSIZE_SERVED,
    "retransmits": Fault.NO_RETRANSMISSION,
    "recognises_duplicate_rfc": Fault.DUPLICATE_RFC_NEW,
    "gives_up_silent_peer": Fault.SILENT_PEER_KEPT,
    "nbytes_counts_odd_byte": Fault.NBYTES_WHOLE_WORDS,
    "data_first_byte_low": Fault.DATA_BYTES_SWAPPED,
    "chudp_header": Fault.CHUDP_NO_HEADER,
    "chudp_pads_odd_byte": Fault.CHUDP_ODD_BYTE_UNPADDED,
    "chudp_msb_first": Fault.CHUDP_LSB_FIRST,
    "trailer_source_own": Fault.TRAILER_SOURCE_DESTINATION,
    "checksum_covers_trailer": Fault.CHECKSUM_WITHOUT_TRAILER,
    "tcp_length_counts_pad": Fault.TCP_LENGTH_UNPADDED,
    "chaosd_little_endian": Fault.CHAOSD_MSB_FIRST,
}
"""Each rule of :class:`ChaosDefects` kept by default (a field true unless broken) and the switch that
breaks it."""


def chaos_defects(faults: FaultSet) -> ChaosDefects:
    """The defects of the server's NCP and links the switches of ``faults`` give them."""
    on = faults.active
    return ChaosDefects(
        **{rule: fault not in on for rule, fault in _CHAOS_RULES.items()},
        packet_number_step=2 if Fault.PACKET_NUMBERS_SKIP in on else 1,
        header_source_first=Fault.HEADER_SOURCE_FIRST in on,
        header_low_byte=1 if Fault.HEADER_LOW_BYTE_SET in on else 0,
    )


def defects_for(faults: FaultSet) -> Defects:
    """The hook points of a session with ``faults`` switched on (none: a conforming server)."""
    return SwitchedDefects(faults) if faults.active else Defects()
