"""What a case works with: :class:`CaseContext` (options, seed, expectations) and :class:`Probe` (a raw
manip session over one fresh Chaos connection that records every packet both ways).

A probe is deliberately *not* a client library: it sends exactly the bytes a case gives it, takes the
server's packets in the order they come, and judges nothing by itself (the checks of
:mod:`manip.conformance.judge.checks` do).  What it adds:

* ``await ctx.connect()`` opens a connection (Chaos contact from the target address) and, unless
  ``initial=False``, waits for the initial RESPONSE (``probe.initial``); no initial RESPONSE is a
  failure of ``connect.initial-response``.
* ``await probe.request(opcode, data=b"")`` sends a request packet (opcode as number or spec name) and
  returns its Chaos packet number; ``await probe.send(name, **values)`` encodes the values with the
  spec layout first.  ``await probe.call(name, **values)`` = send + :meth:`Probe.reply`.
* ``await probe.reply(number, timeout=None)`` returns the next :class:`Answer` (the next RESPONSE,
  non-fatal or fatal error; asynchronous packets are set aside in ``probe.unsolicited``).  Answers come
  in request order, so the probe does not match them by number: ``number`` only labels the record (the
  checks compare it).  No answer within the timeout (``ctx.options.reply_timeout`` by default), or the
  connection ending first, raises :class:`CaseFailure` (``request.one-reply``).
* ``await probe.replies_until_empty(number)``: every packet of a multi-packet reply up to and
  including its empty terminator (or up to an error, a timeout or the close: ``answer.terminated``).
* ``await probe.next_packet(timeout)``: the next server packet of any kind, or None on timeout or at
  the end of the connection (``probe.closed``, ``probe.end_reason``).
* ``probe.packets``: the recording (:class:`~manip.conformance.judge.checks.WirePacket`, both directions,
  times from the start of the case; the end of the connection is a CLS/EOF/LOS pseudo-packet).

What a probe reads from the target is bounded, as in ``manip-client``: a multi-packet reply that brings
more than :data:`~manip.reference_client.options.DEFAULT_MAX_REPLY_BYTES` without its terminator fails
``request.one-reply`` (erratum ``reply-size-limit``), and a case that receives more than
:data:`MAX_CASE_PACKETS` packets from the target ends failed with the first MUST violation of its recording
(a flood of extra replies or asynchronous packets is one), or without a clause when there is none.  A
request the case cannot send because the target ended the connection fails like a reply that never
came.

``ctx.expect(cond, clause=..., expected=..., seen=answer)`` is the one way to state a check, and the
common ones build their condition themselves (``ctx.expect_response``, ``expect_done``, ``expect_opcode``,
``expect_echo``, ``expect_near``, ``expect_finite``, ``expect_none``).  Evidence has one form, ``seen=``
(an answer, packets, ``showing(answer, text)``, ``missing(text)``:
:mod:`~manip.conformance.judge.violation`), and every violation names the packets it judged (text
alone: the last packet recorded, :meth:`CaseContext.judged`), but one about a packet that never came (a
reply that never came names the request it answers).  A false check, on a
clause of any level, is recorded (``ctx.recorded``) and the case goes on, so its report lists every
violation; ``ctx.require(...)`` is the same check for what the rest of the case depends on, and stops the
case when false, as the probe does when an answer never comes.
Every clause a check evaluated, true or false, is *reached* (``ctx.reached``): only a reached clause can
count as held.  The clause must be one the case declares: any other is a bug of the suite
(:class:`~manip.conformance.suite.case.UndeclaredClauseError`, raised at the call whether the condition
holds or not), except a violation the transcript invariant's checkers found
(:mod:`manip.conformance.suite.invariants`).  ``ctx.check(violations)`` applies the same rule to the
violations of a checker; ``ctx.fail(...)`` fails outright; ``ctx.skip(reason)`` ends the case as skipped
(not applicable), and ``ctx.not_judged(reason)`` as not judged (applicable, but this target cannot be
judged on it; the reason says what would judge it).  ``async with ctx.arranged(condition):`` has the
target's world hold a condition of the arm's world (:mod:`manip.conformance.suite.world`) for the block.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import random
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Iterable, Sequence
from contextlib import AbstractAsyncContextManager
from dataclasses import dataclass, replace
from typing import Any, Final, Literal, NoReturn, Protocol

from manip.arm.units import MM_PER_UNIT, LengthUnit
from manip.codecs.errors import CodecError
from manip.codecs.messages import encode_request
from manip.codecs.packet import Direction, Packet
from manip.codecs.pdp11float import unpack_f
from manip.conformance.judge.checks import (
    ANSWER_OPCODES,
    WirePacket,
    check_server_opcode,
    check_transcript,
    describe,
    word,
)
from manip.conformance.judge.packets import carries_data
from manip.conformance.judge.violation import NEVER_CAME, Violation, evidence, seen_kind, seen_packets
from manip.conformance.suite.case import (
    LEVEL_ORDER,
    CaseError,
    CaseFailure,
    CaseSkipped,
    UndeclaredClauseError,
)
from manip.conformance.suite.invariants import TRANSCRIPT, attribution_problem
from manip.conformance.suite.world import CaseNotJudged, Condition, World, no_world
from manip.cougar.memory_map import CougarMemoryMap
from manip.links import ChaosConnection, ChaosError, ConnectionClosed, ConnectionLost
from manip.links.api import LinkWrapper
from manip.reference_client.options import DEFAULT_MAX_REPLY_BYTES
from manip.spec import SPEC, RequestName
from manip.spec.constants import ASYNC_OPS, ERROR_REPLY_OPS, ChaosOp, ServerOp
from manip.spec.model import Hazard, Level
from manip.spec.notation import octal

__all__ = [
    "DONE_SIZE",
    "MAX_CASE_PACKETS",
    "Answer",
    "CaseContext",
    "Connector",
    "Probe",
    "RunOptions",
]

Robot = Literal["sim", "hardware"]
"""What is behind the target: a simulated arm, or real hardware (``--target``), where the motion and
power cases wait for ``--allow-motion``."""
_CHECKER_CLAUSES: Final = (
    TRANSCRIPT.clauses
    | {"response.word-byte-order"}
    | {clause for op in SPEC.requests.values() for clause in op.reply_clauses}
)
"""What a checker run on one answer evaluates (:meth:`CaseContext.check`): the transcript's clauses,
the byte order its decoding relies on, and the reply clauses of the opcodes, whose layouts it decodes."""
DONE_SIZE: Final = 2
"""Data bytes of an empty done: the request number alone."""
DEFAULT_REPLY_TIMEOUT: Final = 2.0
DEFAULT_CONNECT_TIMEOUT: Final = 5.0
MAX_CASE_PACKETS: Final = 20_000
"""The most packets one case takes from the target (all its connections): about 14 MB of recording.
A case needs a few dozen, a property case a few thousand; a describe-self at the reply bound is 2,160."""


class _Connector(Protocol):
    """Opens one fresh Chaos connection to the target (the runner provides it): ``retry_busy`` says
    whether a refusal as busy (the previous case's connection still closing) is retried, ``watch`` is
    given the connection's link first (a case that judges the link keeps it, to read its counters even
    when the connection never opens)."""

    def __call__(self, retry_busy: bool, watch: LinkWrapper | None = None) -> Awaitable[ChaosConnection]: ...


Connector = _Connector


@dataclass(frozen=True)
class RunOptions:
    """The run's settings, as cases see them."""

    robot: Robot = "sim"
    allow_motion: bool = False
    strict: bool = False
    reply_timeout: float = DEFAULT_REPLY_TIMEOUT
    connect_timeout: float = DEFAULT_CONNECT_TIMEOUT
    deadline_scale: float = 1.0
    time_scale: float = 1.0
    """How many times faster than real time the target's arm runs (a simulated server with a time scale):
    the motion cases judge the servo cycle, and sample, at that rate."""
    max_examples: int = 25
    address: str = ""
    """The target's link address, as given (for messages and reproduce commands)."""
    broken_after: float | None = None
    """The target's broken-connection timer, when the run is to check it (``--broken-after``)."""
    embedded: bool = False
    """The target is the embedded reference server: its address is a temporary socket, gone after the
    run, so a case says how to run it again (:attr:`CaseContext.reproduce`), never that address."""
    cougar_map: CougarMemoryMap | None = None
    """A Cougar target's memory map (``--memory-map``; the simulator's own for ``--cougar sim``): without
    one the cases that read or write Cougar memory are not judged."""
    length_unit: LengthUnit = "mm"
    """The unit the target's lengths are taken to be in (``--length-unit``; the 1985 guide gives none,
    errata ``units`` and ``cougar-length-unit``): every Cartesian move and position tolerance of the
    server cases, and a Cougar's frame vector and centre of gravity, are sized in it."""

    learn_length_unit: bool = False
    """``--length-unit auto``: the runner learns :attr:`length_unit` from the target's ready pose before
    the cases (:mod:`manip.conformance.suite.units`)."""

    @property
    def mm_per_unit(self) -> float:
        """Millimetres in one unit of the target's lengths."""
        return MM_PER_UNIT[self.length_unit]

    @property
    def allowed_hazards(self) -> frozenset[Hazard]:
        """Opcode hazard classes cases may send: all on a simulator; on hardware read-only and config
        unless ``--allow-motion``."""
        if self.robot == "sim" or self.allow_motion:
            return frozenset({"read-only", "config", "motion", "power"})
        return frozenset({"read-only", "config"})


