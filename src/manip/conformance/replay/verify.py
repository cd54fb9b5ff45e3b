"""``manip-conform verify FILE``: judge a recording offline with the suite's checks.

Theory of operation
===================

A capture (:mod:`manip.captures`) holds every packet of one or more sessions, whoever recorded them (a
client tap, a server tap, the recording proxy).  :func:`wire_packets` turns a session's packets into the
:class:`~manip.conformance.judge.checks.WirePacket` sequence the live cases record: data packets (0200 and up)
both ways, in order, first copies only (retransmissions left out), and the ends (CLS, EOF, LOS) as
close pseudo-packets.  :func:`judge_session` runs :func:`~manip.conformance.judge.checks.check_transcript`
over it (the RFC's packet number for the initial RESPONSE when the RFC was recorded; ``complete`` when
the recording holds the session's end), plus one check the transcript checker cannot make from a
connection it watched live: after a fatal error the *server* must close, so a recording in which the
client closed first is a failure of ``error.fatal-then-close``.

The violations are sorted into :data:`FAMILIES` (initial response, request numbers, one reply per
request, reply shapes, refusals, error strings, asynchronous responses, describe-self, segments, fatal
close, free joint); each family of each session is one result ``verify.session-N.FAMILY`` of the
suite's report, with its clauses and level: ``pass``, ``fail`` (a MUST clause broke; a SHOULD one too
with ``--strict``), ``warn``, or ``skip`` when the recording does not exercise it.  That judges the
server.  ``--judge client`` judges the client instead (:data:`CLIENT_FAMILIES`: every request a request
opcode, its data laid out as the opcode's layout says), ``--judge both`` both sides; a recording of the
suite itself is no client to judge, as it sends malformed requests on purpose.  The report and the
exit codes are the suite's (erratum ``verify-exit-codes``): 0 conformant, 1 not, 2 usage, 3 the
capture cannot be read (damaged, truncated: ``manip-capture recover`` first) or holds no session,
4 internal error.  A result's ``deadline`` is a nominal second (offline checks have no deadline).
"""

from __future__ import annotations

import os
import shlex
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Final, Literal

from manip.captures import Session
from manip.conformance.judge.checks import (
    CLOSE_OPCODES,
    WirePacket,
    check_transcript,
    describe,
    required_refusal,
)
from manip.conformance.judge.client_checks import check_client_guards, check_client_request
from manip.conformance.judge.verdict import Outcome, grade, strongest_first
from manip.conformance.replay.capture_report import capture_report, open_capture, select_sessions
from manip.conformance.suite.case import LEVEL_ORDER
from manip.conformance.suite.results import CaseResult, RunReport, Violation
from manip.spec import SPEC, RequestName
from manip.spec.constants import ERROR_STRING_OPS, ChaosOp, ServerOp
from manip.spec.model import HAZARDS, Hazard, Level

__all__ = [
    "CLIENT_FAMILIES",
    "FAMILIES",
    "JUDGE_FAMILIES",
    "VERIFY_DEADLINE",
    "Family",
    "Judge",
    "family_of",
    "fatal_close_violations",
    "judge_session",
    "judge_violations",
    "opened",
    "rfc_number",
    "select_sessions",
    "session_hazard",
    "verify_capture",
    "wire_packets",
]

VERIFY_DEADLINE: Final = 1.0


def wire_packets(session: Session, connection: int = 0) -> list[WirePacket]:
    """The session as the checkers see it (see the module docstring); times from its first packet."""
    t0 = session.start_ns
    out: list[WirePacket] = []
    for p in session.packets:
        packet = p.packet
        if packet is None or p.retransmission:
            continue
        op = packet.opcode
        if op >= ChaosOp.DAT or op in CLOSE_OPCODES:
            data = packet.data
            if op in CLOSE_OPCODES and p.annotation.text is not None:
                data = p.annotation.text.encode("ascii", "replace")
            out.append(
                WirePacket(
                    p.direction,
                    op,
                    packet.packet_no,
                    packet.ack_no,
                    bytes(data),
                    (p.time_ns - t0) / 1e9,
                    connection,
                )
            )
    return out


