"""What a batch showed: each :class:`~manip.conformance.judge.violation.Violation` (a crash, a hang,
a silent drop, a wrong answer, a traceback, a drop the target did not count: see :data:`KIND_NAMES`)
with the input it is attributed to, as a :class:`Sighting`.

* The connection's packets are judged by :func:`manip.conformance.judge.checks.check_transcript` (one reply
  per request, in order, echoing its number, the refusal the spec demands for an unknown opcode, a
  wrong length or a reserved-operand float, the shape of every reply, free joint's discarded packet,
  asynchronous responses only when asked for), and by :mod:`.oracles` for what it does not know: the
  suite's stateful model (a factor out of range, motion without power or after an abort) and what
  describe self said.  A request
  never answered is a *silent drop* (also when the replies skip it: a reply carrying the number of a
  later request), anything else a *wrong answer*.  A connection is judged up to its first violation
  that may put answers out of step with requests (:data:`DISRUPTIVE`); the rest are only counted.
* Every stray packet and raw link has an :class:`~.batch.DueAnswer`: a LOS or an RFC answer that
  did not come is a silent drop; an answer to a packet that must be dropped, or a link kept after its
  framing was lost, a wrong answer.
* The liveness check after the batch: a target gone is a *crash*, one that does not answer a *hang*.
* The target's log (when the fuzzer can read it): every traceback.  Its count of bad frames (when it
  reports one): fewer than the fuzzer sent is an *uncounted drop*.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Final

from manip.conformance.fuzz.batch import BatchRun, DueAnswer, Liveness
from manip.conformance.fuzz.oracles import answers, oracle_violations
from manip.conformance.fuzz.session import FuzzConnection, Inbox
from manip.conformance.judge.checks import WirePacket, check_transcript, describe, word
from manip.conformance.judge.violation import FailureKind, Violation
from manip.conformance.suite.rawchaos import format_packet
from manip.spec import SPEC
from manip.spec.constants import ChaosOp, ServerOp
from manip.spec.model import LEVELS, Level
from manip.spec.notation import octal

__all__ = ["ALWAYS", "FUZZ_KINDS", "KIND_NAMES", "Sighting", "judge"]

FUZZ_KINDS: Final[tuple[FailureKind, ...]] = (
    "crash",
    "timeout",
    "traceback",
    "missing_response",
    "wrong_value",
    "uncounted_drop",
)
"""The kinds of violation a campaign finds, in the order its counts list them."""
KIND_NAMES: Final[dict[FailureKind, str]] = {
    "crash": "crash",
    "timeout": "hang",
    "traceback": "traceback",
    "missing_response": "silent drop",
    "wrong_value": "wrong answer",
    "uncounted_drop": "uncounted drop",
}
"""How the console names each kind: a target that does not answer *hangs*, a request never answered
is *dropped silently*."""
DISRUPTIVE: Final = frozenset(
    {
        "connect.initial-response",
        "request.one-reply",
        "error.non-fatal-is-reply",
        "error.fatal-then-close",
        "multi.terminated-by-empty",
        "multi.same-request-number",
        "describe.reply-shape",
        "free-joint.replies",
        "request.unknown-opcode",
        "request.data-length",
        "request.reserved-float",
        "response.data-layout",
        "response.done-empty",
        "response.segment-number",
    }
)
"""Clauses whose breach may pair later answers with the wrong requests (a reply missing, extra or of
another shape), so that later violations on the connection may be its consequence."""
ALWAYS: Final[frozenset[FailureKind]] = frozenset({"crash", "timeout", "traceback", "uncounted_drop"})
"""Kinds that are violations whatever the level: the target's health is no matter of degree."""
_RFC_ANSWERS: Final = frozenset({ChaosOp.OPN, ChaosOp.CLS, ChaosOp.ANS, ChaosOp.FWD})


@dataclass(frozen=True)
class Sighting:
    """A :class:`~manip.conformance.judge.violation.Violation` one batch showed, with the input it is
    attributed to (None: the batch as a whole) and how many violations came after it on the same
    connection (not judged on their own: they may be its consequence)."""

    violation: Violation
    number: int | None = None
    followers: int = 0

    @property
    def level(self) -> Level:
        return self.violation.strength

    @property
    def signature(self) -> tuple[str, str]:
        """What makes two sightings the same violation: the kind and the clause."""
        return self.violation.kind, self.violation.clause or ""


