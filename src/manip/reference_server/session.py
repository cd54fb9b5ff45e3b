"""One connection of the reference Puma server, as a sans-I/O state machine.

Theory of operation
===================

A driver (not here: it owns the Chaos connection, the clock and the timers) feeds the session what
happens and sends what the session returns:

* :meth:`ServerSession.on_open` once the connection is open, with the packet number of the RFC;
* :meth:`ServerSession.on_request` for every data packet, with its opcode, packet number, data and
  (optionally) the Chaos ack field;
* :meth:`ServerSession.tick` every 16 ms (any period works: the arm runs every servo cycle due);
* :meth:`ServerSession.on_close` when the peer closes or the connection breaks.

Each call returns an :class:`Output`: the server packets to send, in order, as ``(opcode, data)``, and
``close``, set after a fatal error: send the packets, then close the connection (CLS).  Time is always an
argument (seconds, any origin, never decreasing); nothing here reads a clock or touches a socket.

States and transitions (:data:`TRANSITIONS` is the table the code runs)::

    state              open             request                        tick      close
    AWAITING_INITIAL   initial RESPONSE  (driver error)                 -         -> CLOSED
                       -> READY
    READY              (driver error)   serve it; stay, or             run arm   -> CLOSED
                                        -> FREE_JOINT_WAIT (free joint),
                                        -> CLOSED (fatal error)
    FREE_JOINT_WAIT    (driver error)   un-free, answer done           run arm   -> CLOSED
                                        without executing -> READY
    WRIST_WAIT         (driver error)   hold it                        run arm;  -> CLOSED
                                                                       answered? reply, serve the
                                                                       held requests -> READY ...
    CLOSED             (driver error)   ignored                        ignored   ignored

The initial RESPONSE carries only the RFC's packet number (erratum ``initial-response``).  Serving a
request goes: run the arm up to ``now`` (so asynchronous events that happened first are sent first,
and requests read fresh move-process data); look the opcode up in the spec (C UOP if unknown, C UIM if
this robot does not serve it, e.g. a wrist opcode without a wrist: both whatever the data, so that what
describe self lists is what a probe finds served, erratum ``describe-self-truthful``); decode its data
by the spec layout (C BDL for a wrong length, C BFL for a reserved-operand float); call the handler
that :data:`HANDLERS` maps the spec name to (the wrist opcodes go to the :class:`Wrist`); send its
reply in the form the spec gives the opcode (done, data, segment number, multi-packet text).  A handler
refuses with :class:`RequestError`: a non-fatal error (0202) is the reply; a fatal one (0201,
first word = the packet last received) ends the session.  Motion requests are checked and queued on
the :class:`~manip.arm.sim.ArmSim` and answered with the segment number before the arm moves.

A wrist request that needs data from Cougar returns a :class:`~manip.reference_server.wrist.Pending`:
the session enters WRIST_WAIT, where later requests are held in order (the Puma's main process waits
for the data, Part II §5.1); each tick runs the arm and the wrist, and once the wrist has resolved the
pending reply (data, or a non-fatal error on timeout) it is sent and the held requests are served, at
the current time, as if they had just arrived.  Running the arm always ends with the wrist's turn
(:meth:`~manip.reference_server.wrist.Wrist.tick`): guard hits become guard-hit asynchronous responses
(0203 code 1: word 2 is 1 to stop, 2 to continue, word 3 the guard) when the client asked for them
(mask bit 0); a stop-the-move guard the client did not ask to hear of is reported as an asynchronous
error instead (erratum ``guard-stop``).

Asynchronous packets carry the number of the last request processed (the RFC's before the first one):
segment completed (0203, code 2) only while the client has asked for it with request-notifications
(0257, mask bit 1; bit 0 = guard hit, for the wrist); aborts of the move process as asynchronous errors
(0204); a joint lagging its command as an asynchronous warning (0205).

Fault switches (:mod:`manip.reference_server.faults`) bend single behaviours for testing conformance
suites; each place that consults one names it.
"""

from __future__ import annotations

import enum
import logging
import math
import struct
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any, Final, Literal

from manip.arm.kinematics import PUMA600, ArmModel, forward
from manip.arm.sim import (
    AbortCause,
    ArmEvent,
    ArmSim,
    FollowingWarning,
    MotionAborted,
    Refused,
    SegmentCompleted,
)
from manip.arm.transform import Transform
from manip.codecs.error_string import ErrorMessage
from manip.codecs.errors import DecodeError
from manip.codecs.lispm_text import encode_lispm
from manip.codecs.messages import (
    MAX_TEXT_PER_PACKET,
    Value,
    decode_request,
    encode_async,
    encode_error,
    encode_reply,
)
from manip.codecs.pdp11float import F_MIN_NORMAL, pack_f
from manip.reference_server import errors
from manip.reference_server.describe import Description, describe_text
from manip.reference_server.errors import RequestError
from manip.reference_server.faults import Fault, FaultSet
from manip.reference_server.wrist import GuardHit, NoWrist, Pending, Wrist, WristConditions, WristNotice
from manip.spec import SPEC, RequestName, RequestOpcode
from manip.spec.constants import AsyncCondition, ServerOp
from manip.spec.notation import octal