def opened(session: Session) -> bool:
    """Whether the connection opened (False: refused, busy say, or the recording starts after it)."""
    return any(e.event == "open" for e in session.events)


def rfc_number(session: Session) -> int | None:
    """The recorded RFC's packet number (None when the recording starts after it, or the connection
    was refused: then there is no initial RESPONSE to expect)."""
    if not opened(session):
        return None
    for p in session.packets:
        if p.packet is not None and p.packet.opcode == ChaosOp.RFC and p.direction == "c2s":
            return p.packet.packet_no
    return None


@dataclass(frozen=True)
class Family:
    """A group of related clauses judged together; ``exercised`` says whether a session tests them."""

    name: str
    summary: str
    clauses: tuple[str, ...]
    exercised: Callable[[Sequence[WirePacket], bool], bool]


def _requests(packets: Sequence[WirePacket]) -> list[WirePacket]:
    return [p for p in packets if p.direction == "c2s" and not p.is_close]


def _server(packets: Sequence[WirePacket], opcodes: Iterable[int]) -> bool:
    wanted = frozenset(opcodes)
    return any(p.direction == "s2c" and p.opcode in wanted for p in packets)


def _asks(kind: str) -> Callable[[Sequence[WirePacket], bool], bool]:
    def exercised(packets: Sequence[WirePacket], _initial: bool) -> bool:
        return any(
            (op := SPEC.requests.get(p.opcode)) is not None and op.response.form == kind
            for p in _requests(packets)
        )

    return exercised


def _asks_op(name: RequestName) -> Callable[[Sequence[WirePacket], bool], bool]:
    opcode = SPEC.request(name).opcode
    return lambda packets, _initial: any(p.opcode == opcode for p in _requests(packets))


def _asks_any(*names: RequestName) -> Callable[[Sequence[WirePacket], bool], bool]:
    opcodes = {SPEC.request(name).opcode for name in names}
    return lambda packets, _initial: any(p.opcode in opcodes for p in _requests(packets))