@dataclass(frozen=True)
class Answer:
    """The server's answer to one request: one packet, or every packet of a multi-packet reply."""

    request: WirePacket
    packets: tuple[WirePacket, ...]
    terminated: bool = True
    """For multi-packet replies: whether the empty terminator came."""

    @property
    def first(self) -> WirePacket:
        return self.packets[0]

    @property
    def opcode(self) -> int:
        return self.first.opcode

    @property
    def number(self) -> int | None:
        """The request number the (first) answer packet carries."""
        return word(self.first.data)

    @property
    def data(self) -> bytes:
        return self.first.data

    @property
    def payload(self) -> bytes:
        """The first packet's data after the request number."""
        return self.first.data[2:]

    @property
    def is_response(self) -> bool:
        return self.opcode == ServerOp.RESPONSE

    @property
    def is_error(self) -> bool:
        return self.opcode in ERROR_REPLY_OPS

    @property
    def all_data(self) -> bytes:
        return b"".join(p.data for p in self.packets)

    def __str__(self) -> str:
        return describe(self.first) + (f" + {len(self.packets) - 1} more" if len(self.packets) > 1 else "")


class Probe:
    """A raw manip session over one Chaos connection; see the module docstring."""

    def __init__(self, ctx: CaseContext, conn: ChaosConnection, index: int) -> None:
        self._ctx = ctx
        self.conn = conn
        self.index = index
        self.packets: list[WirePacket] = []
        self.unsolicited: list[WirePacket] = []
        """Asynchronous packets (0203, 0204, 0205) received while waiting for replies."""
        self.initial: WirePacket | None = None
        self.rfc_packet_no: int | None = None
        self.end_reason: ChaosError | None = None
        self._buffer: list[WirePacket] = []
        self._unanswered: dict[int, tuple[int, float]] = {}
        """Requests sent and not yet answered, in order: packet number -> (opcode, the seconds its answer
        may wait for the arm, 0 for most)."""
        self._speed = 1.0
        """The speed factor this connection last set (accepted set-speed-factor)."""
        self._motion_until = 0.0
        """When (loop clock) the motion this connection queued may at the latest be done."""

    @property
    def closed(self) -> bool:
        """The connection has ended (and every packet before the end has been taken)."""
        return self.end_reason is not None and not self._buffer

    def _record(self, direction: Direction, opcode: int, number: int, ack: int, data: bytes) -> WirePacket:
        packet = WirePacket(direction, opcode, number, ack, bytes(data), self._ctx.clock(), self.index)
        self.packets.append(packet)
        self._ctx.transcript.append(packet)
        if direction == "s2c":
            self._ctx.received += 1
            if self._ctx.received > MAX_CASE_PACKETS:
                self._flooded()
        return packet

    def _flooded(self) -> NoReturn:
        """The case took :data:`MAX_CASE_PACKETS` from the target: it reads no more.  The recording's
        first MUST violation is the failure (what the flood broke); without one, a failure of its own."""
        self.end_reason = self.end_reason or ConnectionClosed("the case stopped reading", by_peer=False)
        self._ctx.auto_check = False
        self._ctx.check(check_transcript(self.packets, rfc_packet_no=self.rfc_packet_no))
        raise CaseFailure(
            Violation(
                f"the target sent more than {MAX_CASE_PACKETS:,} packets within one case; "
                "the suite reads no more",
                expected=f"at most {MAX_CASE_PACKETS:,} packets for one case's requests",
                actual=f"{self._ctx.received - 1:,} packets, and more coming",
                kind="unexpected_message",
                packets=self._ctx.judged(),
            )
        )

    # ------------------------------------------------------------------------------------- sending

    async def request(self, opcode: int | RequestName, data: bytes = b"") -> int:
        """Send one request packet with exactly ``data``; return its Chaos packet number."""
        code = SPEC.request(opcode).opcode if isinstance(opcode, str) else opcode
        wait = self._send_wait()
        try:
            async with asyncio.timeout(wait):
                number = await self.conn.send(bytes(data), code)
        except TimeoutError:
            self._ctx.auto_check = False
            self._ctx.check(check_transcript(self.packets, rfc_packet_no=self.rfc_packet_no))
            raise CaseFailure(
                Violation(
                    f"the target did not take request {_request_name(code)} within {wait:g} s: the window "
                    "it offers stayed full (it acknowledged none of the requests before it)",
                    expected=f"room in the target's window within {wait:g} s",
                    actual="the window full",
                    kind="timeout",
                    packets=self._unanswered_requests(),
                )
            ) from None
        except ChaosError as exc:
            self._ended(exc)
            raise CaseFailure(
                Violation(
                    f"the target ended the connection before request {_request_name(code)} could be sent",
                    "request.one-reply" if self._unanswered else None,
                    expected="the connection open until the case closes it"
                    + (", and a reply to every request sent" if self._unanswered else ""),
                    actual=f"connection ended: {exc}",
                    kind="closed",
                    invariant=TRANSCRIPT.name if self._unanswered else None,
                    packets=self._unanswered_requests(),
                )
            ) from exc
        ack = 0
        self._record("c2s", code, number, ack, data)
        self._unanswered[number] = (code, self.arm_wait(code))
        return number

    def _unanswered_requests(self) -> tuple[WirePacket, ...]:
        """The requests sent and not answered yet, oldest first: what a failure to send names."""
        return tuple(self._request(number) for number in self._unanswered)

    def _send_wait(self) -> float:
        """How long a request may wait for room in the target's window: the reply timeout, or the
        allowance of the oldest unanswered request if longer (the target acknowledges as it takes them)."""
        oldest = next(iter(self._unanswered), None)
        allowed = self.allowance(oldest)[0] if oldest is not None else 0.0
        return max(self._ctx.options.reply_timeout, allowed)

    def arm_wait(self, code: int) -> float:
        """Seconds the answer to request ``code`` sent now may wait for the arm (erratum
        ``answer-allowance``): its own ``answer_within`` at the speed factor in force, after the motion
        still queued before it; 0 for a request whose answer does not wait for the arm."""
        op = SPEC.requests.get(code)
        if op is None or op.answer_within is None:
            return 0.0
        queued = max(0.0, self._motion_until - self._ctx.clock())
        return queued + op.answer_within * self._ctx.options.deadline_scale / self._speed

    def _answered(self, number: int, answer: WirePacket) -> None:
        """Note what an answer tells about the connection's motion queue and speed."""
        code, _ = self._unanswered.pop(number, (None, 0.0))
        op = SPEC.requests.get(code) if code is not None else None
        if op is None or answer.opcode != ServerOp.RESPONSE:
            return
        if op.name == "set-speed":
            sent = self._request(number).data
            with contextlib.suppress(CodecError):
                factor = unpack_f(sent[:4])
                if 0.0 < factor <= 1.0:
                    self._speed = factor
        elif op.response.form == "segment" or (op.hazard == "motion" and op.answer_within is not None):
            # One more segment in the queue (calibrate-wrist leaves its move back queued).
            segment = SPEC.segment_within * self._ctx.options.deadline_scale / self._speed
            self._motion_until = max(self._motion_until, self._ctx.clock()) + segment

    def allowance(self, number: int) -> tuple[float, str]:
        """How long request ``number`` may wait for its answer, and why (for failure messages).

        Each request gets the reply timeout or, when its answer waits for the arm, the time the arm may
        take (:meth:`arm_wait`) if longer.  A server answers in order, so the arm waits of the
        unanswered requests sent before it are added (erratum ``answer-allowance``)."""
        options = self._ctx.options
        code, wait = self._unanswered.get(number, (None, 0.0))
        own = max(options.reply_timeout, wait)
        name = SPEC.requests[code].name if code is not None and code in SPEC.requests else "the request"
        parts = [
            f"{own:g} s "
            + (f"the arm may take for {name} #{number}" if wait > options.reply_timeout else "reply timeout")
        ]
        total = own
        for earlier, (earlier_code, earlier_wait) in self._unanswered.items():
            if earlier == number:
                break
            if earlier_wait > 0:
                total += earlier_wait
                parts.append(
                    f"{earlier_wait:g} s for {SPEC.requests[earlier_code].name} #{earlier} before it"
                )
        return total, " + ".join(parts)

    async def send(self, op: int | RequestName, **values: Any) -> int:
        """Encode ``values`` by the spec layout of ``op`` and send the request."""
        return await self.request(SPEC.request(op).opcode, encode_request(op, **values))

    async def call(self, op: int | RequestName, *, timeout: float | None = None, **values: Any) -> Answer:
        """Send a well-formed request and wait for its answer (multi-packet replies in full)."""
        spec_op = SPEC.request(op)
        number = await self.send(op, **values)
        if spec_op.response.form == "multi":
            return await self.replies_until_empty(number, timeout=timeout)
        return await self.reply(number, timeout=timeout)

    async def call_raw(self, opcode: int, data: bytes = b"", *, timeout: float | None = None) -> Answer:
        """Send raw bytes and wait for the single answer."""
        number = await self.request(opcode, data)
        return await self.reply(number, timeout=timeout)

    # ------------------------------------------------------------------------------------- receiving

    async def next_packet(self, timeout: float | None = None) -> WirePacket | None:
        """The next server packet (any opcode), or None on timeout or once the connection has ended."""
        if self._buffer:
            return self._buffer.pop(0)
        if self.end_reason is not None:
            return None
        wait = self._ctx.options.reply_timeout if timeout is None else timeout
        try:
            async with asyncio.timeout(wait):
                packet: Packet = await self.conn.receive()
        except TimeoutError:
            return None
        except ChaosError as exc:
            self._ended(exc)
            return None
        return self._record("s2c", packet.opcode, packet.packet_no, packet.ack_no, packet.data)

    def _ended(self, exc: ChaosError) -> None:
        """The connection ended (``exc`` says how): recorded once, as a CLS/EOF/LOS pseudo-packet."""
        if self.end_reason is not None:
            return
        self.end_reason = exc
        kind = ChaosOp.LOS if isinstance(exc, ConnectionLost) else ChaosOp.CLS
        if isinstance(exc, ConnectionClosed) and exc.reason == "EOF":
            kind = ChaosOp.EOF
        self._record("s2c", kind, 0, 0, str(exc).encode("ascii", "replace"))

    def push_back(self, packet: WirePacket) -> None:
        """Return a packet so the next :meth:`next_packet` gives it again."""
        self._buffer.insert(0, packet)

    async def _next_answer_packet(self, number: int, timeout: float | None, what: str) -> WirePacket:
        """The next answer packet to request ``number``; none (a timeout, the end of the connection)
        fails ``request.one-reply``, naming the request that went unanswered, or
        ``response.server-opcodes`` when a packet of no server opcode came in its place."""
        request = self._request(number)
        strays: list[Violation] = []  # what came while waiting that no server may send
        loop = asyncio.get_running_loop()
        if timeout is None:
            wait, budget = self.allowance(number)
        else:
            wait, budget = timeout, "the case's own wait"
        deadline = loop.time() + wait
        while True:
            packet = await self.next_packet(max(0.0, deadline - loop.time()))
            if packet is None:
                if self.end_reason is not None:
                    raise CaseFailure(
                        Violation(
                            f"the connection ended while waiting for {what}",
                            "request.one-reply",
                            expected=what,
                            actual=f"connection ended: {self.end_reason}",
                            kind="closed",
                            invariant=TRANSCRIPT.name,
                            packets=(request,),
                        )
                    )
                if strays:  # the answer came, under an opcode a server never sends
                    stray = strays[0]
                    raise CaseFailure(
                        replace(
                            stray,
                            message=f"{what} did not come within {wait:g} s; a {stray.message} came instead",
                            invariant=TRANSCRIPT.name,
                            packets=(*stray.packets, request),
                        )
                    )
                raise CaseFailure(
                    Violation(
                        f"{what} did not come within {wait:g} s ({budget})",
                        "request.one-reply",
                        expected=f"{what} within {wait:g} s",
                        actual="nothing (timeout)",
                        kind="timeout",
                        invariant=TRANSCRIPT.name,
                        packets=(request,),
                    )
                )
            if packet.opcode in ANSWER_OPCODES:
                self._answered(number, packet)
                return packet
            strays += check_server_opcode(packet)
            self.unsolicited.append(packet)

    async def reply(self, number: int, timeout: float | None = None) -> Answer:
        """The next answer packet (RESPONSE, 0201 or 0202), taken as the answer to request ``number``."""
        request = self._request(number)
        packet = await self._next_answer_packet(number, timeout, f"a reply to request #{number}")
        return Answer(request, (packet,))

    async def replies_until_empty(self, number: int, timeout: float | None = None) -> Answer:
        """Every packet of a multi-packet reply to ``number``, up to its empty terminator.

        Stops early (``terminated=False``) at an error packet, a packet that is not a RESPONSE, a timeout
        or the end of the connection; the first packet missing altogether raises like :meth:`reply`.
        A reply that brings more than ``DEFAULT_MAX_REPLY_BYTES`` of text without its terminator fails
        ``request.one-reply`` (erratum ``reply-size-limit``: the bound of ``manip-client``)."""
        request = self._request(number)
        first = await self._next_answer_packet(number, timeout, f"a reply to request #{number}")
        packets = [first]
        if first.opcode != ServerOp.RESPONSE or len(first.data) <= 2:
            return Answer(request, (first,), terminated=first.opcode == ServerOp.RESPONSE)
        size = len(first.data) - 2
        while True:
            if size > DEFAULT_MAX_REPLY_BYTES:
                self._too_large(number, packets, size)
            packet = await self.next_packet(timeout)
            if packet is None:
                return Answer(request, tuple(packets), terminated=False)
            if packet.opcode in ASYNC_OPS:
                self.unsolicited.append(packet)
                continue
            if packet.opcode != ServerOp.RESPONSE:
                self.push_back(packet)
                return Answer(request, tuple(packets), terminated=False)
            packets.append(packet)
            size += max(0, len(packet.data) - 2)
            if len(packet.data) <= 2:
                return Answer(request, tuple(packets), terminated=True)

    def _too_large(self, number: int, packets: Sequence[WirePacket], size: int) -> NoReturn:
        raise CaseFailure(
            Violation(
                f"the multi-packet reply to request #{number} goes past {DEFAULT_MAX_REPLY_BYTES:,} data "
                "bytes without its terminator; the suite reads no more of it (erratum reply-size-limit)",
                "request.one-reply",
                expected=f"the empty terminator within {DEFAULT_MAX_REPLY_BYTES:,} data bytes "
                "(manip-client's bound)",
                actual=f"{len(packets):,} packets, {size:,} data bytes, no terminator",
                data=packets[-1].data,
                kind="unexpected_message",
                invariant=TRANSCRIPT.name,
                packet=packets[-1],
            )
        )

    async def drain(self, quiet: float = 0.2) -> list[WirePacket]:
        """Take every packet that arrives until ``quiet`` seconds pass without one."""
        out: list[WirePacket] = []
        while (packet := await self.next_packet(quiet)) is not None:
            out.append(packet)
        return out

    async def wait_closed(self, timeout: float | None = None) -> bool:
        """Wait for the connection to end, taking (and recording) what arrives; True if it ended."""
        loop = asyncio.get_running_loop()
        wait = self._ctx.options.reply_timeout if timeout is None else timeout
        deadline = loop.time() + wait
        while self.end_reason is None:
            remaining = deadline - loop.time()
            if remaining <= 0:
                return False
            await self.next_packet(remaining)
        return True

    def _request(self, number: int) -> WirePacket:
        for packet in reversed(self.packets):
            if packet.direction == "c2s" and packet.packet_no == number:
                return packet
        raise ValueError(f"request #{number} was not sent on this probe")

    async def close(self, wait: float = 1.0) -> None:
        """Close the connection: our EOF, then a CLS once the target has read it, or after ``wait``
        seconds whatever it did (it may be gone, or never read again)."""
        if self.end_reason is None:
            self.end_reason = ConnectionClosed("closed by the case", by_peer=False)
        with contextlib.suppress(ChaosError):
            await self.conn.close(timeout=wait)


