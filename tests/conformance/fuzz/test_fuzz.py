"""The fuzzer's parts without a target: inputs from the seed and the spec, frames damaged as asked,
shrinking, the judgement of transcripts, the log scanner."""

from __future__ import annotations

import asyncio
import struct
from collections import Counter

import pytest

from manip.codecs.error_string import ErrorMessage
from manip.codecs.errors import DecodeError
from manip.codecs.framing import decode_chudp, decode_tcp, encode_chudp, encode_tcp
from manip.codecs.messages import encode_error, encode_reply
from manip.codecs.packet import Packet
from manip.codecs.pdp11float import pack_f
from manip.conformance.fuzz.generators import INPUT_CLASSES, GenOptions, generate, stray_index
from manip.conformance.fuzz.judge import _connection
from manip.conformance.fuzz.oracles import oracle_violations
from manip.conformance.fuzz.report import CampaignFacts
from manip.conformance.fuzz.session import Allowance, FuzzConnection, Inbox
from manip.conformance.fuzz.shrink import Budget, ddmin
from manip.conformance.fuzz.steps import ConnPacket, FuzzInput, RequestStep, Stray
from manip.conformance.fuzz.target import TracebackScanner
from manip.conformance.judge.checks import WirePacket, required_refusal
from manip.conformance.suite.rawchaos import MAX_RECEIVED, frame
from manip.links.address import parse_address
from manip.reference_server.errors import bad_value
from manip.spec import SPEC
from manip.spec.constants import ChaosOp, ServerOp

STREAM = GenOptions()
DATAGRAM = GenOptions(link="datagram")
ADDRESS = parse_address("tcp://127.0.0.1:42085")


def _inputs(options: GenOptions, count: int, seed: int = 1) -> list[FuzzInput]:
    return [generate(seed, n, options) for n in range(count)]


def _requests(item: FuzzInput) -> list[RequestStep]:
    return [s for s in item.steps if isinstance(s, RequestStep)]


# ------------------------------------------------------------------------------------------ generation


def test_the_same_seed_gives_the_same_inputs_and_another_seed_others() -> None:
    first = _inputs(STREAM, 400, seed=5)
    assert first == _inputs(STREAM, 400, seed=5)
    assert generate(5, 123, STREAM) == first[123]  # an input alone is the same as in its campaign
    other = _inputs(STREAM, 400, seed=6)
    assert sum(a != b for a, b in zip(first, other, strict=True)) > 350


@pytest.mark.parametrize("options", [STREAM, DATAGRAM], ids=["stream", "datagram"])
def test_every_class_of_the_link_is_drawn(options: GenOptions) -> None:
    drawn = Counter(item.kind for item in _inputs(options, 4000))
    expected = {c.id for c in options.classes()}
    assert set(drawn) == expected
    assert all(options.link in INPUT_CLASSES[kind].links for kind in drawn)


def test_the_classes_cover_what_the_issue_names() -> None:
    stream = {c.id for c in STREAM.classes()}
    datagram = {c.id for c in DATAGRAM.classes()}
    assert {"link.bad-length", "link.garbage", "link.truncated", "link.fragmented"} <= stream
    assert {"link.chudp-header", "link.chudp-length", "chaos.oversize"} <= datagram
    assert {"chaos.out-of-window", "chaos.no-connection", "chaos.wrong-source", "chaos.rfc-flood"} <= stream
    assert {"manip.wrong-length", "manip.reserved-float", "manip.extreme-float", "manip.pipeline"} <= stream
    for c in INPUT_CLASSES.values():
        assert c.clauses and all(clause in SPEC.clauses for clause in c.clauses), c.id
        assert c.expected and c.sends


def test_every_opcode_is_sent_at_wrong_lengths_the_spec_refuses() -> None:
    options = GenOptions(select=("manip.wrong-length",))
    seen: set[int] = set()
    for item in _inputs(options, 1500):
        (request,) = _requests(item)
        refusal = required_refusal(request.opcode, request.data)
        assert refusal is not None and refusal.clause == "request.data-length", item.note
        seen.add(request.opcode)
    fixed = {op.opcode for op in SPEC.requests.values() if op.request.fixed_size is not None}
    assert seen == fixed