def _seen(
    kind: FailureKind,
    clause: str | None,
    message: str,
    expected: str = "",
    actual: str = "",
    data: bytes = b"",
    number: int | None = None,
) -> Sighting:
    """A sighting of a violation (one without a clause, or of the target's health, is a MUST)."""
    level: Level | None = "MUST" if clause is None or kind in ALWAYS else None
    return Sighting(Violation(message, clause, level, expected, actual, data, kind), number)


def judge(
    run: BatchRun,
    inbox: Inbox,
    live: Liveness,
    *,
    tracebacks: Sequence[str] = (),
    uncounted: tuple[int, int] | None = None,
) -> list[Sighting]:
    """Everything wrong with one batch (module docstring).  ``uncounted``: (bad frames sent, bad frames
    the target counted meanwhile), when the target reports a count."""
    out: list[Sighting] = []
    last = run.last_number
    if not live.alive:
        kind: FailureKind = "crash" if live.kind == "crash" else "timeout"
        what = "the target is gone" if kind == "crash" else "the target does not answer"
        out.append(
            _seen(
                kind,
                None,
                f"{what} after the batch: {live.detail}",
                "a new connection and Here answered",
                live.detail,
            )
        )
    for conn in run.connections:
        out += _connection(conn, last, report_drops=live.alive, refused=bool(inbox.bad))
    for e in run.due_answers:
        found = _judge_due(e, inbox)
        if found is not None:
            out.append(found)
    for raw, exc in inbox.bad:
        out.append(
            _seen(
                "wrong_value",
                exc.clause if exc.clause in SPEC.clauses else None,
                f"the target sent a frame that does not decode: {exc.message}",
                "frames as the link framing says",
                str(exc),
                raw,
                last,
            )
        )
    for text in tracebacks:
        lines = text.strip().splitlines()
        out.append(
            _seen(
                "traceback",
                None,
                f"a traceback in the target's log: {lines[-1] if lines else ''}",
                "no traceback for anything a peer can cause",
                text,
            )
        )
    if uncounted is not None and uncounted[1] < uncounted[0]:
        sent, counted = uncounted
        out.append(
            _seen(
                "uncounted_drop",
                None,
                f"the target counted {counted} of the {sent} bad frames it was sent",
                "every bad frame dropped and counted (manip-server --stats: bad frames)",
                f"{counted} counted",
            )
        )
    if run.open_error is not None and live.alive:
        first = run.inputs[0].number if run.inputs else None
        out.append(
            _seen(
                "missing_response",
                None,
                f"a link or connection of the batch could not be opened: {run.open_error}",
                "the link accepted and the RFC answered",
                run.open_error,
                number=first,
            )
        )
    return out


def _connection(
    conn: FuzzConnection, last: int, *, report_drops: bool, refused: bool = False
) -> list[Sighting]:
    """What is wrong on one connection, in the order it showed, up to the first violation after which
    answers may be paired with the wrong requests (:data:`DISRUPTIVE`): what follows may be its
    consequence, so it is only counted (``followers``)."""
    packets = conn.packets
    position = {id(p): i for i, p in enumerate(packets)}
    found: list[tuple[int, Sighting]] = []
    for f in check_transcript(packets, rfc_packet_no=conn.rfc_no, complete=True):
        number = conn.origin.get(id(f.packet), last) if f.packet is not None else last
        drop = f.clause == "request.one-reply" and f.actual == "nothing"
        if drop and not report_drops:
            continue  # the hang or crash is the violation
        kind: FailureKind = "missing_response" if drop else "wrong_value"
        # Where it shows: a request never answered at the end, a violation without a packet is about the
        # opening (first) or a whole reply's text (last).
        if drop or f.packet is None:
            at = 0 if (f.clause or "").startswith("connect.") else len(packets)
        else:
            at = position.get(id(f.packet), 0)
        found.append((at, Sighting(replace(f, kind=kind), number)))
    fatal = any(p.opcode == ServerOp.FATAL_ERROR for p in packets if p.direction == "s2c")
    requests = [p for p in packets if p.direction == "c2s"]
    ended_by_target = conn.ended is not None and "from the target" in conn.ended
    if ended_by_target and conn.unanswered and not fatal and report_drops and requests:
        request = requests[-min(conn.unanswered, len(requests))]
        message = (
            f"the target ended the connection ({conn.ended}) with {conn.unanswered} request(s) unanswered"
        )
        ended = _seen(
            "missing_response",
            "request.one-reply",
            message,
            "one reply per request (a connection ends after a fatal error only)",
            str(conn.ended),
            request.data,
            conn.origin.get(id(request), last),
        )
        found.append((len(packets), ended))
    unclosed = _unclosed(conn, last) if fatal else None
    if unclosed is not None:
        found.append(unclosed)
    # A packet number missing, or a lost packet that never came again, is the target's doing only when
    # no frame of the target was refused (``refused``): the one missing may be among them.
    if not refused:  # first: every answer missing after them is their consequence
        found[:0] = [(0, seen) for seen in _numbering(conn, last)]
    for judged in oracle_violations(packets, rfc_packet_no=conn.rfc_no):
        number = conn.origin.get(id(judged.packet), last)
        found.append((position.get(id(judged.packet), len(packets)), Sighting(judged, number)))
    if not found:
        return []
    found.sort(key=lambda item: (item[0], LEVELS.index(item[1].level)))  # the strongest of one packet
    out: list[Sighting] = []
    for index, (at, o) in enumerate(found):
        o = _skipped(o, packets, at, conn.origin, last) or o
        if o.violation.clause in DISRUPTIVE or o.violation.kind != "wrong_value":
            out.append(replace(o, followers=len(found) - index - 1))
            break
        out.append(o)
    return out


