"""One evidence form (``seen=``), and every violation naming the packets it judged.

The fault matrix (``tests/conformance/test_faults.py``) checks the promise over whole runs; these tests
pin its parts: what each form of evidence shows and names, the packet a check whose evidence is text
names, the one-line common checks, and a report window that never cuts a culprit.
"""

from __future__ import annotations

import asyncio
import math

import pytest

from manip.conformance.judge.packets import WirePacket
from manip.conformance.judge.violation import NEVER_CAME, Violation, evidence, missing, seen_packets, showing
from manip.conformance.output.culprit import judged_indices, kept_indices
from manip.conformance.suite.case import CaseFailure
from manip.conformance.suite.context import Answer, CaseContext, Probe
from manip.links import ConnectionClosed
from manip.spec.constants import ServerOp
from tests.support.contexts import bare_context

HERE = 0o201
CLAUSES = ("here.transform", "response.echoes-request-number", "error.fatal-then-close")


def _context() -> CaseContext:
    return bare_context("t.evidence", *CLAUSES)


def _answer(number: int, data: bytes, echo: int | None = None) -> Answer:
    request = WirePacket("c2s", HERE, number, 0, b"")
    quoted = (number if echo is None else echo).to_bytes(2, "little")
    return Answer(request, (WirePacket("s2c", ServerOp.RESPONSE, 7, number, quoted + data),))


def test_each_form_of_evidence_shows_text_bytes_and_packets() -> None:
    answer = _answer(3, b"\x01\x02")
    assert seen_packets(answer) == answer.packets
    text, data = evidence(showing(answer, "mask 5"))
    assert (text, data) == ("mask 5", answer.data)
    assert seen_packets(showing(answer, "mask 5")) == answer.packets
    assert seen_packets([answer, answer.request]) == (*answer.packets, answer.request)
    assert evidence(missing("no CLS", after=answer)) == ("no CLS", answer.data)
    assert seen_packets(missing("no CLS")) == ()
    assert seen_packets("a text") == () and seen_packets(b"\x00") == ()


def test_a_violation_carries_its_culprit_first_among_the_packets_it_judged() -> None:
    answer = _answer(3, b"")
    other = WirePacket("s2c", ServerOp.RESPONSE, 9, 0, b"\x09\x00")
    v = Violation.of("here.transform", "x", seen=[answer, other])
    assert v.packet is answer.first and v.packets == (answer.first, other)
    moved = Violation("x", packet=other, packets=answer.packets)
    assert moved.packets == (other, answer.first)
    assert Violation.of("here.transform", "x", seen=missing("nothing")).kind == "missing_response"


def test_a_check_in_words_names_the_last_packet_recorded() -> None:
    ctx = _context()
    answer = _answer(3, b"\x00" * 48)
    ctx.transcript.extend([answer.request, *answer.packets])
    assert not ctx.expect(False, clause="here.transform", expected="a transform", seen="off by 2 mm")
    violation = ctx.recorded[-1]
    assert violation.actual == "off by 2 mm" and violation.packet is answer.first


def test_a_packet_that_never_came_is_the_one_violation_without_a_packet() -> None:
    ctx = _context()
    with pytest.raises(CaseFailure) as failed:
        ctx.fail("no CLS", clause="error.fatal-then-close", seen=missing("the connection still open"))
    violation = failed.value.violation
    assert violation.kind in NEVER_CAME and violation.packet is None


class _Unanswering:
    """A connection that takes requests and ends before answering any (what a probe needs of one)."""

    async def send(self, data: bytes, opcode: int) -> int:
        return 5

    async def receive(self) -> None:
        raise ConnectionClosed("CLS", by_peer=True)


def test_a_reply_that_never_came_names_the_request_it_answers() -> None:
    async def go() -> Probe:
        probe = Probe(_context(), _Unanswering(), 0)  # type: ignore[arg-type]
        await probe.call_raw(HERE)
        return probe

    with pytest.raises(CaseFailure) as failed:
        asyncio.run(go())
    violation = failed.value.violation
    assert violation.clause == "request.one-reply" and violation.kind in NEVER_CAME
    assert violation.packet is not None and violation.packet.direction == "c2s"
    assert violation.packet.opcode == HERE and violation.packet.packet_no == 5


class _ClosingAfterOne(_Unanswering):
    """A connection that takes one request, then ends before the next can be sent."""

    def __init__(self) -> None:
        self.sent = 0

    async def send(self, data: bytes, opcode: int) -> int:
        self.sent += 1
        if self.sent > 1:
            raise ConnectionClosed("CLS", by_peer=True)
        return 5


def test_a_request_the_target_would_not_take_names_the_unanswered_ones() -> None:
    async def go() -> None:
        probe = Probe(_context(), _ClosingAfterOne(), 0)  # type: ignore[arg-type]
        await probe.request(HERE)
        await probe.request(HERE)

    with pytest.raises(CaseFailure) as failed:
        asyncio.run(go())
    violation = failed.value.violation
    assert violation.clause == "request.one-reply" and violation.kind in NEVER_CAME
    assert [(p.direction, p.packet_no) for p in violation.packets] == [("c2s", 5)]


def test_the_common_checks_are_one_line_each() -> None:
    ctx = _context()
    good, wrong = _answer(3, b""), _answer(4, b"", echo=5)
    assert ctx.expect_echo(good, clause="response.echoes-request-number", expected="#3")
    assert not ctx.expect_echo(wrong, clause="response.echoes-request-number", expected="#4")
    assert ctx.expect_done(good, clause="here.transform", expected="a done")
    assert not ctx.expect_response(good, clause="here.transform", expected="a transform", min_size=3)
    assert not ctx.expect_opcode(good, ServerOp.NON_FATAL_ERROR, clause="here.transform", expected="an error")
    assert ctx.expect_near(1.0, 1.05, 0.1, clause="here.transform", expected="1 +- 0.1", seen=good)
    assert not ctx.expect_near(1.0, 1.2, 0.1, clause="here.transform", expected="1 +- 0.1", seen=good)
    assert ctx.expect_finite((1.0, 2.0), 2, clause="here.transform", expected="two floats", seen=good)
    assert not ctx.expect_finite((1.0, math.inf), 2, clause="here.transform", expected="finite", seen=good)
    assert not ctx.expect_finite((1.0,), 2, clause="here.transform", expected="two floats", seen=good)
    assert ctx.expect_none([], clause="here.transform", expected="nothing more")
    assert not ctx.expect_none([wrong], clause="here.transform", expected="nothing more")
    culprits = [v.packet for v in ctx.recorded]
    assert culprits == [wrong.first, good.first, good.first, good.first, good.first, good.first, wrong.first]
    assert ctx.recorded[-1].actual == str(wrong)


def test_the_report_window_never_cuts_a_culprit() -> None:
    packets = [WirePacket("s2c", 0o200, i, 0, i.to_bytes(2, "little")) for i in range(1, 1000)]
    culprits = list(range(100, 1000, 3))  # 300 culprits, more than the bound
    kept = kept_indices(len(packets), culprits, 200)
    assert set(culprits) <= set(kept) and {0, 1, 2, 3} <= set(kept)
    late = Violation("x", packets=(packets[950], packets[400]))
    assert judged_indices(packets, [late]) == [400, 950]
    assert {400, 950} <= set(kept_indices(len(packets), judged_indices(packets, [late]), 200))