@pytest.mark.parametrize(
    ("kind", "clause"),
    [
        ("manip.unknown-opcode", "request.unknown-opcode"),
        ("manip.reserved-float", "request.reserved-float"),
        ("manip.valid", None),
        ("manip.extreme-float", None),
    ],
)
def test_each_manip_class_sends_what_it_says(kind: str, clause: str | None) -> None:
    for item in _inputs(GenOptions(select=(kind,)), 300):
        for request in _requests(item)[:1]:
            refusal = required_refusal(request.opcode, request.data)
            assert (refusal.clause if refusal else None) == clause, item.note


def test_hardware_without_motion_sends_no_motion_or_power_opcode() -> None:
    options = GenOptions(hazards=frozenset({"read-only", "config"}))
    assert "manip.sequence" not in {c.id for c in options.classes()}
    sent = 0
    for item in _inputs(options, 4000):
        for step in item.steps:
            opcode = step.opcode if isinstance(step, (RequestStep, ConnPacket)) else None
            if opcode is not None and opcode in SPEC.requests:
                assert SPEC.requests[opcode].hazard in ("read-only", "config"), item.note
                sent += 1
    assert sent > 3000


def test_stray_indices_are_unique_within_a_batch_and_apart_from_the_connections() -> None:
    indices = [stray_index(n, step) for n in range(1000, 2000) for step in range(32)]
    assert len(set(indices)) == len(indices)
    assert all(0x0100 <= i <= 0xFEFF for i in indices)


# ------------------------------------------------------------------------------------------ frames


@pytest.mark.parametrize(
    ("damage", "datagram", "clause"),
    [
        ("checksum", False, "chudp.checksum"),
        ("nbytes", False, "chaos.header.nbytes"),
        ("header-byte", False, "chaos.header.unused-byte-zero"),
        ("checksum", True, "chudp.checksum"),
        ("version", True, "chudp.header"),
        ("function", True, "chudp.header"),
        # The codec tests the checksum first: cut, a datagram has it in the wrong place; padded with
        # zero words it still sums right, and the byte count then disagrees with the length.
        ("short", True, "chudp.checksum"),
        ("long", True, "chaos.header.nbytes"),
    ],
)
def test_a_damaged_frame_breaks_exactly_its_clause(damage: str, datagram: bool, clause: str) -> None:
    hop = (ADDRESS.peer_addr, ADDRESS.my_addr)
    packet = Packet(ChaosOp.DAT, hop[0], 0x1234, hop[1], 0x0567, 17, 3, b"abcdefgh")
    decode = decode_chudp if datagram else decode_tcp
    whole = decode(frame(packet, datagram=datagram, hop=hop))
    assert whole.data == b"abcdefgh" and whole.dest_host == ADDRESS.peer_addr
    with pytest.raises(DecodeError) as caught:
        decode(frame(packet, datagram=datagram, hop=hop, damage=damage))  # type: ignore[arg-type]
    assert caught.value.clause == clause


def test_an_undamaged_frame_is_the_codec_s_own() -> None:
    packet = Packet(ChaosOp.DAT + 1, 0o440, 9, 0o401, 8, 100, 99, b"xyz")
    assert frame(packet, datagram=False, hop=(0o440, 0o401)) == encode_tcp(packet)
    assert frame(packet, datagram=True, hop=(0o440, 0o401)) == encode_chudp(packet)


# ------------------------------------------------------------------------------------------ shrinking


def test_ddmin_finds_the_fewest_inputs_that_still_fail() -> None:
    tried: list[list[int]] = []

    async def fails(candidate: list[int]) -> bool:
        tried.append(candidate)
        return 13 in candidate and 71 in candidate

    minimal, complete = asyncio.run(ddmin(list(range(100)), fails, Budget(trials=500)))
    assert minimal == [13, 71] and complete
    assert len(tried) < 100


def test_ddmin_stops_at_its_budget_with_what_still_fails() -> None:
    async def fails(candidate: list[int]) -> bool:
        return 13 in candidate and 71 in candidate

    minimal, complete = asyncio.run(ddmin(list(range(100)), fails, Budget(trials=12)))
    assert not complete and 13 in minimal and 71 in minimal and len(minimal) < 100


# ------------------------------------------------------------------------------------------ judging


def _c2s(opcode: int, number: int, data: bytes = b"") -> WirePacket:
    return WirePacket("c2s", opcode, number, 0, data)


def _s2c(opcode: int, data: bytes) -> WirePacket:
    return WirePacket("s2c", opcode, 0, 0, data)


def _done(number: int) -> WirePacket:
    return _s2c(ServerOp.RESPONSE, encode_reply("kill-power", number))


