"""One connection of the reference Puma server, as a sans-I/O state machine.

Theory of operation
============
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
suites.  The session never tests one: at a few named points (the number a reply carries, the packets of
a reply, what an error says, what follows a fatal error ...) it hands what it is about to do to its
:class:`~manip.reference_server.defects.Defects` and does what comes back; a conforming session's
hooks change nothing (:mod:`manip.reference_server.defects` lists them).
"""

from __future__ import annotations

import enum
import logging
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any, Final, Literal

from manip.arm.kinematics import PUMA600, ArmModel, forward
from manip.arm.sim import (
    ArmEvent,
    ArmSim,
    FollowingWarning,
    MotionAborted,
    Refused,
    SegmentCompleted,
)
from manip.arm.transform import Transform
from manip.arm.units import LengthUnit, WireLengths
from manip.codecs.error_string import ErrorMessage
from manip.codecs.errors import DecodeError
from manip.codecs.lispm_text import encode_lispm
from manip.codecs.messages import (
    MAX_TEXT_PER_PACKET,
    AsyncLayout,
    Value,
    encode_reply,
)
from manip.reference_server import errors
from manip.reference_server.defects import Defects, defects_for
from manip.reference_server.describe import Description, Statement, describe_text
from manip.reference_server.errors import RequestError
from manip.reference_server.faults import FaultSet
from manip.reference_server.wrist import GuardHit, NoWrist, Pending, Wrist, WristNotice
from manip.spec import SPEC, RequestName, RequestOpcode
from manip.spec.constants import AsyncCondition, ServerOp
from manip.spec.notation import octal

__all__ = [
    "HANDLERS",
    "PROFILES",
    "TRANSITIONS",
    "WRIST_OPERATIONS",
    "ConfigurationBits",
    "ErrorArgs",
    "Input",
    "Outgoing",
    "Output",
    "ServerConfig",
    "ServerSession",
    "SessionUsageError",
    "State",
    "server_config",
]

log = logging.getLogger("manip.reference_server")

WORD_MASK: Final = 0xFFFF
ErrorArgs = Literal["aligned", "packed"]
ConfigurationBits = Literal["refuse", "done"]


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
    extensions: bool = True
    """Serve manip's Puma extension opcodes (0240 and up: the wrist, request notifications, reset abort).
    Off, the server is one written from the 1985 guide alone: it serves Appendix E's opcodes only, refuses
    every extension opcode exactly as an unknown one (C UOP), and describe self does not list them."""
    async_layout: AsyncLayout = "numbered"
    """The layout of an asynchronous response (erratum async-request-number; both conform):
    ``numbered`` puts the number of the last request processed first (8 bytes), ``guide`` writes the
    1985 guide's condition code and two words (6 bytes)."""
    length_unit: LengthUnit = "mm"
    """The unit of lengths on the wire (erratum units): the arm model stays in millimetres and the
    session converts transforms' positions and incremental moves' dX dY dZ at its boundary."""
    configuration_bits: ConfigurationBits = "refuse"
    """Set configuration with bits other than bit 0 (erratum set-configuration; both conform): ``refuse``
    answers C BVA, ``done`` answers done, as the 1985 guide says of set configuration, and uses bit 0."""

    @classmethod
    def guide_profile(cls, **changes: Any) -> ServerConfig:
        """A server as one written from the 1985 guide alone would be (``manip-server --profile guide``):
        no extension opcodes, lengths in inches, asynchronous responses in the guide's 6-byte layout,
        configuration bits besides bit 0 answered with done.  ``changes`` set other fields."""
        profile: dict[str, Any] = {
            "extensions": False,
            "length_unit": "inch",
            "async_layout": "guide",
            "configuration_bits": "done",
        }
        return cls(**{**profile, **changes})


PROFILES: Final = ("manip", "guide")
"""The reference server's profiles: ``manip`` (:class:`ServerConfig`'s defaults) and ``guide``
(:meth:`ServerConfig.guide_profile`)."""


def server_config(profile: str = "manip", **changes: Any) -> ServerConfig:
    """The configuration of ``profile`` (one of :data:`PROFILES`), with ``changes`` to single fields."""
    if profile == "guide":
        return ServerConfig.guide_profile(**changes)
    if profile != "manip":
        raise ValueError(f"unknown server profile {profile!r} (known: {', '.join(PROFILES)})")
    return ServerConfig(**changes)


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