__all__ = [
    "HANDLERS",
    "TRANSITIONS",
    "WRIST_OPERATIONS",
    "ErrorArgs",
    "Input",
    "Outgoing",
    "Output",
    "ServerConfig",
    "ServerSession",
    "SessionUsageError",
    "State",
]

log = logging.getLogger("manip.reference_server")

WORD_MASK: Final = 0xFFFF
MISSING_OPERATION: Final[RequestName] = "solve-backwards"
"""The served opcode describe self leaves out under the ``describe-missing-operation`` fault."""
NARROWED_DEG: Final = 5.0
"""How much narrower than the arm's each joint range is stated under ``describe-narrow-limits``."""
READY_OFF_DEG: Final = 10.0
"""How far from where move to ready goes joint 2 of :ready-position is stated under ``describe-ready-off``."""
_SWAPPED_ARGS: Final[dict[Fault, frozenset[str]]] = {
    Fault.UOP_OPCODE_SWAPPED: frozenset({"UOP"}),
    Fault.BDL_COUNTS_SWAPPED: frozenset({"BDL"}),
    Fault.JOINT_MASK_SWAPPED: frozenset({"JOR", "TOR"}),
}
"""The error codes whose numbers each byte-swapping fault sends high byte first."""
ErrorArgs = Literal["aligned", "packed"]


class State(enum.Enum):
    """Where a session stands (see the table in the module docstring)."""

    AWAITING_INITIAL = "awaiting-initial"
    READY = "ready"
    FREE_JOINT_WAIT = "free-joint-wait"
    WRIST_WAIT = "wrist-wait"
    CLOSED = "closed"


class Input(enum.Enum):
    """What the driver tells the session."""

    OPEN = "open"
    REQUEST = "request"
    TICK = "tick"
    CLOSE = "close"


class SessionUsageError(RuntimeError):
    """The driver called the session out of order (a request before open, open twice, ...)."""


@dataclass(frozen=True, slots=True)
class Outgoing:
    """One server packet: Chaos opcode and data."""

    opcode: int
    data: bytes


@dataclass(frozen=True)
class Output:
    """What to send, in order; with ``close`` the driver closes the connection after sending."""

    packets: tuple[Outgoing, ...] = ()
    close: bool = False


@dataclass(frozen=True)
class ServerConfig:
    """How the server describes itself, which arm it simulates, and its fault switches."""

    description: Description = field(default_factory=Description)
    model: ArmModel = PUMA600
    powered_at_open: bool = False
    """Arm power at the start (off: clients send Enable high power before moving)."""
    faults: FaultSet = field(default_factory=FaultSet)
    error_args: ErrorArgs = "aligned"
    """The layout of an error string's numbers (erratum error-arg-layout; both conform): ``aligned`` pads
    them to an even offset of the packet data, ``packed`` writes them straight after the NUL, as the
    1985 guide's NZI example does."""


@dataclass(frozen=True, slots=True)
class _Event:
    kind: Input
    now: float
    opcode: int = 0
    packet_no: int = 0
    data: bytes = b""
    ack_no: int | None = None


Handler = Callable[["ServerSession", Mapping[str, Value], float], dict[str, Any]]
"""A request handler: the decoded values and the time in, the reply's values out (``{}`` for done)."""

_FLOAT_FAULTS: Final = frozenset({Fault.UNDERFLOW_DIRTY_ZERO, Fault.NOT_FINITE_RESERVED})
_SEGMENTS_STOP_REST_S: Final = 0.1
"""How long the segments-stop fault rests between queued segments: clearly more than a blend's pause."""
_RESERVED_OPERAND: Final = 0x8000
"""First word of a reserved-operand float: sign 1, exponent 0."""
_SEGMENT_BIT: Final = 1 << SPEC.async_codes[AsyncCondition.SEGMENT_COMPLETED].notification_bit
_GUARD_BIT: Final = 1 << SPEC.async_codes[AsyncCondition.GUARD_HIT].notification_bit
_GUARD_STOP: Final = 1
"""Word 2 of a guard-hit response: 1 = the trajectory was stopped, 2 = it continues (E.3)."""
_GUARD_CONTINUE: Final = 2
_ASYNC_ERRORS: Final = frozenset({ServerOp.ASYNCHRONOUS_ERROR, ServerOp.ASYNCHRONOUS_WARNING})
_NOTIFICATION_MASK: Final = sum(1 << code.notification_bit for code in SPEC.async_codes.values())