def test_a_speed_outside_its_range_answered_done_is_a_wrong_answer() -> None:
    speed = SPEC.request("set-speed").opcode
    packets = [_s2c(ServerOp.RESPONSE, b"\x01\x00"), _c2s(speed, 2, pack_f(2.0)), _done(2)]
    (found,) = oracle_violations(packets)
    assert found.clause == "speed.range"
    refused = encode_error(ServerOp.NON_FATAL_ERROR, 2, bad_value("set-speed", "factor 2 > 1").error)
    assert not oracle_violations([*packets[:2], _s2c(ServerOp.NON_FATAL_ERROR, refused)])


def test_a_move_accepted_after_kill_power_is_a_wrong_answer() -> None:
    kill, ready = SPEC.request("kill-power").opcode, SPEC.request("ready").opcode
    segment = _s2c(ServerOp.RESPONSE, struct.pack("<HH", 3, 1))
    packets = [_c2s(kill, 2), _done(2), _c2s(ready, 3), segment]
    assert [f.clause for f in oracle_violations(packets)] == ["motion.no-power"]
    enable = SPEC.request("enable-power").opcode
    powered = [_c2s(kill, 2), _done(2), _c2s(enable, 3), _done(3), _c2s(ready, 4), segment]
    assert not oracle_violations(powered)


def test_a_move_accepted_after_an_abort_is_a_wrong_answer_until_a_reset() -> None:
    ready, reset = SPEC.request("ready").opcode, SPEC.request("reset-abort").opcode
    segment = _s2c(ServerOp.RESPONSE, struct.pack("<HH", 2, 1))
    collision = ErrorMessage("arm", "E", "COL", "collision")
    aborted = _s2c(ServerOp.ASYNCHRONOUS_ERROR, encode_error(ServerOp.ASYNCHRONOUS_ERROR, 2, collision))
    again = _s2c(ServerOp.RESPONSE, struct.pack("<HH", 3, 2))
    packets = [_c2s(ready, 2), segment, aborted, _c2s(ready, 3), again]
    (found,) = oracle_violations(packets)
    assert found.clause == "motion.abort" and found.packet is again and found.kind == "wrong_value"
    after_reset = [*packets[:3], _c2s(reset, 3), _done(3), _c2s(ready, 4), again]
    assert not oracle_violations(after_reset)


class _Conn:
    """What the judgement reads of a connection."""

    def __init__(self, packets: list[WirePacket]) -> None:
        self.packets = packets
        self.origin = {id(p): i for i, p in enumerate(packets)}
        self.rfc_no = 1
        self.ended: str | None = None
        self.unanswered = 0
        self.after_eof: str | None = None
        self.ahead: dict[int, int] = {}
        self.gap: int | None = None
        self.lost: tuple[int, int] | None = None

    def skipped(self) -> int | None:
        return self.gap

    def never_again(self) -> tuple[int, int] | None:
        return self.lost


def test_a_packet_number_skipped_is_named_first_and_the_rest_only_counted() -> None:
    packets = [_c2s(SPEC.request("here").opcode, 2)]
    conn = _Conn(packets)
    conn.gap, conn.ahead = 2, {3: 2}
    sightings = _connection(conn, 0, report_drops=True)  # type: ignore[arg-type]
    first = sightings[0]
    assert (first.violation.clause, first.violation.kind) == ("ncp.packet-numbers", "missing_response")
    assert first.number == 0 and len(sightings) == 1 and first.followers >= 1  # the Here never answered
    refused = _connection(conn, 0, report_drops=True, refused=True)  # type: ignore[arg-type]
    assert all(s.violation.clause != "ncp.packet-numbers" for s in refused)  # it may be among the refused


def test_a_lost_packet_never_sent_again_is_a_retransmission_violation_of_the_losing_input() -> None:
    conn = _Conn([_c2s(SPEC.request("here").opcode, 2)])
    conn.lost = (7, 4)
    (first, *_) = _connection(conn, 9, report_drops=True)  # type: ignore[arg-type]
    assert (first.violation.clause, first.number) == ("ncp.retransmission", 4)
    conn.lost = None
    assert all(s.violation.clause != "ncp.retransmission" for s in _connection(conn, 9, report_drops=True))  # type: ignore[arg-type]