def _numbering(conn: FuzzConnection, last: int) -> list[Sighting]:
    """A lost packet that never came again, and a packet number the target skipped (the lost packet is
    also the next one expected: its gap is that retransmission failure, not a second fault)."""
    out: list[Sighting] = []
    lost = conn.never_again()
    if lost is not None:
        again = _seen(
            "missing_response",
            "ncp.retransmission",
            f"the target's packet #{lost[0]}, lost on its way, never came again",
            "a controlled packet sent again until a receipt covers it",
            "nothing",
            number=lost[1],
        )
        out.append(again)
    gap = conn.skipped()
    if gap is not None and (lost is None or gap != lost[0]):
        first = next((conn.origin.get(id(p), last) for p in conn.packets if p.direction == "c2s"), last)
        skipped = _seen(
            "missing_response",
            "ncp.packet-numbers",
            f"the target's packet #{gap} never came, though packets numbered past it came again",
            "controlled packets numbered consecutively",
            f"packets numbered {', '.join(f'#{n}' for n in sorted(conn.ahead)[:4])}",
            number=first,
        )
        out.append(skipped)
    return out


def _unclosed(conn: FuzzConnection, last: int) -> tuple[int, Sighting] | None:
    """After a fatal error, the target's EOF with no CLS after it (``after_eof``: the connection was
    watched to its end): the 1985 guide's server sends CLS after a fatal error (error.fatal-then-close)."""
    ends = [(i, p) for i, p in enumerate(conn.packets) if p.direction == "s2c" and p.opcode == ChaosOp.EOF]
    if conn.after_eof != "none" or not ends:
        return None
    at, eof = ends[-1]
    seen = _seen(
        "wrong_value",
        "error.fatal-then-close",
        "the connection ended with EOF after the fatal error, and no CLS followed it",
        "CLS after the fatal error (EOF first or not)",
        "EOF, then the link dropped or silence",
        eof.data,
        conn.origin.get(id(eof), last),
    )
    return at, seen


def _skipped(
    o: Sighting, packets: Sequence[WirePacket], at: int, origin: dict[int, int], last: int
) -> Sighting | None:
    """A reply out of step with the requests, said as what it is rather than as a wrong number: one
    carrying the number of a later request means the requests in between were never answered (a silent
    drop); one carrying the number of a request already answered is a second reply to it."""
    if o.violation.clause != "response.echoes-request-number" or not 0 <= at < len(packets):
        return None
    reply = packets[at]
    number = word(reply.data)
    sent = [p for p in packets[:at] if p.direction == "c2s"]
    numbers = [p.packet_no for p in sent]
    if number is None or number not in numbers:
        return None
    done = list(answers(packets[:at]))
    index = numbers.index(number)
    if index < len(done):  # answered already: this is a second reply
        earlier = done[index]
        clause = (
            "request.one-reply" if earlier.first.opcode == ServerOp.RESPONSE else "error.non-fatal-is-reply"
        )
        return _seen(
            "wrong_value",
            clause,
            f"a second reply to {describe(earlier.request)}, after {describe(earlier.first)}",
            "one reply per request (a non-fatal error is the reply)",
            describe(reply),
            reply.data,
            origin.get(id(earlier.request), last),
        )
    skipped = sent[len(done) : index]
    if not skipped or _answered_each(packets):
        return None  # every request got its answer in position: only the number is wrong
    first = skipped[0]
    return _seen(
        "missing_response",
        "request.one-reply",
        f"{len(skipped)} request(s) never answered, from {describe(first)}: the next reply answers #{number}",
        "one reply per request, in order",
        describe(reply),
        first.data,
        origin.get(id(first), last),
    )


