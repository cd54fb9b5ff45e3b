"""``manip-conform replay FILE --serve URL``: play a recording's server side to a client under test.

Theory of operation
===================

:func:`turns_of` cuts a recorded session's server packets into *turns*: turn 0 is what the server sent
before the first request (the initial RESPONSE, and anything else it sent unasked), turn k the answer
to the k-th recorded request (sorted as :class:`~manip.conformance.replay.against.AnswerSorter` sorts them,
by order) followed by the asynchronous packets the recording shows after it, before the next request.
Recorded connections that never opened (refused as busy) are left out.  When the recorded server
closed the connection first (after a fatal error, say), the turn it closed
after is noted.

:func:`serve_capture` listens at the link address (``tcp://127.0.0.1:0``: a free port, reported through
``on_listening``) for the address's contact, one client at a time (others are refused as busy).  The
n-th connection accepted plays the n-th recorded session: it sends turn 0 at once, then for each
request the client sends, the turn of the recorded request at the same place, with every request-number
word rewritten from the recorded request (or RFC) number to the live one (mask ``packet-numbers`` of
:mod:`manip.conformance.replay.masking`).  Timing is not reproduced: a turn goes out as soon as its request
arrives.  Each client request is compared with the recorded one
(:func:`~manip.conformance.replay.masking.compare_request`: opcode, then decoded fields, floats with the
replay tolerance); a difference, a request beyond the recording, or a client that closes before sending
every recorded request, is a violation of that session's result ``replay.session-N.served``.

The run ends when every session was served, or after ``seconds``; sessions no client opened are
failures, and none opened at all is "unreachable" (exit 3).
"""

from __future__ import annotations

import asyncio
import os
import shlex
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Final

from manip.conformance.judge.checks import WirePacket, describe
from manip.conformance.judge.verdict import Outcome, grade
from manip.conformance.replay.against import AnswerSorter
from manip.conformance.replay.capture_report import capture_report, read_sessions
from manip.conformance.replay.masking import Mismatch, NumberMap, compare_request, masked
from manip.conformance.replay.verify import opened, rfc_number, session_hazard, wire_packets
from manip.conformance.suite.results import CaseResult, RunReport, Violation
from manip.links import ChaosConnection, ChaosError, start_server
from manip.links.api import LinkWrapper

__all__ = ["SERVE_CLAUSES", "ServeOptions", "ServedSession", "Turns", "serve_capture", "turns_of"]

SERVE_CLAUSES: Final = ("request.opcode-range", "request-data.types")
SESSION_DEADLINE: Final = 60.0
"""The nominal deadline a served session's result reports (the client sets the pace)."""


@dataclass
class Turns:
    """A recorded session's server side cut into turns (see the module docstring)."""

    requests: list[WirePacket]
    turns: list[list[WirePacket]]
    """``turns[0]``: sent at the open; ``turns[k]``: after the k-th request (1-based)."""
    rfc: int | None
    close_after: int | None
    """The recorded server closed after this turn (None: the client closed first)."""
    packets: list[WirePacket]


def turns_of(session_packets: Sequence[WirePacket], rfc: int | None) -> Turns:
    sorter = AnswerSorter(initial=rfc is not None)
    requests: list[WirePacket] = []
    turns: list[list[WirePacket]] = [[]]
    close_after: int | None = None
    client_closed = False
    for p in session_packets:
        if p.direction == "c2s":
            if p.is_close:
                client_closed = True
            elif not client_closed:
                requests.append(p)
                turns.append([])
                sorter.request(p)
            continue
        if p.is_close:
            if not client_closed and close_after is None:
                close_after = len(requests)
            continue
        index = sorter.completed
        answers_before = len(sorter.answers[index]) if index < len(sorter.answers) else -1
        sorter.server(p)
        answered = index < len(sorter.answers) and len(sorter.answers[index]) > answers_before
        # sorter index 0 is the RFC when the RFC was recorded: turn k is request k either way
        turn = index + (0 if rfc is not None else 1) if answered else len(requests)
        turns[min(turn, len(turns) - 1)].append(p)
    return Turns(requests, turns, rfc, close_after, list(session_packets))


def _renumbered(packet: WirePacket, numbers: NumberMap) -> bytes:
    data = packet.data
    if len(data) < 2:
        return data
    recorded = int.from_bytes(data[:2], "little")
    return numbers.expected(recorded).to_bytes(2, "little") + data[2:]


@dataclass(frozen=True)
class ServeOptions:
    seconds: float | None = None
    """Stop after this many seconds even if sessions are left (None: wait for every session)."""
    ignore: tuple[str, ...] = ()
    strict: bool = False
    sessions: tuple[int, ...] = ()
    wrap_link: LinkWrapper | None = None
    on_listening: Callable[[str], None] | None = None
    """Called with the real address once listening (port 0 replaced)."""


@dataclass
class ServedSession:
    number: int
    turns: Turns
    served: bool = False
    packets: list[WirePacket] = field(default_factory=list)
    mismatches: list[Mismatch] = field(default_factory=list)
    masked: int = 0
    notes: list[str] = field(default_factory=list)
    duration: float = 0.0