def _word(n: int) -> bytes:
    return (n & WORD_MASK).to_bytes(2, "little")


class ServerSession:
    """One connection's protocol state machine; see the module docstring."""

    def __init__(
        self, config: ServerConfig | None = None, *, arm: ArmSim | None = None, wrist: Wrist | None = None
    ) -> None:
        self.config = config or ServerConfig()
        faults = self.config.faults
        self.faults = faults
        self.arm = arm or ArmSim(self.config.model, powered=self.config.powered_at_open)
        self.wrist: Wrist = wrist or NoWrist()
        self.wrist.condition(
            WristConditions(
                silent=Fault.WRIST_SILENT in faults, answer_timeouts=Fault.WRIST_TIMEOUT_SILENT not in faults
            )
        )
        if Fault.SEGMENT_NUMBER_STUCK in faults:
            self.arm.segment_step = 0
        self.arm.enforce_power = Fault.NO_NAP not in faults
        self.arm.enforce_abort = Fault.AWA_IGNORED not in faults
        if faults.obstacle is not None and Fault.OBSTACLE in faults:
            self.arm.place_obstacle(faults.obstacle)
        if Fault.SLUGGISH_JOINT in faults:
            self.arm.sluggish = faults.sluggish
        if Fault.COLLISION_UNCHECKED in faults:
            self.arm.collision_tol_deg = math.inf
        self.arm.increment_from_actual = Fault.INCREMENT_FROM_ACTUAL in faults
        self.arm.keep_queue_on_abort = Fault.ABORT_KEEPS_QUEUE in faults
        if Fault.SEGMENTS_STOP in faults:
            self.arm.stop_between_segments = _SEGMENTS_STOP_REST_S
        if Fault.SERVO_DOUBLE_RATE in faults:
            self.arm.tick_period /= 2
        self.arm.collision_test_compliant = Fault.COMPLIANT_COLLISION_TEST in faults
        self.arm.hold_compliant_end = Fault.COMPLIANT_SNAP_BACK not in faults
        use_faults = getattr(self.wrist, "use_faults", None)
        if use_faults is not None:  # the wrist processes' own defects (a Wrist need have none)
            use_faults(faults)
        self.state = State.AWAITING_INITIAL
        self.notifications = 0
        """The request-notifications mask in force (bit 0 guard hit, bit 1 segment completed)."""
        self.last_processed: int | None = None
        """Packet number of the last request processed (the RFC's until the first request)."""
        self._processed_before: int | None = None
        """The one processed before it (fault async-number-previous)."""
        self.last_received: int | None = None
        self._now = float("-inf")
        self._out: list[Outgoing] = []
        self._close = False
        self._next_state: State | None = None
        self._payloads: dict[int, tuple[tuple[Any, ...], bytes]] = {}
        """The last reply payload (after the request number) per opcode, by its values: Here polled while
        the arm stands still is answered without encoding (bench/server.py)."""
        self._pose: tuple[tuple[float, ...], tuple[float, ...]] | None = None
        """The last Here transform and the joint angles it is of."""
        self._waiting: tuple[RequestOpcode, int, Pending] | None = None
        """The request whose answer waits for the wrist: spec entry, reply number, pending reply."""
        self._held: deque[_Event] = deque()
        """Requests that arrived while waiting for the wrist, in order."""

    def inherit(self, previous: ServerSession) -> None:
        """Take over what the connection before this one set, as the ``connection-keeps-*`` fault
        switches say (a conforming session takes nothing: erratum server-robot)."""
        if Fault.KEEPS_SPEED in self.faults:
            self.arm.set_speed(previous.arm.speed)
        if Fault.KEEPS_CONFIGURATION in self.faults and previous.arm.lefty is not None:
            self.arm.set_configuration(previous.arm.lefty)
        if Fault.KEEPS_NOTIFICATIONS in self.faults:
            self.notifications = previous.notifications

    # ------------------------------------------------------------------------------ driver inputs
    def on_open(self, now: float, rfc_packet_no: int) -> Output:
        """The connection is open; ``rfc_packet_no`` is the packet number of the RFC that opened it."""
        return self._step(_Event(Input.OPEN, now, packet_no=rfc_packet_no))

    def on_request(
        self, now: float, opcode: int, packet_no: int, data: bytes, ack_no: int | None = None
    ) -> Output:
        """A data packet from the client (``ack_no``: its Chaos ack field, when the driver has it)."""
        return self._step(_Event(Input.REQUEST, now, opcode, packet_no, bytes(data), ack_no))

    def tick(self, now: float) -> Output:
        """Run the arm up to ``now``; returns the asynchronous packets due."""
        return self._step(_Event(Input.TICK, now))

    def on_close(self, now: float) -> Output:
        """The connection is gone; the session ends (the arm stops with it)."""
        return self._step(_Event(Input.CLOSE, now))

    @property
    def operations(self) -> tuple[int, ...]:
        """The opcodes this session answers normally, as describe self lists them."""
        served = {SPEC.request(name).opcode for name in HANDLERS}
        return tuple(sorted(served | self.wrist.served))

    # ---------------------------------------------------------------------------- the machine
    def _step(self, event: _Event) -> Output:
        transition = TRANSITIONS.get((self.state, event.kind))
        if transition is None:
            raise SessionUsageError(f"{event.kind.value} in state {self.state.value}")
        if event.now < self._now:
            raise ValueError(f"time went backwards: {event.now} < {self._now}")
        self._now = event.now
        self._out, self._close = [], False
        action, fixed = transition
        decided = action(self, event)
        self.state = decided or fixed or self.state
        return Output(tuple(self._out), self._close)

    def _emit(self, opcode: int, data: bytes) -> None:
        self._out.append(Outgoing(opcode, data))

    def _ignore(self, event: _Event) -> State | None:
        return None

    def _send_initial(self, event: _Event) -> State | None:
        self.last_processed = event.packet_no
        self.arm.tick(event.now)  # the move process starts with the connection
        if Fault.PANIC_BUTTON in self.faults:
            self.arm.press_panic(at=event.now + self.faults.panic_delay)
        if Fault.NO_INITIAL_RESPONSE not in self.faults:
            number = event.packet_no + (1 if Fault.INITIAL_RESPONSE_NUMBER in self.faults else 0)
            self._emit(ServerOp.RESPONSE, _word(number))
        return None

    def _run_arm(self, event: _Event) -> State | None:
        """Run the move process up to ``now``, then the wrist processes, and report what they did."""
        number = self.last_processed or 0
        self._report_arm(number, self.arm.tick(event.now))
        for wev in self.wrist.tick(event.now, self.arm):
            if isinstance(wev, GuardHit):
                # The abort is the guard hit itself: report only the segments that ended before it.
                self._report_arm(number, [e for e in wev.arm_events if not isinstance(e, MotionAborted)])
                if Fault.GUARD_UNREPORTED in self.faults:
                    continue
                if self.notifications & _GUARD_BIT or Fault.UNREQUESTED_ASYNC in self.faults:
                    word2 = _GUARD_STOP if wev.stop else _GUARD_CONTINUE
                    if Fault.GUARD_HIT_WORD_SWAPPED in self.faults:
                        word2 = _GUARD_STOP + _GUARD_CONTINUE - word2
                    self._emit_async(number, AsyncCondition.GUARD_HIT, word2, wev.index)
                elif wev.stop:
                    self._emit_error(ServerOp.ASYNCHRONOUS_ERROR, number, errors.guard_stop_error(wev.index))
            elif isinstance(wev, WristNotice):
                opcode = ServerOp.ASYNCHRONOUS_ERROR if wev.error else ServerOp.ASYNCHRONOUS_WARNING
                self._emit_error(opcode, number, wev.message)
        return None

    def _report_arm(self, number: int, events: list[ArmEvent]) -> None:
        for ev in events:
            if isinstance(ev, SegmentCompleted):
                if self.notifications & _SEGMENT_BIT or Fault.UNREQUESTED_ASYNC in self.faults:
                    segment = ev.segment
                    if Fault.SEGMENT_REPORT_PREVIOUS in self.faults:
                        segment = (segment - 1) & 0xFFFF
                    self._emit_async(number, AsyncCondition.SEGMENT_COMPLETED, 0, segment)
            elif isinstance(ev, MotionAborted):
                self._emit_error(ServerOp.ASYNCHRONOUS_ERROR, number, errors.abort_error(ev))
            elif isinstance(ev, FollowingWarning):
                self._emit_error(ServerOp.ASYNCHRONOUS_WARNING, number, errors.warning_error(ev))
                if Fault.WARNING_INTERRUPTS in self.faults:
                    self._report_arm(number, self.arm.halt(AbortCause.COLLISION))

    # ---------------------------------------------------------------- waiting for the wrist
    def _hold(self, event: _Event) -> State | None:
        """A request while the main process waits for Cougar: it is served after the wait."""
        self.last_received = event.packet_no
        self._held.append(event)
        return None

    def _wait_tick(self, event: _Event) -> State | None:
        self._run_arm(event)
        return self._settle(event.now)

    def _settle(self, now: float) -> State | None:
        """Answer the waiting request once the wrist has resolved it, then serve the held ones."""
        waiting = self._waiting
        if waiting is None or not waiting[2].done:
            return None
        op, number, pending = waiting
        self._waiting = None
        state: State | None = None
        try:
            values = pending.outcome()
        except RequestError as exc:
            if Fault.WRIST_ERROR_FATAL in self.faults:
                state = self._fatal(number, replace(exc.error, severity="F"))
            else:
                state = self._refuse(number, exc)
        else:
            self._reply(op, number, values)
        state = state or State.READY
        while self._held and state in (State.READY, State.FREE_JOINT_WAIT):
            held = replace(self._held.popleft(), now=now)
            action, fixed = TRANSITIONS[(state, Input.REQUEST)]
            state = action(self, held) or fixed or state
        return state

    def _abandon(self, event: _Event) -> State | None:
        if self._waiting is not None:
            self._waiting[2].cancel()
            self._waiting = None
        self._held.clear()
        return None

    def _discard(self, event: _Event) -> State | None:
        """The packet after free joint: un-free the joint, answer done, do not execute it."""
        self._run_arm(event)
        self.arm.unfree()
        if Fault.FREE_JOINT_EXECUTES in self.faults:
            return self._serve(event)
        self.last_received = self.last_processed = event.packet_no
        self._emit(ServerOp.RESPONSE, _word(self._echo(event)))
        return None

    def _serve(self, event: _Event) -> State | None:
        self._run_arm(event)
        self._processed_before = self.last_processed
        self.last_received = self.last_processed = event.packet_no
        number = self._echo(event)
        self._next_state = None
        op = SPEC.requests.get(event.opcode)
        try:
            if op is None:
                if Fault.UNKNOWN_OPCODE_ANSWERED in self.faults:
                    self._emit(ServerOp.RESPONSE, _word(number))
                    return None
                raise errors.unknown_opcode(event.opcode)
            handler = HANDLERS.get(op.name)
            if handler is None and op.opcode not in self.wrist.served:
                raise errors.not_served(op.opcode)
            values = self._decode(op, event.data)
            if (
                Fault.AWA_REFUSES_ALL in self.faults
                and self.arm.aborted
                and op.name not in ("enable-power", "reset-abort")
            ):
                raise errors.refusal_error(op.name, Refused("AWA", "motion aborted; reset first"))
            try:
                result: dict[str, Any] | Pending
                if handler is None:
                    result = self.wrist.handle(op, values, event.now, self.arm)
                else:
                    result = handler(self, values, event.now)
            except Refused as refusal:
                swap = Fault.SWAP_TOR_JOR in self.faults
                raise errors.refusal_error(op.name, refusal, swap_tor_jor=swap) from refusal
        except RequestError as exc:
            return self._refuse(number, exc)
        except Exception:
            log.exception("handler for opcode %s failed", octal(event.opcode))
            self._emit_error(ServerOp.NON_FATAL_ERROR, number, errors.internal_error(event.opcode).error)
            return None
        if isinstance(result, Pending):
            self._waiting = (op, number, result)
            return self._settle(event.now) or State.WRIST_WAIT  # already failed: answer at once
        self._reply(op, number, result)
        return self._next_state

    def _refuse(self, number: int, exc: RequestError) -> State | None:
        if exc.fatal:
            return self._fatal(number, exc.error)
        self._emit_error(ServerOp.NON_FATAL_ERROR, number, exc.error)
        if Fault.EXTRA_REPLY_AFTER_ERROR in self.faults:
            self._emit(ServerOp.RESPONSE, _word(number))
        return None

    def _fatal(self, number: int, error: ErrorMessage) -> State | None:
        if Fault.FATAL_NUMBER_PREVIOUS in self.faults:
            number = (number - 1) & WORD_MASK
        if Fault.FATAL_SEVERITY_E in self.faults:
            error = replace(error, severity="E")
        self._emit_error(ServerOp.FATAL_ERROR, number, error)
        if Fault.FATAL_WITHOUT_CLOSE in self.faults:
            return None
        self._close = True
        return State.CLOSED

    # ------------------------------------------------------------------------------- encoding
    def _echo(self, event: _Event) -> int:
        """The request number a reply to ``event`` carries."""
        if Fault.ECHO_ACK_NUMBER in self.faults:
            return event.ack_no if event.ack_no is not None else 0
        if Fault.WRONG_REQUEST_NUMBER in self.faults:
            return (event.packet_no + 1) & WORD_MASK
        return event.packet_no

    def _decode(self, op: RequestOpcode, data: bytes) -> Mapping[str, Value]:
        try:
            return decode_request(op.opcode, data).values
        except DecodeError as exc:
            expected = op.request.fixed_size or 0
            if exc.clause == "request.data-length":
                if Fault.LENGTH_UNCHECKED in self.faults:
                    return decode_request(op.opcode, data[:expected].ljust(expected, b"\0")).values
                raise errors.bad_length(expected, len(data)) from exc
            if exc.clause == "float.reserved-operand":
                raise errors.bad_float((exc.offset or 0) // 2) from exc
            raise errors.bad_value(op.name, exc.message) from exc

    def _reply(self, op: RequestOpcode, number: int, values: dict[str, Any]) -> None:
        if op.response.form == "multi":
            self._reply_text(number, str(values["text"]))
            return
        data = _word(number) + self._payload(op, values)
        floats_only = all(f.type.element == "float" for f in op.response.data.fields)
        if Fault.SWAPPED_FLOAT_WORDS in self.faults and op.response.form == "data" and floats_only:
            body = data[2:]
            swapped = (body[i + 2 : i + 4] + body[i : i + 2] for i in range(0, len(body), 4))
            data = data[:2] + b"".join(swapped)
        self._emit(ServerOp.RESPONSE, data)

    def _payload(self, op: RequestOpcode, values: dict[str, Any]) -> bytes:
        fields = op.response.data.fields
        if self.faults.active & _FLOAT_FAULTS and fields and all(f.type.element == "float" for f in fields):
            return b"".join(self._faulty_float(float(x)) for f in fields for x in values[f.name])
        key = tuple(values.values())  # equal values encode alike (-0.0 and 0.0 both as a clean zero)
        cached = self._payloads.get(op.opcode)
        if cached is not None and cached[0] == key:
            return cached[1]
        payload = encode_reply(op.opcode, 0, **values)[2:]
        self._payloads[op.opcode] = (key, payload)
        return payload

    def _faulty_float(self, x: float) -> bytes:
        """``x`` as a float encoder with the float faults switched on writes it."""
        if not math.isfinite(x) and Fault.NOT_FINITE_RESERVED in self.faults:
            return struct.pack("<HH", _RESERVED_OPERAND, 0)  # what an unchecked encoder makes of NaN
        if 0.0 < abs(x) < F_MIN_NORMAL and Fault.UNDERFLOW_DIRTY_ZERO in self.faults:
            fraction = max(1, int(abs(x) / F_MIN_NORMAL * (1 << 23)))  # exponent 0, the bits kept
            return struct.pack("<HH", fraction >> 16 & 0x7F, fraction & 0xFFFF)
        return pack_f(x)

    def _reply_text(self, number: int, text: str) -> None:
        """A multi-packet text reply: one packet per line (split further if a line is too long)."""
        first = True
        for line in text.splitlines(keepends=True):
            raw = encode_lispm(line)
            for i in range(0, len(raw), MAX_TEXT_PER_PACKET):
                n = number if first or Fault.MULTI_WRONG_NUMBER not in self.faults else number + 1
                self._emit(ServerOp.RESPONSE, _word(n) + raw[i : i + MAX_TEXT_PER_PACKET])
                first = False
        if Fault.NO_DESCRIBE_TERMINATOR not in self.faults:
            self._emit(ServerOp.RESPONSE, _word(number))

    def _emit_error(self, opcode: int, number: int, error: ErrorMessage) -> None:
        faults = self.faults
        if Fault.ASYNC_NUMBER_PREVIOUS in faults and opcode in _ASYNC_ERRORS:
            number = self._processed_before if self._processed_before is not None else number
        if Fault.WRONG_SEVERITY in faults:
            error = replace(error, severity="E" if opcode == ServerOp.FATAL_ERROR else "F")
        if any(fault in faults and error.code in codes for fault, codes in _SWAPPED_ARGS.items()):
            error = replace(
                error, args=tuple(int.from_bytes(a.to_bytes(2, "little"), "big") for a in error.args)
            )
        aligned = self.config.error_args == "aligned"
        if aligned and Fault.ERROR_PAD_MISPLACED not in faults and Fault.ERROR_WITHOUT_COLON not in faults:
            self._emit(opcode, encode_error(opcode, number, error))
            return
        body = error.encode(align_args=aligned)
        if Fault.ERROR_PAD_MISPLACED in faults and error.args:
            after_nul = body.index(0) + 1
            if after_nul % 2 == 0:  # no pad is due: one here puts the numbers at an odd offset
                body = body[:after_nul] + b"\0" + body[after_nul:]
        if Fault.ERROR_WITHOUT_COLON in faults:
            body = body.replace(b": ", b" ", 1)
        self._emit(opcode, _word(number) + body)

    def _emit_async(self, number: int, condition: int, word2: int, word3: int) -> None:
        with_number = Fault.ASYNC_WITHOUT_NUMBER not in self.faults
        data = encode_async(number, condition, word2, word3, async_has_request_number=with_number)
        self._emit(ServerOp.ASYNCHRONOUS_RESPONSE, data)

    # ------------------------------------------------------------------------------- handlers
    def _transform(self, op: str, values: Mapping[str, Value]) -> Transform:
        floats = values["transform"]
        assert isinstance(floats, tuple)
        try:
            return Transform.from_floats([float(x) for x in floats], orthonormalise=True)
        except ValueError as exc:
            raise errors.bad_value(op, "N, O and A are not a rotation") from exc

    def _describe_self(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        faults = self.faults
        operations = set(self.operations)
        if Fault.DESCRIBE_EXTRA_OPERATION in faults:
            operations.add(min(set(range(0o200, 0o300)) - operations))  # listed, answered C UOP
        if Fault.DESCRIBE_MISSING_OPERATION in faults:
            operations.discard(SPEC.request(MISSING_OPERATION).opcode)  # answered, not listed
        model = self.arm.model
        dof = len(model.ready) + (1 if Fault.DESCRIBE_WRONG_DOF in faults else 0)
        limits = [(lo, hi) for lo, hi in zip(model.limits.lower, model.limits.upper, strict=True)]
        if Fault.DESCRIBE_NARROW_LIMITS in faults:
            limits = [(lo + NARROWED_DEG, hi - NARROWED_DEG) for lo, hi in limits]
        if Fault.DESCRIBE_LIMITS_SHORT in faults:
            limits = limits[:-1]
        ready = list(model.ready)
        if Fault.DESCRIBE_READY_OFF in faults:
            ready[1] += READY_OFF_DEG
        text = describe_text(
            self.config.description,
            model,
            operations,
            with_protocol_version=Fault.NO_PROTOCOL_VERSION not in faults,
            degrees_of_freedom=dof,
            joint_limits=limits,
            ready_position=ready,
        )
        return {"text": text}

    def _here(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        actual = self.arm.actual
        if self._pose is None or self._pose[0] != actual:
            self._pose = (actual, self.arm.pose().to_floats())
        return {"transform": self._pose[1]}

    def _joint_angles(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        return {"joints": self.arm.actual}

    def _calibrate(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        if Fault.CALIBRATE_NZI in self.faults:
            raise errors.nzi_error(self.faults.nzi_joints)
        return {}  # the simulated arm needs no calibration

    def _move(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        return {"segment": self.arm.move_to(self._transform("move", values), now)}

    def _straight_move(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        pose = self._transform("straight-move", values)
        straight = Fault.STRAIGHT_AS_JOINT not in self.faults
        return {"segment": self.arm.move_to(pose, now, straight=straight)}

    def _kill_power(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        self.arm.kill_power()
        return {}

    def _set_configuration(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        low = _int(values["configuration"]) & 0xFF  # erratum set-configuration: the low byte counts
        if low & 0xFE:
            raise errors.bad_value("set-configuration", f"configuration {low} has bits other than bit 0 set")
        if Fault.CONFIGURATION_IGNORED not in self.faults:
            self.arm.set_configuration(lefty=bool(low & 1))
        return {}

    def _hand(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        self.arm.set_hand(_int(values["amount"]) != 0)
        return {}

    def _delta(self, values: Mapping[str, Value]) -> tuple[float, ...]:
        delta = _floats(values["delta"])
        if Fault.INCREMENT_O_T_SWAPPED in self.faults:
            dx, dy, dz, do, da, dt = delta
            return (dx, dy, dz, dt, da, do)
        return delta

    def _incremental_move(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        return {"segment": self.arm.move_increment(self._delta(values), now)}

    def _incremental_straight_move(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        straight = Fault.STRAIGHT_AS_JOINT not in self.faults
        return {"segment": self.arm.move_increment(self._delta(values), now, straight=straight)}

    def _free_joint(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        self.arm.free(_int(values["joint"]) & 0xFF)  # the first byte is the joint number
        self._next_state = State.FREE_JOINT_WAIT
        return {}

    def _ready(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        if Fault.READY_LEAVES_WRIST in self.faults:
            goal = self.arm.model.ready[:3] + self.arm.planned[3:]
            return {"segment": self.arm.move_joints(goal, now)}
        return {"segment": self.arm.move_ready(now)}

    def _set_joint_angles(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        goal = _floats(values["joints"])
        return {"segment": self.arm.move_joints(goal, now, check_limits=Fault.NO_JOR not in self.faults)}

    def _set_speed(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        factor = values["factor"]
        assert isinstance(factor, float)
        try:
            self.arm.set_speed(factor)
        except Refused:
            if Fault.SPEED_UNCHECKED not in self.faults:
                raise
        return {}

    def _enable_power(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        self.arm.enable_power()
        return {}

    def _solve_forwards(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        pose = self._transform("solve-forwards", values)
        try:
            return {"joints": self.arm.solve(pose, _floats(values["current"]))}
        except Refused:
            if Fault.NOT_FINITE_RESERVED not in self.faults:
                raise
            return {"joints": (math.nan,) * 6}

    def _solve_backwards(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        return {"transform": forward(_floats(values["joints"]), self.arm.model.geometry).to_floats()}

    def _request_notifications(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        mask = _int(values["mask"])
        if mask & ~_NOTIFICATION_MASK:
            raise errors.bad_value("request-notifications", f"mask {octal(mask)} has undefined bits set")
        self.notifications = mask
        return {}

    def _reset_abort(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        self.arm.reset_abort()
        return {}


def _int(value: Value) -> int:
    assert isinstance(value, int)
    return value


def _floats(value: Value) -> tuple[float, ...]:
    assert isinstance(value, tuple)
    return tuple(float(x) for x in value)


Transition = tuple[Callable[[ServerSession, _Event], State | None], State | None]
"""An action and the state after it (None: the state the action returns, else unchanged)."""

TRANSITIONS: Final[Mapping[tuple[State, Input], Transition]] = {
    (State.AWAITING_INITIAL, Input.OPEN): (ServerSession._send_initial, State.READY),
    (State.AWAITING_INITIAL, Input.TICK): (ServerSession._ignore, None),
    (State.AWAITING_INITIAL, Input.CLOSE): (ServerSession._ignore, State.CLOSED),
    (State.READY, Input.REQUEST): (ServerSession._serve, None),
    (State.READY, Input.TICK): (ServerSession._run_arm, None),
    (State.READY, Input.CLOSE): (ServerSession._ignore, State.CLOSED),
    (State.FREE_JOINT_WAIT, Input.REQUEST): (ServerSession._discard, State.READY),
    (State.FREE_JOINT_WAIT, Input.TICK): (ServerSession._run_arm, None),
    (State.FREE_JOINT_WAIT, Input.CLOSE): (ServerSession._ignore, State.CLOSED),
    (State.WRIST_WAIT, Input.REQUEST): (ServerSession._hold, None),
    (State.WRIST_WAIT, Input.TICK): (ServerSession._wait_tick, None),
    (State.WRIST_WAIT, Input.CLOSE): (ServerSession._abandon, State.CLOSED),
    (State.CLOSED, Input.REQUEST): (ServerSession._ignore, None),
    (State.CLOSED, Input.TICK): (ServerSession._ignore, None),
    (State.CLOSED, Input.CLOSE): (ServerSession._ignore, None),
}
"""The state table.  A missing pair (open twice, a request before open) is a driver error."""

HANDLERS: Final[Mapping[RequestName, Handler]] = {
    "describe-self": ServerSession._describe_self,
    "here": ServerSession._here,
    "joint-angles": ServerSession._joint_angles,
    "calibrate": ServerSession._calibrate,
    "move": ServerSession._move,
    "straight-move": ServerSession._straight_move,
    "kill-power": ServerSession._kill_power,
    "set-configuration": ServerSession._set_configuration,
    "hand": ServerSession._hand,
    "incremental-move": ServerSession._incremental_move,
    "incremental-straight-move": ServerSession._incremental_straight_move,
    "free-joint": ServerSession._free_joint,
    "ready": ServerSession._ready,
    "set-joint-angles": ServerSession._set_joint_angles,
    "set-speed": ServerSession._set_speed,
    "enable-power": ServerSession._enable_power,
    "solve-forwards": ServerSession._solve_forwards,
    "solve-backwards": ServerSession._solve_backwards,
    "request-notifications": ServerSession._request_notifications,
    "reset-abort": ServerSession._reset_abort,
}
"""Request handlers by spec name: every opcode the session itself serves."""

WRIST_OPERATIONS: Final[frozenset[RequestName]] = frozenset(
    {
        "read-forces",
        "read-raw-gauges",
        "set-gauge-offsets",
        "calibrate-wrist",
        "set-spring",
        "set-damping",
        "set-joint-damping",
        "set-frame-vector",
        "set-weight",
        "set-guard",
        "clear-guard",
        "compliant-move",
        "examine-wrist",
        "deposit-wrist",
        "wrist-version",
        "set-commanded-force",
    }
)
"""Spec requests handed to the :class:`Wrist` (answered C UIM without one)."""


def _check_tables() -> None:
    """Every spec request is served by a handler or handed to the wrist, and nothing else is named."""
    names = {op.name for op in SPEC.requests.values()}
    unknown = (set(HANDLERS) | WRIST_OPERATIONS) - names
    if unknown:
        raise RuntimeError(f"dispatch names requests the spec does not define: {sorted(unknown)}")
    both = set(HANDLERS) & WRIST_OPERATIONS
    if both:
        raise RuntimeError(f"requests both served and handed to the wrist: {sorted(both)}")
    missing = names - set(HANDLERS) - WRIST_OPERATIONS
    if missing:
        raise RuntimeError(f"spec requests with no handler: {sorted(missing)}")
    pairs = {(s, i) for s in State for i in Input}
    if set(TRANSITIONS) - pairs:
        raise RuntimeError("the state table names unknown states")


_check_tables()