FAMILIES: Final[tuple[Family, ...]] = (
    Family(
        "initial-response",
        "the initial RESPONSE quotes the RFC's packet number",
        ("connect.initial-response", "connect.initial-response-number"),
        lambda _packets, initial: initial,
    ),
    Family(
        "request-numbers",
        "every answer echoes its request's packet number",
        ("response.echoes-request-number", "error.fatal-request-number", "multi.same-request-number"),
        lambda packets, _initial: bool(_requests(packets)),
    ),
    Family(
        "one-reply",
        "exactly one answer per request, in order",
        ("request.one-reply", "error.non-fatal-is-reply"),
        lambda packets, _initial: bool(_requests(packets)),
    ),
    Family(
        "reply-shapes",
        "server opcodes and reply layouts by the request's response form",
        ("response.server-opcodes", "response.done-empty", "response.segment-number", "response.data-layout"),
        lambda packets, _initial: bool(_requests(packets)),
    ),
    Family(
        "refusals",
        "malformed requests are refused with a command error",
        ("request.unknown-opcode", "request.data-length", "request.reserved-float"),
        lambda packets, _initial: any(required_refusal(p.opcode, p.data) for p in _requests(packets)),
    ),
    Family(
        "error-strings",
        "error strings: where, severity letter, code, substitutions",
        (
            "error-string.format",
            "error-string.where-no-colon",
            "error-string.severity",
            "error-string.code",
            "error-string.substitution",
            "error-string.arg-layout",
            "error.severity-matches-opcode",
        ),
        lambda packets, _initial: _server(packets, ERROR_STRING_OPS),
    ),
    Family(
        "async",
        "asynchronous responses: layout, codes, only when asked for",
        ("async.layout", "async.codes", "async.only-when-requested"),
        lambda packets, _initial: _server(packets, (ServerOp.ASYNCHRONOUS_RESPONSE,)),
    ),
    Family(
        "describe",
        "the describe-self reply: packets, terminator, alist",
        (
            "describe.reply-shape",
            "multi.terminated-by-empty",
            "describe.alist-readable",
            "describe.protocol-version",
            "describe.brand-name",
            "describe.unique-name",
            "describe.degrees-of-freedom",
            "describe.operations",
            "describe.software-version",
        ),
        _asks("multi"),
    ),
    Family(
        "segments",
        "segment numbers increase by one",
        ("segment.number-increases",),
        _asks("segment"),
    ),
    Family(
        "fatal-close",
        "the server closes after a fatal error",
        ("error.fatal-then-close",),
        lambda packets, _initial: _server(packets, (ServerOp.FATAL_ERROR,)),
    ),
    Family(
        "free-joint",
        "the packet after free joint is discarded and answered with done",
        ("free-joint.replies",),
        _asks_op("free-joint"),
    ),
)
CLIENT_FAMILIES: Final[tuple[Family, ...]] = (
    Family(
        "client-requests",
        "requests as the client built them: request opcodes, data by the opcode's layout",
        ("request.opcode-range", "request-data.types", "move.transform-data"),
        lambda packets, _initial: bool(_requests(packets)),
    ),
    Family(
        "client-guards",
        "guards numbered with free guards; the gravity model kept up to date and left alone under a guard",
        ("client.guard-numbers", "client.no-newwc-with-guard", "client.newwc-on-load"),
        _asks_any("set-guard", "set-frame-vector", "set-weight"),
    ),
)
"""What ``--judge client`` reports: the client's side of each session."""
Judge = Literal["server", "client", "both"]
JUDGE_FAMILIES: Final[Mapping[str, tuple[Family, ...]]] = {
    "server": FAMILIES,
    "client": CLIENT_FAMILIES,
    "both": FAMILIES + CLIENT_FAMILIES,
}
_BY_CLAUSE: Final = {clause: f for f in FAMILIES + CLIENT_FAMILIES for clause in f.clauses}
_PREFIX_FAMILY: Final = {
    "connect": "initial-response",
    "error-string": "error-strings",
    "async": "async",
    "describe": "describe",
    "multi": "describe",
    "segment": "segments",
    "free-joint": "free-joint",
    "request": "refusals",
}


def family_of(clause: str | None) -> Family:
    """The family a violation's clause belongs to (codec clauses by their area; the rest, and a violation
    without a clause: reply shapes)."""
    if clause in _BY_CLAUSE:
        return _BY_CLAUSE[clause]
    name = _PREFIX_FAMILY.get((clause or "").split(".", 1)[0], "reply-shapes")
    return next(f for f in FAMILIES if f.name == name)


def fatal_close_violations(packets: Sequence[WirePacket]) -> list[Violation]:
    """After a fatal error the first close must be the server's (a recording shows who closed first)."""
    fatal: WirePacket | None = None
    for p in packets:
        if fatal is None:
            if p.direction == "s2c" and p.opcode == ServerOp.FATAL_ERROR:
                fatal = p
            continue
        if p.is_close:
            if p.direction == "c2s":
                return [
                    Violation(
                        "the client closed the connection first after the fatal error",
                        "error.fatal-then-close",
                        expected="CLS from the server after the fatal error",
                        actual=f"the client's {describe(p)} first",
                        data=fatal.data,
                        packet=fatal,
                    )
                ]
            return []
    return []


def judge_session(session: Session, connection: int = 0) -> tuple[list[WirePacket], list[Violation]]:
    """The session's packets and every violation about them (the server's and the client's)."""
    packets = wire_packets(session, connection)
    rfc = rfc_number(session)
    complete = any(p.is_close for p in packets)
    violations = check_transcript(
        packets, rfc_packet_no=rfc, expect_initial=rfc is not None, complete=complete
    )
    if not any(f.clause == "error.fatal-then-close" for f in violations):
        violations += fatal_close_violations(packets)
    for request in _requests(packets):
        violations += check_client_request(request)
    violations += check_client_guards(packets)
    return packets, violations