class _Player:
    def __init__(self, sessions: list[ServedSession], options: ServeOptions) -> None:
        self.sessions = sessions
        self.options = options
        self.next = 0
        self.done = asyncio.Event()
        if not sessions:
            self.done.set()

    async def handle(self, conn: ChaosConnection) -> None:
        if self.next >= len(self.sessions):
            conn.abort("every recorded session has been served")
            return
        served = self.sessions[self.next]
        self.next += 1
        served.served = True
        t0 = time.monotonic()
        try:
            await self._play(conn, served, t0)
        finally:
            served.duration = time.monotonic() - t0
            served.mismatches, served.masked = masked(served.mismatches, self.options.ignore)
            if self.next >= len(self.sessions):
                self.done.set()

    async def _play(self, conn: ChaosConnection, served: ServedSession, t0: float) -> None:
        turns = served.turns
        numbers = NumberMap()
        index = served.number - 1
        if turns.rfc is not None and conn.rfc is not None:
            numbers.add(turns.rfc, conn.rfc.packet_no)

        async def send_turn(k: int) -> None:
            for packet in turns.turns[k]:
                data = _renumbered(packet, numbers)
                number = await conn.send(data, packet.opcode)
                served.packets.append(
                    WirePacket("s2c", packet.opcode, number, 0, data, time.monotonic() - t0, index)
                )

        await send_turn(0)
        if turns.close_after == 0:
            await conn.close()
            return
        k = 0
        while True:
            try:
                packet = await conn.receive()
            except ChaosError as exc:
                if k < len(turns.requests):
                    served.mismatches.append(
                        Mismatch(
                            "requests",
                            f"the client ended the connection ({exc}) after {k} of the "
                            f"{len(turns.requests)} recorded requests",
                            f"{len(turns.requests)} requests",
                            f"{k} requests",
                        )
                    )
                return
            k += 1
            live = WirePacket(
                "c2s",
                packet.opcode,
                packet.packet_no,
                packet.ack_no,
                packet.data,
                time.monotonic() - t0,
                index,
            )
            served.packets.append(live)
            if k > len(turns.requests):
                served.mismatches.append(
                    Mismatch(
                        "requests",
                        f"request {k} ({describe(live)}) is beyond the recording (not answered)",
                        "no more requests",
                        describe(live),
                        b"",
                        live.data,
                    )
                )
                continue
            recorded = turns.requests[k - 1]
            for m in compare_request(recorded, live):
                served.mismatches.append(
                    Mismatch(
                        m.path,
                        f"request {k}: {m.message}",
                        m.recorded,
                        m.live,
                        m.recorded_bytes,
                        m.live_bytes,
                    )
                )
            numbers.add(recorded.packet_no, packet.packet_no)
            await send_turn(k)
            if turns.close_after == k:
                await conn.close()
                return


async def serve_capture(
    path: str | os.PathLike[str], address: str, options: ServeOptions | None = None, *, command: str = ""
) -> RunReport:
    """Serve the recorded sessions of the capture at ``address`` (see the module docstring)."""
    options = options or ServeOptions()
    t0 = time.monotonic()
    name = os.fspath(path)
    report = capture_report(
        address,
        embedded=False,
        strict=options.strict,
        options={
            "mode": "serve",
            "capture": name,
            "seconds": options.seconds,
            "ignore": list(options.ignore),
            "sessions": list(options.sessions),
        },
        command=command or shlex.join(["manip-conform", "replay", name, "--serve", address]),
    )
    chosen = [(n, s) for n, s in read_sessions(path, options.sessions, report) if opened(s)]
    sessions = [
        ServedSession(number, turns_of(wire_packets(s, number - 1), rfc_number(s))) for number, s in chosen
    ]
    if report.unreachable:
        report.duration = time.monotonic() - t0
        return report
    player = _Player(sessions, options)
    server = await start_server(address, None, player.handle, max_connections=1, wrap_link=options.wrap_link)
    try:
        report.target = str(server.address)
        if options.on_listening is not None:
            options.on_listening(report.target)
        try:
            async with asyncio.timeout(options.seconds):
                await player.done.wait()
                while server.connections:  # let the last session's close finish
                    await asyncio.sleep(0.02)
        except TimeoutError:
            report.problems.append(f"stopped after {options.seconds:g} s")
        except (asyncio.CancelledError, KeyboardInterrupt):
            report.interrupted = True
            report.problems.append("the replay was interrupted; this report is partial")
    finally:
        await server.aclose()
    if not any(s.served for s in sessions):
        report.unreachable = True
        report.problems.append("no client connected")
    reproduce = ["manip-conform", "replay", name, "--serve", address]
    report.results = [_result(s, name, reproduce, options.strict) for s in sessions]
    report.duration = time.monotonic() - t0
    return report


def _result(served: ServedSession, path: str, reproduce: Sequence[str], strict: bool) -> CaseResult:
    turns = served.turns
    result = CaseResult(
        id=f"replay.session-{served.number}.served",
        clauses=SERVE_CLAUSES,
        level="MUST",
        kind="replay",
        hazard=session_hazard(turns.packets),
        summary=f"session {served.number} of {os.path.basename(path)} served: "
        f"{len(turns.requests)} recorded request(s) compared with the client's",
        outcome=Outcome.PASS,
        seed=0,
        deadline=SESSION_DEADLINE,
        duration=served.duration,
        packets=served.packets,
        reproduce=shlex.join([*reproduce, "--session", str(served.number)]),
        notes=list(served.notes)
        + ([f"{served.masked} difference(s) left out by --ignore"] if served.masked else []),
    )
    if not served.served:
        result.violations.append(
            Violation(
                "no client opened this session",
                None,
                "MUST",
                f"a connection playing {len(turns.requests)} recorded request(s)",
                "no connection",
                kind="missing",
            )
        )
    for m in served.mismatches:
        result.violations.append(m.violation("request.opcode-range" if m.path == "opcode" else None))
    result.outcome = grade(result.outcome, result.violations, strict)
    return result