_SEGMENT_BIT: Final = 1 << SPEC.async_codes[AsyncCondition.SEGMENT_COMPLETED].notification_bit
_GUARD_BIT: Final = 1 << SPEC.async_codes[AsyncCondition.GUARD_HIT].notification_bit
_GUARD_STOP: Final = 1
"""Word 2 of a guard-hit response: 1 = the trajectory was stopped, 2 = it continues (E.3)."""
_GUARD_CONTINUE: Final = 2
_NOTIFICATION_MASK: Final = sum(1 << code.notification_bit for code in SPEC.async_codes.values())


def _word(n: int) -> bytes:
    return (n & WORD_MASK).to_bytes(2, "little")


class ServerSession:
    """One connection's protocol state machine; see the module docstring."""

    def __init__(
        self, config: ServerConfig | None = None, *, arm: ArmSim | None = None, wrist: Wrist | None = None
    ) -> None:
        self.config = config or ServerConfig()
        self.lengths = WireLengths(self.config.length_unit)
        """Where wire lengths become the arm model's millimetres and back (the one place)."""
        self.defects: Defects = defects_for(self.config.faults)
        """The hook points the fault switches bend (chosen once, here)."""
        self.arm = arm or ArmSim(
            self.config.model, powered=self.config.powered_at_open, defects=self.defects.arm
        )
        self.wrist: Wrist = wrist or NoWrist()
        self.world = self.config.faults.world
        """The conditions of the arm's world this connection meets (none by default)."""
        self.world.place(self.arm)
        self.wrist.condition(self.defects.wrist, silent=self.world.wrist_silent)
        self.state = State.AWAITING_INITIAL
        self.notifications = 0
        """The request-notifications mask in force (bit 0 guard hit, bit 1 segment completed)."""
        self.last_processed: int | None = None
        """Packet number of the last request processed (the RFC's until the first request)."""
        self._processed_before: int | None = None
        """The one processed before it (the error-number hook point may use it)."""
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
        self.defects.inherit(self, previous)

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
        served = {SPEC.request(name).opcode for name in HANDLERS} | self.wrist.served
        return tuple(sorted(code for code in served if self._offered(SPEC.requests.get(code)) is not None))

    def _offered(self, op: RequestOpcode | None) -> RequestOpcode | None:
        """``op`` as this server knows it: None (an unknown opcode) for an extension opcode when the
        extensions are off."""
        if op is not None and op.extension and not self.config.extensions:
            return None
        return op

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
        return Output(tuple(self.defects.sent(event.kind is Input.REQUEST, self._out)), self._close)

    def _emit(self, opcode: int, data: bytes) -> None:
        self._out.append(Outgoing(opcode, data))

    def _ignore(self, event: _Event) -> State | None:
        return None

    def _send_initial(self, event: _Event) -> State | None:
        self.last_processed = event.packet_no
        self.arm.tick(event.now)  # the move process starts with the connection
        self.world.opened(self.arm, event.now)
        for number in self.defects.initial_numbers(event.packet_no):
            self._emit(ServerOp.RESPONSE, _word(number))
        return None

    def _run_arm(self, event: _Event) -> State | None:
        """Run the move process up to ``now``, then the wrist processes, and report what they did."""
        for data in self.defects.held_back(self.arm):
            self._emit(ServerOp.RESPONSE, data)
        number = self.last_processed or 0
        self._report_arm(number, self.arm.tick(event.now))
        for wev in self.wrist.tick(event.now, self.arm):
            if isinstance(wev, GuardHit):
                # The abort is the guard hit itself: report only the segments that ended before it.
                self._report_arm(number, [e for e in wev.arm_events if not isinstance(e, MotionAborted)])
                self._report_guard(number, wev)
            elif isinstance(wev, WristNotice):
                opcode = ServerOp.ASYNCHRONOUS_ERROR if wev.error else ServerOp.ASYNCHRONOUS_WARNING
                self._emit_error(opcode, number, wev.message)
        return None

    def _report_guard(self, number: int, hit: GuardHit) -> None:
        """A guard-hit response when the client asked for them, else an asynchronous error when the
        guard stopped the move (erratum ``guard-stop``)."""
        if not self.defects.reports_guard(hit):
            return
        if self.defects.notifications(self.notifications) & _GUARD_BIT:
            word2 = _GUARD_STOP if hit.stop else _GUARD_CONTINUE
            self._emit_async(number, AsyncCondition.GUARD_HIT, word2, hit.index)
        elif hit.stop:
            self._emit_error(ServerOp.ASYNCHRONOUS_ERROR, number, errors.guard_stop_error(hit.index))

    def _report_arm(self, number: int, events: list[ArmEvent]) -> None:
        for ev in events:
            if isinstance(ev, SegmentCompleted):
                if self.defects.notifications(self.notifications) & _SEGMENT_BIT:
                    self._emit_async(number, AsyncCondition.SEGMENT_COMPLETED, 0, ev.segment)
            elif isinstance(ev, MotionAborted):
                self._emit_error(ServerOp.ASYNCHRONOUS_ERROR, number, errors.abort_error(ev))
            elif isinstance(ev, FollowingWarning):
                self._emit_error(ServerOp.ASYNCHRONOUS_WARNING, number, errors.warning_error(ev))
                self._report_arm(number, self.defects.after_warning(self.arm))

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
            state = self._refuse(number, self.defects.wrist_failure(exc))
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
        if not self.defects.discards_after_free_joint:
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
        op = self._offered(SPEC.requests.get(event.opcode))
        try:
            result = self._execute(op, event)
        except RequestError as exc:
            outcome = self.defects.refused(op, exc)
            if isinstance(outcome, RequestError):
                return self._refuse(number, outcome)
            result = outcome  # a defect answers it anyway
        except Exception:
            log.exception("handler for opcode %s failed", octal(event.opcode))
            self._emit_error(ServerOp.NON_FATAL_ERROR, number, errors.internal_error(event.opcode).error)
            return None
        if isinstance(result, Pending):
            assert op is not None
            self._waiting = (op, number, result)
            return self._settle(event.now) or State.WRIST_WAIT  # already failed: answer at once
        self._reply(op, number, result)
        return self._next_state

    def _execute(self, op: RequestOpcode | None, event: _Event) -> dict[str, Any] | Pending:
        """Look the request up, decode it and run its handler (or the wrist's): its reply's values, a
        :class:`Pending`, or RequestError."""
        if op is None:
            raise errors.unknown_opcode(event.opcode)
        handler = HANDLERS.get(op.name)
        if handler is None and op.opcode not in self.wrist.served:
            raise errors.not_served(op.opcode)
        values = self._decode(op, event.data)
        self.defects.check(op, self.arm)
        self.world.check(op.name)
        try:
            if handler is None:
                return self.wrist.handle(op, values, event.now, self.arm)
            return handler(self, values, event.now)
        except Refused as refusal:
            raise errors.refusal_error(op.name, refusal) from refusal

    def _refuse(self, number: int, exc: RequestError) -> State | None:
        if exc.fatal:
            return self._fatal(number, exc.error)
        self._emit_error(ServerOp.NON_FATAL_ERROR, number, exc.error)
        for data in self.defects.after_error(number):
            self._emit(ServerOp.RESPONSE, data)
        return None

    def _fatal(self, number: int, error: ErrorMessage) -> State | None:
        self._emit_error(ServerOp.FATAL_ERROR, number, error)
        if self.defects.after_fatal == "stay-open":
            return None
        self._close = True
        return State.CLOSED

    # ------------------------------------------------------------------------------- encoding
    def _echo(self, event: _Event) -> int:
        """The request number a reply to ``event`` carries."""
        return self.defects.reply_number(event.packet_no, event.ack_no)

    def _decode(self, op: RequestOpcode, data: bytes) -> Mapping[str, Value]:
        try:
            return self.defects.decode(op, data)
        except DecodeError as exc:
            expected = op.request.fixed_size or 0
            if exc.clause == "request.data-length":
                raise errors.bad_length(expected, len(data)) from exc
            if exc.clause == "float.reserved-operand":
                raise errors.bad_float((exc.offset or 0) // 2) from exc
            raise errors.bad_value(op.name, exc.message) from exc

    def _reply(self, op: RequestOpcode | None, number: int, values: dict[str, Any]) -> None:
        """The reply in the form the spec gives the opcode (``op`` None, an unknown opcode: a bare
        RESPONSE, which only a defect answers with)."""
        if op is None:
            packets = [_word(number)]
        elif op.response.form == "multi":
            packets = self._text_packets(number, str(values["text"]))
        else:
            packets = [_word(number) + self.defects.payload(op, values, self._payload)]
        opcode = self.defects.reply_opcode(op)
        for data in self.defects.reply(op, packets):
            self._emit(opcode, data)

    def _payload(self, op: RequestOpcode, values: Mapping[str, Any]) -> bytes:
        """A reply's data after the request number, by the spec codec."""
        key = tuple(values.values())  # equal values encode alike (-0.0 and 0.0 both as a clean zero)
        cached = self._payloads.get(op.opcode)
        if cached is not None and cached[0] == key:
            return cached[1]
        payload = encode_reply(op.opcode, 0, **values)[2:]
        self._payloads[op.opcode] = (key, payload)
        return payload

    def _text_packets(self, number: int, text: str) -> list[bytes]:
        """A multi-packet text reply: one packet per line (split further if a line is too long), then
        the empty terminator."""
        packets = []
        for line in text.splitlines(keepends=True):
            raw = encode_lispm(line)
            for i in range(0, len(raw), MAX_TEXT_PER_PACKET):
                packets.append(_word(number) + raw[i : i + MAX_TEXT_PER_PACKET])
        return [*packets, _word(number)]

    def _emit_error(self, opcode: int, number: int, error: ErrorMessage) -> None:
        number = self.defects.error_number(opcode, number, self._processed_before)
        error = self.defects.error(opcode, error)
        encoded = error.encode(align_args=self.config.error_args == "aligned")
        self._emit(opcode, _word(number) + self.defects.error_string(error, encoded))

    def _emit_async(self, number: int, condition: int, word2: int, word3: int) -> None:
        self._emit(
            ServerOp.ASYNCHRONOUS_RESPONSE,
            self.defects.async_response(
                number, condition, word2, word3, numbered=self.config.async_layout == "numbered"
            ),
        )

    # ------------------------------------------------------------------------------- handlers
    def _transform(self, op: str, values: Mapping[str, Value]) -> Transform:
        floats = values["transform"]
        assert isinstance(floats, tuple)
        try:
            return Transform.from_floats(list(self.lengths.transform_in(floats)), orthonormalise=True)
        except ValueError as exc:
            raise errors.bad_value(op, "N, O and A are not a rotation") from exc

    def _describe_self(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        model = self.arm.model
        stated = self.defects.describe(Statement.of(model, self.operations))
        text = describe_text(
            self.config.description,
            model,
            stated.operations,
            with_protocol_version=stated.protocol_version,
            degrees_of_freedom=stated.degrees_of_freedom,
            joint_limits=stated.joint_limits,
            ready_position=stated.ready_position,
        )
        return {"text": self.defects.describe_text(text)}

    def _here(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        actual = self.arm.actual
        if self._pose is None or self._pose[0] != actual:
            self._pose = (actual, self.lengths.transform_out(self.arm.pose().to_floats()))
        return {"transform": self._pose[1]}

    def _joint_angles(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        return {"joints": self.arm.actual}

    def _calibrate(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        return {}  # the simulated arm needs no calibration

    def _move(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        straight = not self.defects.joint_moves
        return {"segment": self.arm.move_to(self._transform("move", values), now, straight=straight)}

    def _straight_move(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        pose = self._transform("straight-move", values)
        return {"segment": self.arm.move_to(pose, now, straight=self.defects.straight_lines)}

    def _kill_power(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        self.arm.kill_power()
        return {}

    def _set_configuration(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        low = _int(values["configuration"]) & 0xFF  # erratum set-configuration: the low byte counts
        if low & 0xFE and self.config.configuration_bits == "refuse":
            raise errors.bad_value("set-configuration", f"configuration {low} has bits other than bit 0 set")
        if self.defects.applies_configuration:
            self.arm.set_configuration(lefty=self.defects.configuration(bool(low & 1)))
        return {}

    def _hand(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        self.arm.set_hand(_int(values["amount"]) != 0)
        return {}

    def _delta(self, values: Mapping[str, Value]) -> tuple[float, ...]:
        return self.defects.increment(self.lengths.increment_in(_floats(values["delta"])))

    def _incremental_move(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        straight = not self.defects.joint_moves
        return {"segment": self.arm.move_increment(self._delta(values), now, straight=straight)}

    def _incremental_straight_move(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        straight = self.defects.straight_lines
        return {"segment": self.arm.move_increment(self._delta(values), now, straight=straight)}

    def _free_joint(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        self.arm.free(_int(values["joint"]) & 0xFF)  # the first byte is the joint number
        self._next_state = State.FREE_JOINT_WAIT
        return {}

    def _ready(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        return {"segment": self.defects.move_ready(self.arm, now)}

    def _set_joint_angles(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        goal = _floats(values["joints"])
        return {"segment": self.arm.move_joints(goal, now, check_limits=self.defects.checks_joint_limits)}

    def _set_speed(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        factor = values["factor"]
        assert isinstance(factor, float)
        self.defects.set_speed(self.arm, factor)
        return {}

    def _enable_power(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        self.arm.enable_power()
        return {}

    def _solve_forwards(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        pose = self._transform("solve-forwards", values)
        return {"joints": self.arm.solve(pose, _floats(values["current"]))}

    def _solve_backwards(self, values: Mapping[str, Value], now: float) -> dict[str, Any]:
        pose = forward(_floats(values["joints"]), self.arm.model.geometry)
        return {"transform": self.lengths.transform_out(pose.to_floats())}

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