def session_hazard(packets: Sequence[WirePacket]) -> Hazard:
    """The highest hazard class among the session's request opcodes."""
    levels = [HAZARDS.index(op.hazard) for p in _requests(packets) if (op := SPEC.requests.get(p.opcode))]
    return HAZARDS[max(levels, default=0)]


def judge_violations(result: CaseResult, violations: Iterable[Violation], *, strict: bool) -> None:
    """Record ``violations`` as the result's violations (the strongest first) and grade its outcome."""
    result.violations.extend(strongest_first(violations))
    result.outcome = grade(result.outcome, result.violations, strict)


def _family_level(family: Family) -> Level:
    levels = [SPEC.clauses[c].level for c in family.clauses if c in SPEC.clauses]
    return max(levels, key=lambda lv: LEVEL_ORDER[lv], default="MUST")


def verify_capture(
    path: str | os.PathLike[str],
    *,
    strict: bool = False,
    sessions: Sequence[int] = (),
    command: str = "",
    judge: Judge = "server",
) -> RunReport:
    """Judge every session of the capture (or those numbered in ``sessions``, 1-based): the server's
    side, the client's (``judge="client"``) or both.

    An unreadable capture, or one without the sessions asked for, gives a report with ``unreachable``
    set (exit 3) and the reason in ``problems``."""
    t0 = time.monotonic()
    report = capture_report(
        os.fspath(path),
        embedded=False,
        strict=strict,
        options={"mode": "verify", "capture": os.fspath(path), "sessions": list(sessions), "judge": judge},
        command=command or shlex.join(["manip-conform", "verify", os.fspath(path)]),
    )
    capture = open_capture(path, report)
    chosen = [] if capture is None else select_sessions(capture.sessions, sessions, report)
    if capture is None or report.unreachable:
        report.duration = time.monotonic() - t0
        return report
    families = JUDGE_FAMILIES[judge]
    for number, session in chosen:
        start = time.monotonic()
        packets, violations = judge_session(session, connection=number - 1)
        initial = rfc_number(session) is not None
        by_family: dict[str, list[Violation]] = {}
        for f in violations:
            by_family.setdefault(family_of(f.clause).name, []).append(f)
        hazard = session_hazard(packets)
        elapsed = (time.monotonic() - start) / len(families)
        for family in families:
            result = CaseResult(
                id=f"verify.session-{number}.{family.name}",
                clauses=tuple(c for c in family.clauses if c in SPEC.clauses),
                level=_family_level(family),
                kind="verify",
                hazard=hazard,
                summary=f"session {number} ({session.contact or 'no RFC recorded'}): {family.summary}",
                outcome=Outcome.PASS
                if opened(session) and family.exercised(packets, initial)
                else Outcome.SKIP,
                seed=0,
                deadline=VERIFY_DEADLINE,
                duration=elapsed,
                packets=packets,
                reproduce=shlex.join(
                    ["manip-conform", "verify", os.fspath(path), "--session", str(number)]
                    + (["--strict"] if strict else [])
                    + ([] if judge == "server" else ["--judge", judge])
                ),
            )
            if result.outcome == "skip":
                result.reason = (
                    "the recording does not exercise it" if opened(session) else "the connection never opened"
                )
            judge_violations(result, by_family.get(family.name, ()), strict=strict)
            report.results.append(result)
    if capture.bad_frames:
        report.problems.append(
            f"{len(capture.bad_frames)} recorded frame(s) do not decode as Chaos packets "
            f"(first: {capture.bad_frames[0].annotation.decode_error})"
        )
    report.duration = time.monotonic() - t0
    return report