def test_a_lost_packet_that_is_also_the_gap_is_one_retransmission_violation() -> None:
    """Later packets sent again but never the lost one: the next number expected is the lost packet's,
    one fault (ncp.retransmission), not also a packet number skipped."""
    conn = _Conn([_c2s(SPEC.request("here").opcode, 2)])
    conn.lost = (7, 4)
    alone = _connection(conn, 9, report_drops=True)  # type: ignore[arg-type]
    conn.gap, conn.ahead = 7, {8: 2}
    sightings = _connection(conn, 9, report_drops=True)  # type: ignore[arg-type]
    assert sightings == alone and sightings[0].violation.clause == "ncp.retransmission"
    conn.gap = 6  # another number missing is a fault of its own
    (first,) = _connection(conn, 9, report_drops=True)  # type: ignore[arg-type]
    assert first.followers == alone[0].followers + 1


def _connection_to(server_index: int, inbox: Inbox) -> FuzzConnection:
    """A connection already open to the target's ``server_index`` (its link is never used)."""
    conn = FuzzConnection(None, inbox, 0o101, Allowance())  # type: ignore[arg-type]
    conn.server_index = server_index
    return conn


def test_a_flood_from_a_wrong_source_is_kept_bounded() -> None:
    async def flood() -> Inbox:
        inbox = Inbox()
        conn = _connection_to(0o7001, inbox)
        for n in range(MAX_RECEIVED + 50):
            conn.on_packet(Packet(ChaosOp.DAT, 0o440, 0o101, 0o401, 0o7002, n & 0xFFFF, 0, b""), b"", 0.0)
        return inbox

    inbox = asyncio.run(flood())
    assert len(inbox.strays[0o101]) == MAX_RECEIVED  # what came first is kept
    assert inbox.strays[0o101][0][0].packet_no == 0


def test_a_lazy_reader_does_not_count_an_old_packet_sent_again_as_ahead() -> None:
    async def resend() -> Counter[int]:
        conn = _connection_to(0o7001, Inbox())
        conn.received_upto = conn.acked_upto = 5
        conn._lazy = True
        for number in (4, 5, 8, 8):
            conn.on_packet(Packet(ChaosOp.DAT, 0o440, 0o101, 0o401, 0o7001, number, 0, b""), b"", 0.0)
        assert conn.skipped() == 6
        return conn.ahead

    assert asyncio.run(resend()) == Counter({8: 2})


def test_a_request_skipped_by_the_replies_is_a_silent_drop_not_a_wrong_number() -> None:
    here = SPEC.request("here").opcode
    reply = encode_reply("here", 3, transform=[1.0] * 12)
    packets = [
        _s2c(ServerOp.RESPONSE, b"\x01\x00"),
        _c2s(here, 2),
        _c2s(here, 3),
        _s2c(ServerOp.RESPONSE, reply),
    ]
    sightings = _connection(_Conn(packets), 0, report_drops=True)  # type: ignore[arg-type]
    first = sightings[0].violation
    assert first.kind == "missing_response" and first.clause == "request.one-reply"
    assert sightings[0].number == 1  # the request never answered, not the one after it


def test_replies_each_numbered_as_the_next_request_are_wrong_numbers_not_drops() -> None:
    """Every request answered in position, each reply carrying the next request's number: no request
    went unanswered, so the first violation is the echo, not a silent drop."""
    here = SPEC.request("here").opcode
    packets = [
        _s2c(ServerOp.RESPONSE, b"\x01\x00"),
        _c2s(here, 2),
        _c2s(here, 3),
        _s2c(ServerOp.RESPONSE, encode_reply("here", 3, transform=[1.0] * 12)),
        _s2c(ServerOp.RESPONSE, encode_reply("here", 4, transform=[1.0] * 12)),
    ]
    sightings = _connection(_Conn(packets), 0, report_drops=True)  # type: ignore[arg-type]
    first = sightings[0].violation
    assert first.kind == "wrong_value" and first.clause == "response.echoes-request-number"
    assert sightings[0].number == 3  # the first reply, in position for request #2


def test_a_reply_to_a_request_answered_already_is_a_second_reply() -> None:
    unknown = 0o277
    refusal = encode_error(ServerOp.NON_FATAL_ERROR, 2, bad_value("dispatch", "unknown").error)
    packets = [
        _s2c(ServerOp.RESPONSE, b"\x01\x00"),
        _c2s(unknown, 2),
        _c2s(unknown, 3),
        _s2c(ServerOp.NON_FATAL_ERROR, refusal),
        _s2c(ServerOp.RESPONSE, b"\x02\x00"),  # done for #2 again, where #3's answer was due
    ]
    sightings = _connection(_Conn(packets), 0, report_drops=True)  # type: ignore[arg-type]
    assert sightings[0].violation.clause == "error.non-fatal-is-reply"
    assert sightings[0].number == 1  # the request answered twice