class CaseContext:
    """Everything a running case may use; see the module docstring."""

    def __init__(
        self,
        *,
        case_id: str,
        level: Level,
        seed: int,
        options: RunOptions,
        connector: Connector,
        clauses: Iterable[str] | None = None,
        world: World | None = None,
        reproduce: str = "",
    ) -> None:
        self.case_id = case_id
        self.reproduce = reproduce
        """The command that runs this case again (the report's reproduce line)."""
        self.world = world
        """The target's world, which arranges the conditions the protocol cannot provoke
        (:meth:`arranged`); None when the run has none (the embedded server always has one)."""
        self.level = level
        self.clauses: frozenset[str] | None = None if clauses is None else frozenset(clauses)
        """The clauses the case declares: the only ones it may report (None: any, for contexts that
        run no registered case, such as the liveness probe)."""
        self.seed = seed
        """This case's seed: derived from the run's ``--seed`` and the case id, so it does not change
        when other cases are selected or skipped."""
        self.random = random.Random(seed)
        self.options = options
        self.transcript: list[WirePacket] = []
        """Every packet of every probe of this case, in the order recorded."""
        self.probes: list[Probe] = []
        self.recorded: list[Violation] = []
        """The violations recorded on the way, of every level (the case went on after each)."""
        self.reached: set[str] = set()
        """The declared clauses a check of this case actually evaluated (:meth:`expect`, :meth:`check`,
        :meth:`exercised`): only these can count as held
        (:func:`~manip.conformance.suite.results.clause_statuses`)."""
        self.notes: list[str] = []
        self.shown_packets: list[WirePacket] | None = None
        """The packet log the report shows, when not the transcript (:meth:`show_packets`)."""
        self.auto_check = True
        """After the case, the runner checks every probe's whole recording with
        :func:`~manip.conformance.judge.checks.check_transcript`; a case that leaves the protocol on purpose
        (it sends a raw packet the transcript checker would misjudge) sets this False."""
        self.deadline_scope: asyncio.Timeout | None = None
        """The case's deadline (set by the runner); time spent waiting on the world is added to it."""
        self.received = 0
        """Packets taken from the target so far, all connections (bounded: :data:`MAX_CASE_PACKETS`)."""
        self._connector = connector
        self._clock = _loop_clock()
        self._t0 = self._clock()

    @property
    def max_examples(self) -> int:
        return self.options.max_examples

    def clock(self) -> float:
        """Seconds since the case started, on the event loop's clock (virtual in a simulated run)."""
        return self._clock() - self._t0

    def show_packets(self, packets: Sequence[WirePacket]) -> None:
        """Make ``packets`` the case's packet log in the report instead of its whole transcript: a property
        or stateful case shows the run of its shrunk example, where the failure is."""
        self.shown_packets = list(packets)

    def note(self, text: str) -> None:
        """A line of information for the report (what the case observed)."""
        self.notes.append(text)

    # ------------------------------------------------------------------------------------- connecting

    async def connect(
        self, *, initial: bool = True, retry_busy: bool = True, watch: LinkWrapper | None = None
    ) -> Probe:
        """A new probe over a fresh connection; with ``initial`` the initial RESPONSE is taken first.

        ``retry_busy=False`` for a case that expects the refusal (one server per robot); ``watch`` is
        given the connection's link (:class:`Connector`)."""
        try:
            conn = await (
                self._connector(retry_busy) if watch is None else self._connector(retry_busy, watch)
            )
        except ChaosError as exc:
            raise CaseFailure(
                f"could not connect: {exc}",
                expected="the connection to open",
                actual=f"{type(exc).__name__}: {exc}",
                kind="closed",
            ) from exc
        probe = Probe(self, conn, len(self.probes))
        info = conn.info()
        probe.rfc_packet_no = info.last_sent if info is not None else None
        self.probes.append(probe)
        if initial:
            packet = await probe.next_packet(self.options.reply_timeout)
            if packet is None or packet.opcode != ServerOp.RESPONSE:
                if packet is not None:
                    probe.push_back(packet)
                raise CaseFailure(
                    Violation(
                        "no initial RESPONSE after the connection opened",
                        "connect.initial-response",
                        expected=f"a RESPONSE (200) within {self.options.reply_timeout:g} s of the open",
                        actual="nothing" if packet is None else describe(packet),
                        data=b"" if packet is None else packet.data,
                        kind="missing_response",
                        invariant=TRANSCRIPT.name,
                        packet=packet,
                    )
                )
            probe.initial = packet
        return probe

    async def close_all(self, wait: float = 1.0) -> None:
        """Close every connection of the case (:meth:`Probe.close`)."""
        for probe in self.probes:
            await probe.close(wait)

    # ------------------------------------------------------------------------------------- verdicts

    def _attribute(self, clause: str | None, invariant: str | None) -> str | None:
        """The invariant a report of ``clause`` counts under (None: the case's own); a clause the case
        does not declare, outside that invariant, is a bug of the suite and raises at once."""
        if self.clauses is None or clause is None or clause in self.clauses:
            return None
        problem = attribution_problem(self.case_id, self.clauses, clause, invariant)
        if problem is not None:
            raise UndeclaredClauseError(problem)
        return invariant

    def _clause_level(self, clause: str | None, level: Level | None) -> Level:
        if level is not None:
            return level
        if clause is not None:
            if clause not in SPEC.clauses:
                raise ValueError(f"unknown clause {clause!r}")
            return SPEC.clauses[clause].level
        return self.level

    def expect(
        self,
        condition: object,
        *,
        clause: str | None = None,
        expected: str = "",
        seen: object = None,
        message: str | None = None,
        level: Level | None = None,
        invariant: str | None = None,
    ) -> bool:
        """Check ``condition``; when false, a violation is recorded and the case goes on.

        ``seen`` is the evidence, in the one form of :mod:`~manip.conformance.judge.violation`: an
        answer, a packet, Cougar responses, a list of them, ``showing(answer, "text")`` in the case's own
        words, or ``missing("text")`` for a packet that never came.  The violation's text, bytes and
        packets are derived from it; evidence that names no packet (text alone) names the last packet
        of the case's recording, the one the check was reading (:meth:`judged`), so that every violation
        but a ``missing`` one carries its culprit.  The level is ``level`` if given, else the clause's,
        else the case's.  Returns ``bool(condition)``.  ``clause`` must be one the case declares, or one
        of ``invariant``'s when a suite invariant's violation is passed on: checked at every call, true or
        not (UndeclaredClauseError).  ``clause`` and ``expected`` are keywords so that the clause scan of
        ``tests/support/clause_scan.py`` sees every clause a case can report.

        A false check of any level is recorded and the case goes on, so that its report lists every
        violation; a check the rest of the case depends on is :meth:`require`.  Either way the clause
        counts as reached (:attr:`reached`)."""
        attributed = self._attribute(clause, invariant)
        self._reach(clause, attributed)
        if (
            level is not None
            and clause is not None
            and clause in SPEC.clauses
            and SPEC.clauses[clause].level != level
        ):
            raise CaseError(
                f"case {self.case_id} checks clause {clause} as {level}; the spec says "
                f"{SPEC.clauses[clause].level} (a weaker check needs a clause of its own)"
            )
        if condition:
            return True
        text = message or (f"expected {expected}" if expected else "check failed")
        self._report(
            self._violation(text, clause, self._clause_level(clause, level), expected, seen, attributed)
        )
        return False

    def _violation(
        self,
        message: str,
        clause: str | None,
        level: Level | None,
        expected: str,
        seen: object,
        invariant: str | None,
    ) -> Violation:
        """The violation a false check states, its evidence ``seen`` (see :meth:`expect`)."""
        actual, data = evidence(seen) if seen is not None else ("", b"")
        kind = seen_kind(seen)
        packets = seen_packets(seen) or (self.judged() if kind != "missing_response" else ())
        return Violation(message, clause, level, expected, actual, data, kind, invariant, packets=packets)

    # The common checks: the condition is theirs, the evidence the answer they judge.

    def expect_response(
        self, answer: Answer, *, clause: str, expected: str, size: int | None = None, min_size: int = 0
    ) -> bool:
        """``answer`` is a normal response (RESPONSE, 200), of exactly ``size`` data bytes when given and
        of at least ``min_size``."""
        data = len(answer.data)
        return self.expect(
            answer.is_response and (size is None or data == size) and data >= min_size,
            clause=clause,
            expected=expected,
            seen=answer,
        )

    def expect_done(self, answer: Answer, *, clause: str, expected: str) -> bool:
        """``answer`` is an empty done: a normal response carrying only the request number."""
        return self.expect_response(answer, clause=clause, expected=expected, size=DONE_SIZE)

    def expect_opcode(self, answer: Answer, opcode: int, *, clause: str, expected: str) -> bool:
        """``answer`` (its first packet) has ``opcode``."""
        return self.expect(answer.opcode == opcode, clause=clause, expected=expected, seen=answer)

    def expect_echo(self, answer: Answer, *, clause: str, expected: str) -> bool:
        """``answer`` quotes the number of the request it answers."""
        return self.expect(
            answer.number == answer.request.packet_no, clause=clause, expected=expected, seen=answer
        )

    def expect_finite(
        self, values: Sequence[float], count: int, *, clause: str, expected: str, seen: object
    ) -> bool:
        """``values`` are ``count`` finite floats (``seen``: the evidence, as for :meth:`expect`)."""
        whole = len(values) == count and all(math.isfinite(v) for v in values)
        return self.expect(whole, clause=clause, expected=expected, seen=seen)

    def expect_none(self, items: Sequence[object], *, clause: str, expected: str) -> bool:
        """Nothing came of what ``items`` collects (extra packets, responses): the evidence is ``items``."""
        return self.expect(not items, clause=clause, expected=expected, seen=items)

    def expect_near(
        self, value: float, wanted: float, tolerance: float, *, clause: str, expected: str, seen: object
    ) -> bool:
        """``value`` is within ``tolerance`` of ``wanted`` (``seen``: the evidence, as for :meth:`expect`)."""
        return self.expect(abs(value - wanted) <= tolerance, clause=clause, expected=expected, seen=seen)

    def _named(self, violation: Violation) -> Violation:
        """``violation`` naming a packet: one found elsewhere that names none (a checker's violation about a
        whole reply's text) names what :meth:`judged` names, unless it is about a packet that never came."""
        if violation.packets or violation.kind in NEVER_CAME:
            return violation
        return replace(violation, packets=self.judged())

    def judged(self) -> tuple[WirePacket, ...]:
        """What a check whose evidence names no packet judged: the last data packet of the case's
        recording (the reply it was reading); in a recording with none (a client's that never got as far
        as a request) its last Chaos control packet; nothing before any."""
        recorded = [p for p in reversed(self.shown_packets or self.transcript) if not p.is_close]
        return next(((p,) for p in recorded if carries_data(p)), tuple(recorded[:1]))

    def require(
        self,
        condition: object,
        *,
        clause: str | None = None,
        expected: str = "",
        seen: object = None,
        message: str | None = None,
    ) -> None:
        """:meth:`expect` for a check the rest of the case depends on: when false, the violation is
        recorded and the case stops there (whatever the clause's level)."""
        if not self.expect(condition, clause=clause, expected=expected, seen=seen, message=message):
            raise CaseFailure(self.recorded.pop())

    def _reach(self, clause: str | None, attributed: str | None) -> None:
        """A check of ``clause`` ran: mark it reached when it is one of the case's own."""
        if clause is not None and attributed is None and (self.clauses is None or clause in self.clauses):
            self.reached.add(clause)

    def exercised(self, *clauses: str) -> None:
        """Mark clauses as reached by a check the case made itself (a property's example, a step of
        the stateful model), for cases that judge without :meth:`expect`.  Clauses the case does not
        declare are ignored; callable from a worker thread."""
        declared = self.clauses
        self.reached.update(c for c in clauses if declared is None or c in declared)

    def _report(self, violation: Violation) -> None:
        """Record a violation; the case goes on (every violation is reported, not only the first)."""
        self.recorded.append(violation)

    def check(
        self, violations: Iterable[Violation], *, clauses: Iterable[str] | None = None, stop: bool = False
    ) -> bool:
        """Report a checker's violations, the strongest first; the case goes on.  True when there were
        none.  The checkers are the transcript invariant's: a violation of a clause the case does not
        declare is attributed to it.  ``clauses``: the clauses the checker evaluated, marked reached
        (default: the case's own clauses among those a checker run on one answer judges, which is an
        approximation; the runner's check of the whole recording passes none).  ``stop``: a MUST
        violation stops the case (what follows needs the answer well formed)."""
        items = sorted(violations, key=lambda v: -LEVEL_ORDER[v.strength])
        if clauses is None:
            clauses = (c for c in self.clauses or () if c in _CHECKER_CLAUSES)
        self.exercised(*clauses)
        stopping: Violation | None = None
        for item in items:
            attributed = self._attribute(item.clause, TRANSCRIPT.name)
            violation = self._named(replace(item, invariant=attributed))
            if stop and stopping is None and violation.level == "MUST":
                stopping = violation
            else:
                self._report(violation)
        if stopping is not None:
            raise CaseFailure(stopping)
        return not items

    def fail(
        self,
        message: str,
        *,
        clause: str | None = None,
        expected: str = "",
        seen: object = None,
        invariant: str | None = None,
    ) -> NoReturn:
        """Fail outright, the case stops; ``clause``, ``seen`` and ``invariant`` as for :meth:`expect`."""
        attributed = self._attribute(clause, invariant)
        self._reach(clause, attributed)
        raise CaseFailure(self._violation(message, clause, None, expected, seen, attributed))

    def fail_with(self, violation: Violation) -> NoReturn:
        """Fail with a violation found elsewhere (a failed example's); attributed as for :meth:`expect`."""
        attributed = self._attribute(violation.clause, violation.invariant)
        self._reach(violation.clause, attributed)
        raise CaseFailure(self._named(replace(violation, invariant=attributed)))

    def record(self, violation: Violation) -> None:
        """Record a violation found elsewhere (one of several a stateful run found) and go on;
        attributed as for :meth:`expect`."""
        attributed = self._attribute(violation.clause, violation.invariant)
        self._reach(violation.clause, attributed)
        self._report(self._named(replace(violation, invariant=attributed)))

    def skip(self, reason: str) -> NoReturn:
        raise CaseSkipped(reason)

    def not_judged(self, reason: str) -> NoReturn:
        """End the case ``not-judged``: it cannot judge its clauses on this target; ``reason`` says why
        and what would judge them (never a pass, never a skip)."""
        raise CaseNotJudged(reason)

    def arranged(self, condition: Condition) -> AbstractAsyncContextManager[None]:
        """``async with ctx.arranged(condition):`` the target's world holds ``condition`` in the block
        (connections that are to meet it open inside).  Without a world, or when the world cannot
        arrange it, the case ends ``not-judged`` saying what would judge it."""
        if self.world is None:
            return no_world(condition)
        return self._held(self.world, condition)

    @contextlib.asynccontextmanager
    async def _held(self, world: World, condition: Condition) -> AsyncIterator[None]:
        """The world's arrangement, the time it takes to arrange and to clear kept off the case's
        deadline (an operator may take minutes)."""
        manager = world.arranged(condition)
        async with self._off_deadline():
            await manager.__aenter__()
        self.note(f"arranged by {world.description}: {condition.describe()}")
        try:
            yield
        except BaseException as exc:
            async with self._off_deadline():
                if not await manager.__aexit__(type(exc), exc, exc.__traceback__):
                    raise
        else:
            async with self._off_deadline():
                await manager.__aexit__(None, None, None)

    @contextlib.asynccontextmanager
    async def _off_deadline(self) -> AsyncIterator[None]:
        """The block's time is not counted against the case's deadline."""
        scope = self.deadline_scope
        when = None if scope is None else scope.when()
        if scope is None or when is None:
            yield
            return
        start = self._clock()
        scope.reschedule(None)
        try:
            yield
        finally:
            scope.reschedule(when + (self._clock() - start))

    def require_hazard(self, hazard: Hazard) -> None:
        """Skip unless the run allows opcodes of ``hazard`` (for cases that decide at run time)."""
        if hazard not in self.options.allowed_hazards:
            self.skip(f"{hazard} requests are not allowed on {self.options.robot} without --allow-motion")


def _request_name(code: int) -> str:
    op = SPEC.requests.get(code)
    return op.name if op is not None else octal(code)


def _loop_clock() -> Callable[[], float]:
    """The running loop's clock (the one every deadline uses), or the monotonic clock outside a loop."""
    try:
        return asyncio.get_running_loop().time
    except RuntimeError:
        return time.monotonic