def _answered_each(packets: Sequence[WirePacket]) -> bool:
    """Whether the connection's answers, paired by position, number as many as its requests: then none
    was dropped, whatever numbers they carry."""
    requests = sum(1 for p in packets if p.direction == "c2s" and not p.is_close)
    return requests > 0 and len(list(answers(packets))) >= requests


def _busy(e: DueAnswer, when: float | None) -> bool:
    """Whether the batch's connection still held the robot when ``when`` (an OPN) came."""
    conn = e.connection
    if conn is None or when is None:
        return False
    return conn.ended_at is None or conn.ended_at > when


def _judge_due(e: DueAnswer, inbox: Inbox) -> Sighting | None:
    """Whether what a step was due came (or what must not come did not)."""
    return _DUE_JUDGES[e.what](e, inbox)


def _due_los(e: DueAnswer, inbox: Inbox) -> Sighting | None:
    got = [p for p, _ in inbox.strays.get(e.key, ())]
    if any(p.opcode == ChaosOp.LOS for p in got):
        return None
    shown = "; ".join(format_packet(p) for p in got[:2]) or "nothing"
    return _seen(
        "missing_response",
        e.clause,
        f"no LOS for {e.note}",
        f"a LOS back to index {octal(e.key)}",
        shown,
        e.data,
        e.number,
    )


def _due_answer(e: DueAnswer, inbox: Inbox) -> Sighting | None:
    got = [p for p, _ in inbox.strays.get(e.key, ())]
    answers = [p for p in got if p.opcode in _RFC_ANSWERS]
    if not answers:
        return _seen(
            "missing_response",
            e.clause,
            f"no answer to {e.note}",
            "OPN, CLS, ANS or FWD",
            "nothing",
            e.data,
            e.number,
        )
    opened = {p.src_index for p in answers if p.opcode == ChaosOp.OPN}
    opened_at = min((t for p, t in inbox.strays.get(e.key, ()) if p.opcode == ChaosOp.OPN), default=None)
    if len(opened) > 1:
        return _seen(
            "wrong_value",
            "ncp.duplicate-rfc",
            f"one RFC (index {octal(e.key)}) opened {len(opened)} connections",
            "one connection for a retransmitted RFC",
            f"OPN from indices {', '.join(f'{octal(i)}' for i in sorted(opened))}",
            e.data,
            e.number,
        )
    if opened and e.clause == "connect.one-server-per-robot" and _busy(e, opened_at):
        return _seen(
            "wrong_value",
            "connect.one-server-per-robot",
            "a second connection was opened while the robot had its client",
            'CLS ("busy")',
            "OPN",
            e.data,
            e.number,
        )
    return None


def _due_silence(e: DueAnswer, inbox: Inbox) -> Sighting | None:
    got = [p for p, _ in inbox.strays.get(e.key, ())]
    if not got:
        return None
    return _seen(
        "wrong_value",
        e.clause,
        f"an answer to {e.note}",
        "nothing: the packet is dropped",
        format_packet(got[0]),
        e.data,
        e.number,
    )


def _due_sts(e: DueAnswer, inbox: Inbox) -> Sighting | None:
    conn = e.connection
    if conn is None or any(t >= e.since for t in conn.sts_times):
        return None
    if conn.ended is not None and "from the target" in conn.ended:
        return None
    return _seen(
        "missing_response",
        e.clause,
        "no STS in answer to SNS",
        "an STS (the connection's receipt and window)",
        "nothing",
        e.data,
        e.number,
    )


def _due_close(e: DueAnswer, inbox: Inbox) -> Sighting | None:
    if e.link is None or e.link.ended is not None:
        return None
    return _seen(
        "wrong_value",
        e.clause,
        f"the link was kept open after {e.note}",
        "the link dropped: its framing is lost",
        "the link still open",
        e.data,
        e.number,
    )


_DUE_JUDGES: Final[dict[str, Callable[[DueAnswer, Inbox], Sighting | None]]] = {
    "los": _due_los,
    "answer": _due_answer,
    "silence": _due_silence,
    "sts": _due_sts,
    "close": _due_close,
}
