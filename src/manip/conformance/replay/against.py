"""``manip-conform replay FILE --against URL``: send a recording's client side to a live server and
compare every answer with the recorded one.

Theory of operation
===================

**Sorting answers.**  :class:`AnswerSorter` (sans-I/O) is fed one connection's packets in order, the
requests sent and the server packets received, and sorts the server packets by the pairing rule the
checkers and the capture view use too (:mod:`manip.codecs.pairing`, erratum ``capture-pairing``):
answers (RESPONSE, 0201, 0202) belong to the oldest request not yet fully answered (the RFC first,
answered by the initial RESPONSE); a multi-packet reply stays open until its empty terminator or an
error (which answers the same request); asynchronous packets (0203-0205) form their own sequence; an
answer with no request outstanding, or after a fatal error, is an *extra*.  Matching by order rather
than by the request-number word keeps a wrong echo a *mismatch* instead of a lost answer.  The same sorter
reads the recording and the live connection, so both sides are cut into the same units.

**The script.**  :func:`script_of` sorts the recorded session and notes, before each recorded request,
how many requests had been fully answered and how many asynchronous packets had come (a *barrier*):
the recorded client had seen those before it sent the request.  The replay keeps that order and
nothing else of the timing: it sends each request as soon as the live server has reached the same
barrier (each answer within ``reply_timeout``, or the spec's ``answer_within`` for a request that waits
for the arm; asynchronous packets within ``async_timeout``), so a client that pipelined is replayed
pipelined and one that waited for a notification waits for it.

**A session.**  Each recorded session gets a fresh connection to the target (a refusal as busy is
retried briefly: the previous session's connection may still be closing).  Requests go out with their
recorded opcode and data; each live packet number is noted against the recorded one
(:class:`~manip.conformance.replay.masking.NumberMap`, the live RFC's too).  No answer within the timeout, or
the connection ending, stops the session (what was not sent is noted).  At the end the replay waits for
the server's close if the recorded server closed, else listens ``settle`` seconds for stray packets
and closes.

**Judging.**  Every recorded answer is compared with the live one by
:func:`~manip.conformance.replay.masking.compare_answer`, asynchronous packets pairwise in order by
:func:`~manip.conformance.replay.masking.compare_async`, extras and a missing or unexpected close are
mismatches too; the mask list is in :mod:`manip.conformance.replay.masking` (erratum ``replay-masking``).
Each session gives two results: ``replay.session-N.exchange`` (the mismatches, each with its field
path, the recorded value and bytes, the live value and bytes) and ``replay.session-N.checks`` (the live
transcript judged by the suite's checks, citing clauses).  Exit codes are the suite's: 0 every session
matched and conformed, 1 a mismatch or a failed check, 2 usage, 3 the capture unreadable or empty, or
the target unreachable before any session was compared, 4 internal error.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import shlex
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Final

from manip.captures import Session
from manip.codecs.pairing import ReplyPairing
from manip.conformance.judge.checks import WirePacket, check_transcript, describe
from manip.conformance.judge.verdict import Outcome, grade
from manip.conformance.replay.capture_report import capture_report, read_sessions
from manip.conformance.replay.masking import (
    Mismatch,
    NumberMap,
    SegmentBase,
    compare_answer,
    compare_async,
    masked,
)
from manip.conformance.replay.verify import (
    FAMILIES,
    judge_violations,
    opened,
    rfc_number,
    session_hazard,
    wire_packets,
)
from manip.conformance.suite.busy import open_retrying_busy
from manip.conformance.suite.context import DEFAULT_CONNECT_TIMEOUT, DEFAULT_REPLY_TIMEOUT
from manip.conformance.suite.results import CaseResult, RunReport, Violation
from manip.links import (
    ChaosConnection,
    ChaosError,
    ConnectionClosed,
    ConnectionLost,
    open_connection,
)
from manip.links.api import LinkWrapper
from manip.spec import SPEC
from manip.spec.constants import ChaosOp, ServerOp
from manip.spec.notation import octal

__all__ = [
    "DEFAULT_ASYNC_TIMEOUT",
    "DEFAULT_SETTLE",
    "AnswerSorter",
    "Barrier",
    "ReplayOptions",
    "ReplayScript",
    "SessionReplay",
    "replay_capture",
    "replay_session",
    "script_of",
]

DEFAULT_ASYNC_TIMEOUT: Final = 10.0
DEFAULT_SETTLE: Final = 0.2
CHECK_CLAUSES: Final = tuple(sorted({c for f in FAMILIES for c in f.clauses if c in SPEC.clauses}))
EXCHANGE_CLAUSES: Final = ("request.one-reply", "response.echoes-request-number")


# ------------------------------------------------------------------------------------- sorting


class AnswerSorter:
    """Sorts one connection's server packets into answers per request, asynchronous packets and
    extras, by the shared pairing rule (:class:`~manip.codecs.pairing.ReplyPairing`).  Index 0 is the
    RFC when ``initial`` (its answer: the initial RESPONSE)."""

    def __init__(self, initial: bool) -> None:
        self.requests: list[WirePacket | None] = [None] if initial else []
        self.answers: list[list[WirePacket]] = [[] for _ in self.requests]
        self.asyncs: list[WirePacket] = []
        self.extras: list[WirePacket] = []
        self.closed: WirePacket | None = None
        self._pairing: ReplyPairing[int] = ReplyPairing()
        if initial:
            self._pairing.rfc(0)

    @property
    def completed(self) -> int:
        """How many requests (from the first) are fully answered."""
        return self._pairing.completed

    def request(self, packet: WirePacket) -> int:
        index = len(self.requests)
        self.requests.append(packet)
        self.answers.append([])
        self._pairing.request(index, packet.opcode, packet.data)
        return index

    def server(self, packet: WirePacket) -> None:
        if packet.is_close:
            if self.closed is None:
                self.closed = packet
                self._pairing.close()
            return
        place = self._pairing.server(packet.opcode, packet.data)
        if place.role == "async":
            self.asyncs.append(packet)
        elif place.request is not None:
            self.answers[place.request].append(packet)
        else:
            self.extras.append(packet)

    @property
    def outstanding(self) -> int:
        return len(self.requests) - self.completed


# ------------------------------------------------------------------------------------- the script


@dataclass(frozen=True)
class Barrier:
    """What the recorded client had seen: ``answers`` requests fully answered, ``asyncs`` asynchronous
    packets."""

    answers: int
    asyncs: int


@dataclass
class ReplayScript:
    """One recorded session, ready to replay."""

    number: int
    session: Session
    packets: list[WirePacket]
    recorded: AnswerSorter
    sends: list[tuple[WirePacket, Barrier]]
    end: Barrier
    rfc: int | None
    server_closes: bool
    """The recorded server ended the connection before the client did (after a fatal error, say)."""


def script_of(session: Session, number: int = 1) -> ReplayScript:
    """The replay script of a recorded session (see the module docstring)."""
    packets = wire_packets(session, number - 1)
    rfc = rfc_number(session)
    recorded = AnswerSorter(initial=rfc is not None)
    sends: list[tuple[WirePacket, Barrier]] = []
    server_closes = False
    client_closed = False
    for p in packets:
        if p.direction == "c2s":
            if p.is_close:
                client_closed = True
            elif not client_closed:
                sends.append((p, Barrier(recorded.completed, len(recorded.asyncs))))
                recorded.request(p)
        else:
            if p.is_close and not client_closed and recorded.closed is None:
                server_closes = True
            recorded.server(p)
    end = Barrier(recorded.completed, len(recorded.asyncs))
    return ReplayScript(number, session, packets, recorded, sends, end, rfc, server_closes)


# ------------------------------------------------------------------------------------- options


@dataclass(frozen=True)
class ReplayOptions:
    reply_timeout: float = DEFAULT_REPLY_TIMEOUT
    """Seconds to wait for the live answers a barrier needs."""
    async_timeout: float = DEFAULT_ASYNC_TIMEOUT
    """Seconds to wait for the live asynchronous packets a barrier needs (motions take time)."""
    connect_timeout: float = DEFAULT_CONNECT_TIMEOUT
    settle: float = DEFAULT_SETTLE
    """Seconds of quiet listened for at the end of a session (stray or extra packets)."""
    ignore: tuple[str, ...] = ()
    """Mismatch paths to leave out (fnmatch globs: ``error.message``, ``describe.*``)."""
    strict: bool = False
    sessions: tuple[int, ...] = ()
    """1-based numbers of the sessions to replay (all when empty)."""
    wrap_link: LinkWrapper | None = None
    paced: bool = False
    """Open each session, send each request and end each session at its recorded time on the loop's
    clock (a simulated run's capture replayed in virtual time: same instants, same server states)."""
    clock_offset_ns: int = 0
    """What to take off a recorded log time to get the loop's clock at that instant (a simulated run's
    capture is written anchored at its wall-clock start; metadata ``wall_origin_ns`` less
    ``virtual_origin_ns``)."""
    """Put between the node and its link (``RecorderTap(recorder, "client").wrap`` records the replay)."""


# ------------------------------------------------------------------------------------- one session


@dataclass
class SessionReplay:
    """What replaying one session gave."""

    script: ReplayScript
    live: AnswerSorter
    packets: list[WirePacket] = field(default_factory=list)
    numbers: NumberMap = field(default_factory=NumberMap)
    live_rfc: int | None = None
    sent: int = 0
    mismatches: list[Mismatch] = field(default_factory=list)
    masked: int = 0
    notes: list[str] = field(default_factory=list)
    stopped: str = ""
    """Why the session stopped before its end ("" when it ran to the end)."""
    connected: bool = False
    duration: float = 0.0


class _Live:
    """The live connection's receiving side: packets recorded and sorted as they come."""

    def __init__(self, conn: ChaosConnection, replay: SessionReplay, t0: float) -> None:
        self.conn = conn
        self.replay = replay
        self.t0 = t0

    def record(self, direction: str, opcode: int, number: int, ack: int, data: bytes) -> WirePacket:
        packet = WirePacket(
            "c2s" if direction == "c2s" else "s2c",
            opcode,
            number,
            ack,
            bytes(data),
            time.monotonic() - self.t0,
            self.replay.script.number - 1,
        )
        self.replay.packets.append(packet)
        return packet

    async def take(self, timeout: float) -> bool:
        """Receive one packet within ``timeout``; False on timeout or once the connection has ended."""
        live = self.replay.live
        if live.closed is not None:
            return False
        try:
            async with asyncio.timeout(max(0.0, timeout)):
                packet = await self.conn.receive()
        except TimeoutError:
            return False
        except ChaosError as exc:
            kind = ChaosOp.LOS if isinstance(exc, ConnectionLost) else ChaosOp.CLS
            if isinstance(exc, ConnectionClosed) and exc.reason == "EOF":
                kind = ChaosOp.EOF
            live.server(self.record("s2c", kind, 0, 0, str(exc).encode("ascii", "replace")))
            return False
        live.server(self.record("s2c", packet.opcode, packet.packet_no, packet.ack_no, packet.data))
        return True

    async def reach(self, barrier: Barrier, options: ReplayOptions) -> str:
        """Wait until the live side has reached ``barrier``; "" or what is missing."""
        live = self.replay.live
        loop = asyncio.get_running_loop()
        while live.completed < barrier.answers:
            waiting = live.completed
            allowed = _answer_time(live.requests[waiting], options)
            deadline = loop.time() + allowed
            while live.completed == waiting:
                if not await self.take(deadline - loop.time()):
                    if live.closed is not None:
                        return f"the connection ended ({describe(live.closed)}) before the answer came"
                    return f"no answer within {allowed:g} s"
        deadline = loop.time() + options.async_timeout
        while len(live.asyncs) < barrier.asyncs:
            if not await self.take(deadline - loop.time()):
                if live.closed is not None:
                    return (
                        f"the connection ended ({describe(live.closed)}) before the asynchronous packet came"
                    )
                wanted = len(live.asyncs) + 1
                return f"asynchronous packet {wanted} did not come within {options.async_timeout:g} s"
        return ""

    async def quiet(self, seconds: float) -> None:
        """Take whatever arrives until ``seconds`` pass without a packet."""
        while await self.take(seconds):
            pass

    async def quiet_until(self, t_ns: int) -> None:
        """Take whatever arrives until the loop's clock reads ``t_ns``."""
        loop = asyncio.get_running_loop()
        while await self.take(t_ns / 1e9 - loop.time()):
            pass


async def _until(t_ns: int) -> None:
    """Sleep until the loop's clock reads ``t_ns`` (a recorded log time, paced replay)."""
    await asyncio.sleep(max(0.0, t_ns / 1e9 - asyncio.get_running_loop().time()))


def _answer_time(request: WirePacket | None, options: ReplayOptions) -> float:
    """Seconds to wait for the answer to ``request``: the reply timeout, or longer for a request whose
    answer waits for the arm (the spec's ``answer_within``, e.g. calibrate-wrist)."""
    op = SPEC.requests.get(request.opcode) if request is not None else None
    return options.reply_timeout if op is None else op.answer_time(options.reply_timeout)


async def _connect(address: str, options: ReplayOptions) -> ChaosConnection:
    return await open_retrying_busy(
        lambda: open_connection(address, timeout=options.connect_timeout, wrap_link=options.wrap_link)
    )


async def replay_session(script: ReplayScript, address: str, options: ReplayOptions) -> SessionReplay:
    """Replay one recorded session against the server at ``address`` and compare (never raises a
    ChaosError: a failure to connect is ``stopped``)."""
    replay = SessionReplay(script, AnswerSorter(initial=script.rfc is not None))
    if options.paced:
        await _until(script.session.start_ns - options.clock_offset_ns)
    t0 = time.monotonic()
    try:
        conn = await _connect(address, options)
    except (ChaosError, OSError) as exc:
        replay.stopped = f"could not connect: {type(exc).__name__}: {exc}"
        replay.duration = time.monotonic() - t0
        return replay
    replay.connected = True
    live = _Live(conn, replay, t0)
    info = conn.info()
    replay.live_rfc = info.last_sent if info is not None else None
    if script.rfc is not None and replay.live_rfc is not None:
        replay.numbers.add(script.rfc, replay.live_rfc)
    try:
        await _play(script, live, options)
    finally:
        ours = replay.live.closed is None
        with contextlib.suppress(ChaosError):
            await conn.close(timeout=1.0)  # also closes the node and link (after the peer's end: only them)
        if ours:
            live.record("c2s", ChaosOp.EOF, 0, 0, b"closed by the replay")
    replay.duration = time.monotonic() - t0
    _judge(replay, options)
    return replay


async def _play(script: ReplayScript, live: _Live, options: ReplayOptions) -> None:
    replay = live.replay
    for packet, barrier in script.sends:
        missing = await live.reach(barrier, options)
        closed = replay.live.closed
        if closed is not None or replay.live.completed < barrier.answers:
            replay.stopped = missing or f"the connection ended ({describe(closed)})" if closed else missing
            break
        if missing:
            replay.notes.append(f"before request {replay.sent + 1}: {missing}")
        if options.paced:
            await _until(script.session.start_ns - options.clock_offset_ns + round(packet.time * 1e9))
        try:
            number = await live.conn.send(packet.data, packet.opcode)
        except ChaosError as exc:
            replay.stopped = f"sending request {replay.sent + 1} failed: {exc}"
            break
        replay.numbers.add(packet.packet_no, number)
        replay.live.request(live.record("c2s", packet.opcode, number, 0, packet.data))
        replay.sent += 1
    else:
        missing = await live.reach(script.end, options)
        if missing:
            replay.notes.append(f"at the end of the session: {missing}")
        if script.server_closes:
            loop = asyncio.get_running_loop()
            deadline = loop.time() + options.reply_timeout
            while replay.live.closed is None and await live.take(deadline - loop.time()):
                pass
        elif options.paced:
            end = script.session.start_ns - options.clock_offset_ns + round(script.packets[-1].time * 1e9)
            await live.quiet_until(end)
        else:
            await live.quiet(options.settle)
    if replay.stopped:
        left = len(script.sends) - replay.sent
        replay.notes.append(f"stopped: {replay.stopped}; {left} recorded request(s) not sent")


# ------------------------------------------------------------------------------------- judging


def _judge(replay: SessionReplay, options: ReplayOptions) -> None:
    script, live = replay.script, replay.live
    recorded = script.recorded
    segments = SegmentBase()
    out: list[Mismatch] = []
    for i, request in enumerate(live.requests):
        where = _request_name(i, request)
        rec_answer = recorded.answers[i] if i < len(recorded.answers) else []
        opcode = None if request is None else request.opcode
        for m in compare_answer(opcode, rec_answer, live.answers[i], replay.numbers, segments):
            out.append(_located(m, where))
    compared = max(len(recorded.asyncs), len(live.asyncs))
    if replay.stopped:  # asynchronous packets the stop kept from coming are not mismatches
        compared = len(live.asyncs)
    for j in range(compared):
        where = f"asynchronous packet {j + 1}"
        if j >= len(live.asyncs):
            r = recorded.asyncs[j]
            out.append(
                Mismatch("async", f"{where}: recorded {describe(r)}, none came", describe(r), "none", r.data)
            )
        elif j >= len(recorded.asyncs):
            v = live.asyncs[j]
            message = f"{where}: not in the recording, live {describe(v)}"
            out.append(Mismatch("async", message, "none", describe(v), b"", v.data))
        else:
            for m in compare_async(recorded.asyncs[j], live.asyncs[j], replay.numbers, segments):
                out.append(_located(m, where))
    for extra in live.extras:
        out.append(
            Mismatch(
                "extra",
                f"an answer to no outstanding request: {describe(extra)}",
                "nothing",
                describe(extra),
                b"",
                extra.data,
                "request.one-reply",
            )
        )
    out += _close_mismatches(replay)
    replay.mismatches, replay.masked = masked(out, options.ignore)


def _close_mismatches(replay: SessionReplay) -> list[Mismatch]:
    script, live = replay.script, replay.live
    if replay.stopped and live.closed is None:
        return []
    fatal = any(p.opcode == ServerOp.FATAL_ERROR for p in script.packets if p.direction == "s2c")
    clause = "error.fatal-then-close" if fatal else None
    if script.server_closes and live.closed is None:
        return [
            Mismatch(
                "close",
                "close: the recorded server closed the connection, the live one did not",
                "the server closes",
                "still open",
                b"",
                b"",
                clause,
            )
        ]
    if not script.server_closes and live.closed is not None:
        return [
            Mismatch(
                "close",
                f"close: the live server ended the connection ({describe(live.closed)})",
                "open until the client closes",
                describe(live.closed),
                b"",
                live.closed.data,
            )
        ]
    return []


def _request_name(index: int, request: WirePacket | None) -> str:
    if request is None:
        return "initial RESPONSE"
    op = SPEC.requests.get(request.opcode)
    name = op.name if op is not None else f"opcode {octal(request.opcode)}"
    return f"request {index} ({name}, recorded #{request.packet_no})"


def _located(m: Mismatch, where: str) -> Mismatch:
    return Mismatch(
        m.path, f"{where}: {m.message}", m.recorded, m.live, m.recorded_bytes, m.live_bytes, m.clause
    )


# ------------------------------------------------------------------------------------- results


def _results(replay: SessionReplay, path: str, reproduce: Sequence[str], strict: bool) -> list[CaseResult]:
    script = replay.script
    number = script.number
    hazard = session_hazard(script.packets)
    deadline = 2 * (len(script.sends) + 1) * DEFAULT_REPLY_TIMEOUT + script.end.asyncs * DEFAULT_ASYNC_TIMEOUT
    command = shlex.join([*reproduce, "--session", str(number)])
    exchange = CaseResult(
        id=f"replay.session-{number}.exchange",
        clauses=tuple(sorted({*EXCHANGE_CLAUSES, *(m.clause for m in replay.mismatches if m.clause)})),
        level="MUST",
        kind="replay",
        hazard=hazard,
        summary=f"session {number} of {os.path.basename(path)}: {len(script.sends)} request(s) replayed, "
        "every answer compared with the recording",
        outcome=Outcome.PASS,
        seed=0,
        deadline=deadline,
        duration=replay.duration,
        packets=replay.packets,
        reproduce=command,
        notes=list(replay.notes)
        + ([f"{replay.masked} mismatch(es) left out by --ignore"] if replay.masked else []),
    )
    exchange.violations += [m.violation(m.clause) for m in replay.mismatches]
    if replay.stopped and not replay.mismatches:
        exchange.violations.append(
            Violation(
                f"the replay stopped: {replay.stopped}",
                "request.one-reply",
                "MUST",
                "every recorded request replayed",
                replay.stopped,
                b"",
                "stopped",
            )
        )
    exchange.outcome = grade(exchange.outcome, exchange.violations, strict)
    checks = CaseResult(
        id=f"replay.session-{number}.checks",
        clauses=CHECK_CLAUSES,
        level="MUST",
        kind="replay",
        hazard=hazard,
        summary=f"session {number}: the live transcript judged by the suite's checks",
        outcome=Outcome.PASS,
        seed=0,
        deadline=deadline,
        duration=0.0,
        packets=replay.packets,
        reproduce=command,
    )
    if replay.connected:
        violations = check_transcript(
            replay.packets,
            rfc_packet_no=replay.live_rfc,
            expect_initial=script.rfc is not None,
            complete=not replay.stopped,
        )
        judge_violations(checks, violations, strict=strict)
    else:
        checks.outcome = Outcome.SKIP
        checks.reason = replay.stopped
    return [exchange, checks]


def _refused(number: int, session: Session, path: str) -> CaseResult:
    """A recorded connection that never opened (refused as busy, say): nothing to replay."""
    return CaseResult(
        id=f"replay.session-{number}.exchange",
        clauses=EXCHANGE_CLAUSES,
        level="MUST",
        kind="replay",
        hazard="read-only",
        summary=f"session {number} of {os.path.basename(path)}",
        outcome=Outcome.SKIP,
        seed=0,
        deadline=DEFAULT_REPLY_TIMEOUT,
        reason="the recorded connection never opened (refused): not replayed",
        packets=wire_packets(session, number - 1),
    )


async def replay_capture(
    path: str | os.PathLike[str],
    address: str,
    options: ReplayOptions | None = None,
    *,
    embedded: bool = False,
    command: str = "",
    reproduce: Sequence[str] | None = None,
) -> RunReport:
    """Replay every session of the capture (or ``options.sessions``) against ``address``, in order."""
    options = options or ReplayOptions()
    t0 = time.monotonic()
    name = os.fspath(path)
    report = capture_report(
        address,
        embedded=embedded,
        strict=options.strict,
        options={
            "mode": "replay",
            "capture": name,
            "reply_timeout": options.reply_timeout,
            "async_timeout": options.async_timeout,
            "settle": options.settle,
            "ignore": list(options.ignore),
            "sessions": list(options.sessions),
        },
        command=command or shlex.join(["manip-conform", "replay", name, "--against", address]),
    )
    chosen = read_sessions(path, options.sessions, report)
    if report.unreachable:
        report.duration = time.monotonic() - t0
        return report
    words = (
        list(reproduce) if reproduce is not None else ["manip-conform", "replay", name, "--against", address]
    )
    try:
        for number, session in chosen:
            if not opened(session):
                report.results.append(_refused(number, session, name))
                continue
            replay = await replay_session(script_of(session, number), address, options)
            if not replay.connected and not report.results:
                report.unreachable = True
                report.problems.append(f"the target {address} is unreachable: {replay.stopped}")
                break
            report.results += _results(replay, name, words, options.strict)
    except (asyncio.CancelledError, KeyboardInterrupt):
        report.interrupted = True
        report.problems.append("the replay was interrupted; this report is partial")
    report.duration = time.monotonic() - t0
    return report