def test_after_a_reply_out_of_step_later_findings_are_only_counted() -> None:
    unknown = 0o277
    extra = _s2c(ServerOp.RESPONSE, b"\x02\x00")
    packets = [_s2c(ServerOp.RESPONSE, b"\x01\x00"), _c2s(unknown, 2), extra, _c2s(unknown, 3), extra]
    sightings = _connection(_Conn(packets), 0, report_drops=True)  # type: ignore[arg-type]
    assert [o.violation.clause for o in sightings] == ["request.unknown-opcode"]
    assert sightings[0].followers >= 1


@pytest.mark.parametrize(
    ("after_eof", "closes"), [("none", ()), ("CLS", (ChaosOp.CLS,))], ids=["none", "CLS"]
)
def test_an_eof_after_a_fatal_error_must_be_followed_by_cls(after_eof: str, closes: tuple[int, ...]) -> None:
    """The connection watched to its end after the target's EOF: nothing after the EOF breaks
    error.fatal-then-close (judged at the EOF's input); a CLS after it does not."""
    calibrate = SPEC.request("calibrate").opcode
    fatal = encode_error(ServerOp.FATAL_ERROR, 2, bad_value("calibrate", "no zero index").error)
    packets = [
        _s2c(ServerOp.RESPONSE, b"\x01\x00"),
        _c2s(calibrate, 2),
        _s2c(ServerOp.FATAL_ERROR, fatal),
        _s2c(ChaosOp.EOF, b""),
        *(_s2c(opcode, b"") for opcode in closes),
    ]
    conn = _Conn(packets)
    conn.after_eof = after_eof
    unclosed = [
        s
        for s in _connection(conn, 0, report_drops=True)  # type: ignore[arg-type]
        if s.violation.clause == "error.fatal-then-close"
    ]
    assert [s.number for s in unclosed] == ([3] if after_eof == "none" else [])


def test_the_scanner_finds_each_traceback_with_the_line_before_it() -> None:
    scanner = TracebackScanner()
    lines = [
        "2026 INFO manip: fine",
        "2026 ERROR manip.reference_server: handler failed",
        "Traceback (most recent call last):",
        '  File "x.py", line 1, in <module>',
        "RuntimeError: boom",
        "Traceback (most recent call last):",
        '  File "y.py", line 2, in f',
        "ValueError: bad",
        "2026 WARNING manip.links: something",
    ]
    for line in lines:
        scanner.feed(line + "\n")
    found = scanner.take()
    assert scanner.total == 2 and len(found) == 2
    assert found[0].startswith("2026 ERROR") and found[0].endswith("RuntimeError: boom")
    assert found[1].endswith("ValueError: bad")
    assert scanner.take() == []


def test_stray_steps_say_what_must_come_back() -> None:
    expects = Counter()
    for item in _inputs(GenOptions(select=("chaos.*", "link.bad-*", "link.header-byte")), 800):
        for step in item.steps:
            if isinstance(step, Stray):
                expects[(item.kind, step.expect)] += 1
                assert step.counted == (item.kind.startswith("link.")), item.kind
    assert expects[("chaos.no-connection", "los")] and expects[("chaos.no-los-for-los", "silence")]
    assert expects[("chaos.rfc-flood", "answer")] and expects[("link.bad-checksum", "silence")]
    assert not [key for key in expects if key[0] == "chaos.no-connection" and key[1] != "los"]


def test_the_campaign_line_counts_in_words() -> None:
    """One of a thing is singular, any other number plural (``1 batch``, ``3 batches``)."""
    one = CampaignFacts(inputs=1, requests=1, batches=1, liveness_checks=1, tracebacks_seen=1)
    assert one.summary_line(1.0).startswith(
        "1 input (1 request) in 1.0 s (1 inputs/s), 1 batch, 1 of 1 liveness check passed; "
        "1 traceback in the target's log; 0 crashes"
    )
    many = CampaignFacts(inputs=10, requests=12, batches=3, liveness_checks=3, tracebacks_seen=0)
    line = many.summary_line(1.0)
    assert "10 inputs (12 requests)" in line
    assert "3 batches, 3 of 3 liveness checks passed; 0 tracebacks in the target's log" in line
