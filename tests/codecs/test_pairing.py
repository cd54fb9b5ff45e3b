"""The one reply-pairing rule (erratum capture-pairing): the capture view, the transcript checks,
replay's answer sorter and the fuzz oracles place every server packet alike, on the golden captures,
on generated connections (wrong echoes, errors in the middle of a multi-packet reply, free joint,
extras) and on a recording of a server that echoes wrong numbers."""

from __future__ import annotations

import asyncio
import json
import re
from dataclasses import dataclass
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from manip.captures import Annotator, read_session
from manip.captures.cli import main as capture_main
from manip.codecs.error_string import ErrorMessage
from manip.codecs.messages import encode_error, encode_request
from manip.codecs.packet import Packet
from manip.codecs.pairing import ReplyPairing
from manip.conformance.fuzz.oracles import answers
from manip.conformance.judge.checks import WirePacket, check_transcript
from manip.conformance.replay.against import AnswerSorter, ReplayOptions, replay_capture
from manip.conformance.replay.cli import recording
from manip.conformance.replay.verify import judge_session, rfc_number, verify_capture, wire_packets
from manip.conformance.suite.embedded import EmbeddedServer
from manip.reference_server import FaultSet, ServerConfig
from manip.spec import SPEC
from manip.spec.constants import ChaosOp, ServerOp
from tests.support.paths import ROOT

GOLDEN = ROOT / "captures"
CLIENT = (0o401, 0x1234)
SERVER = (0o440, 0x5678)
RFC_NO = 1
ECHO_CLAUSES = ("response.echoes-request-number", "error.fatal-request-number", "multi.same-request-number")

Where = int | str | None
"""A server packet's place: the index of the request it answers (-1 the RFC), "async", or None."""


def _word(n: int) -> bytes:
    return (n & 0xFFFF).to_bytes(2, "little")


def _error(opcode: int, echo: int) -> bytes:
    severity = "F" if opcode == ServerOp.FATAL_ERROR else "E"
    return encode_error(opcode, echo, ErrorMessage("test", severity, "XYZ", "pairing"))


# ------------------------------------------------------------------------------ the rule itself


def test_an_error_in_a_multi_packet_reply_answers_the_same_request() -> None:
    pairing: ReplyPairing[str] = ReplyPairing()
    describe = SPEC.request("describe-self").opcode
    pairing.request("describe", describe, b"")
    pairing.request("here", SPEC.request("here").opcode, b"")
    first = pairing.server(ServerOp.RESPONSE, _word(2) + b"(:A 1)")
    error = pairing.server(ServerOp.NON_FATAL_ERROR, _error(ServerOp.NON_FATAL_ERROR, 2))
    assert (first.request, first.final) == ("describe", False)
    assert (error.request, error.final, error.cut_short) == ("describe", True, True)
    assert pairing.head == "here" and pairing.completed == 1


def test_a_wrong_echo_never_re_pairs_and_nothing_answers_after_a_fatal_error() -> None:
    pairing: ReplyPairing[int] = ReplyPairing()
    for tag in range(3):
        pairing.request(tag, SPEC.request("here").opcode, b"")
    assert pairing.server(ServerOp.RESPONSE, _word(99)).request == 0
    assert pairing.server(ServerOp.FATAL_ERROR, _error(ServerOp.FATAL_ERROR, 4)).request == 1
    assert pairing.server(ServerOp.RESPONSE, _word(4)).role == "extra"
    assert pairing.server(ServerOp.ASYNCHRONOUS_RESPONSE, bytes(8)).role == "async"
    assert pairing.outstanding() == [2]


def test_the_request_after_granted_free_joint_is_answered_by_one_packet() -> None:
    pairing: ReplyPairing[str] = ReplyPairing()
    pairing.request("free", SPEC.request("free-joint").opcode, encode_request("free-joint", joint=2))
    assert pairing.server(ServerOp.RESPONSE, _word(2)).final
    assert pairing.request("discarded", SPEC.request("describe-self").opcode, b"")
    assert pairing.server(ServerOp.RESPONSE, _word(3) + b"text").final  # not a multi-packet reply now
    assert not pairing.request("next", SPEC.request("describe-self").opcode, b"")


# ------------------------------------------------------------------------------ three readers, one answer


@dataclass
class Connection:
    """One generated connection: the packets as the capture view sees them (with the RFC and OPN) and as
    the checkers see them (data packets), in the same order."""

    packets: list[tuple[str, Packet]]
    initial: bool

    def wire(self) -> list[WirePacket]:
        return [
            WirePacket(d, p.opcode, p.packet_no, p.ack_no, p.data, float(i))
            for i, (d, p) in enumerate(self.packets)
            if p.opcode >= ChaosOp.DAT
        ]


def by_view(conn: Connection) -> list[Where]:
    """Each server data packet's place by the capture view's pair ids."""
    annotator = Annotator()
    index_of: dict[int | None, int] = {}
    out: list[Where] = []
    requests = 0
    for direction, packet in conn.packets:
        ann = annotator.annotate(1, direction, packet)  # type: ignore[arg-type]
        if direction == "c2s" and ann.pair is not None:
            index_of[ann.pair] = -1 if packet.opcode == ChaosOp.RFC else requests
            requests += packet.opcode >= ChaosOp.DAT
        elif direction == "s2c" and packet.opcode >= ChaosOp.DAT:
            out.append("async" if ann.kind == "async" else index_of.get(ann.pair))
    return out


def by_sorter(conn: Connection) -> list[Where]:
    sorter = AnswerSorter(initial=conn.initial)
    server = []
    for p in conn.wire():
        if p.direction == "c2s":
            sorter.request(p)
        else:
            sorter.server(p)
            server.append(p)
    place: dict[int, Where] = {id(p): "async" for p in sorter.asyncs}
    for index, answer in enumerate(sorter.answers):
        for p in answer:
            place[id(p)] = index - conn.initial
    return [place.get(id(p)) for p in server]


def by_fuzz_oracles(conn: Connection) -> list[Where]:
    """The fuzz oracles' requests-with-answers, as places (answers to requests only)."""
    wire = conn.wire()
    requests = [p for p in wire if p.direction == "c2s"]
    place: dict[int, Where] = {}
    for item in answers(wire):
        for p in item.packets:
            place[id(p)] = requests.index(item.request)
    return [place.get(id(p)) for p in wire if p.direction == "s2c"]


def check_violations_agree(conn: Connection, places: list[Where]) -> None:
    """The checker judges each answer against the request the other two pair it with: a wrong echo is
    a finding naming that request, a right one is none, an answer to nothing is an extra."""
    wire = conn.wire()
    findings = check_transcript(wire, rfc_packet_no=RFC_NO, expect_initial=conn.initial)
    requests = [p for p in wire if p.direction == "c2s"]
    server = [p for p in wire if p.direction == "s2c"]
    for packet, place in zip(server, places, strict=True):
        echo_violations = {
            int(m.group(1))
            for f in findings
            if f.packet is packet and f.clause in ECHO_CLAUSES
            for m in [re.search(r"request number (\d+)", f.expected)]
            if m
        }
        if isinstance(place, int) and place >= 0:
            echoed = int.from_bytes(packet.data[:2], "little")
            wanted = requests[place].packet_no
            assert echo_violations == (set() if echoed == wanted else {wanted}), (packet, place, findings)
        elif place is None and packet.opcode in (0o200, 0o201, 0o202):
            clauses = {f.clause for f in findings if f.packet is packet}
            assert clauses & {"request.one-reply", "error.non-fatal-is-reply", "error.fatal-then-close"}


_SIMPLE = ("here", "joint-angles", "kill-power", "ready", "enable-power")


@st.composite
def connections(draw: st.DrawFn) -> Connection:
    """A client that sends requests (sometimes waiting for the answers so far) and a server that answers
    them in order, with wrong echoes, multi-packet replies cut short by errors, fatal errors, missing
    answers, asynchronous packets and extras."""
    initial = draw(st.booleans())
    packets: list[tuple[str, Packet]] = []
    c_no, s_no = RFC_NO + 1, 1

    def c2s(opcode: int, data: bytes = b"") -> None:
        nonlocal c_no
        packets.append(("c2s", Packet(opcode, *SERVER, *CLIENT, c_no, 0, data)))
        c_no += 1

    def s2c(opcode: int, data: bytes) -> None:
        nonlocal s_no
        packets.append(("s2c", Packet(opcode, *CLIENT, *SERVER, s_no, 0, data)))
        s_no += 1

    if initial:
        packets.append(("c2s", Packet(ChaosOp.RFC, SERVER[0], 0, *CLIENT, RFC_NO, 0, b"PUMA")))
        s2c(ChaosOp.OPN, b"")
        s2c(ServerOp.RESPONSE, _word(RFC_NO))
    queued: list[tuple[int, bytes]] = []
    skew = st.sampled_from([0, 0, 0, 1, -1, 7])
    for _ in range(draw(st.integers(1, 8))):
        name = draw(st.sampled_from(("describe-self", "free-joint", *_SIMPLE)))
        op = SPEC.request(name)
        number = c_no
        c2s(op.opcode, encode_request("free-joint", joint=2) if name == "free-joint" else b"")
        texts = draw(st.integers(0, 3)) if name == "describe-self" else 0
        for _ in range(texts):
            queued.append((ServerOp.RESPONSE, _word(number + draw(skew)) + b"(:X 1)"))
        end = draw(st.sampled_from(["response", "response", "error", "fatal", "none"]))
        if end != "none":
            opcode = {"response": 0o200, "error": 0o202, "fatal": 0o201}[end]
            echo = number + draw(skew)
            queued.append((opcode, _word(echo) if opcode == 0o200 else _error(opcode, echo)))
        if draw(st.booleans()):
            queued.append((ServerOp.ASYNCHRONOUS_RESPONSE, _word(number) + _word(2) + bytes(4)))
        if draw(st.booleans()):  # the client waits for what was answered so far
            for item in queued:
                s2c(*item)
            queued.clear()
    for item in queued:
        s2c(*item)
    for _ in range(draw(st.integers(0, 2))):
        s2c(ServerOp.RESPONSE, _word(500))
    return Connection(packets, initial)


@settings(max_examples=300, deadline=None)
@given(connections())
def test_view_sorter_and_checks_pair_generated_connections_alike(conn: Connection) -> None:
    view, sorter = by_view(conn), by_sorter(conn)
    assert view == sorter
    assert by_fuzz_oracles(conn) == [p if isinstance(p, int) and p >= 0 else None for p in sorter]
    check_violations_agree(conn, sorter)


@pytest.mark.parametrize("name", ["describe-self", "motion", "errors"])
def test_view_sorter_and_checks_pair_the_golden_captures_alike(name: str) -> None:
    session = read_session(GOLDEN / f"{name}.mcap")
    packets = wire_packets(session)
    sorter = AnswerSorter(initial=rfc_number(session) is not None)
    for p in packets:
        if p.is_close:
            continue
        if p.direction == "c2s":
            sorter.request(p)
        else:
            sorter.server(p)
    by_sorter_numbers = {
        (p.packet_no, p.opcode): req.packet_no if req is not None else -1
        for req, answer in zip(sorter.requests, sorter.answers, strict=True)
        for p in answer
    }
    view_numbers = {}
    for pair in session.pairs.values():
        request = pair.request.packet
        assert request is not None
        for reply in pair.replies:
            assert reply.packet is not None
            view_numbers[(reply.packet.packet_no, reply.packet.opcode)] = (
                -1 if request.opcode == ChaosOp.RFC else request.packet_no
            )
    assert view_numbers == by_sorter_numbers and len(view_numbers) > 2
    _, findings = judge_session(session)
    assert not [f for f in findings if f.clause in (*ECHO_CLAUSES, "request.one-reply")]


# ------------------------------------------------------------------------------ a server with a wrong echo


def test_capture_info_and_verify_pair_a_wrong_echo_alike(tmp_path: Path) -> None:
    out = tmp_path / "wrong-echo.mcap"

    async def job() -> None:
        with recording(out, how="test") as wrap:
            options = ReplayOptions(reply_timeout=0.5, async_timeout=2.0, settle=0.05, wrap_link=wrap)
            config = ServerConfig(faults=FaultSet.parse(["wrong-request-number"]))
            with EmbeddedServer(config, time_scale=20) as address:
                await replay_capture(GOLDEN / "motion.mcap", address, options)

    asyncio.run(job())
    info = CliRunner().invoke(capture_main, ["info", str(out), "--json"])
    assert info.exit_code == 0, info.output
    views = json.loads(info.output)["packets"]
    number_of_pair = {
        v["pair"]: v["packet_no"]
        for v in views
        if v["direction"] == "c2s" and v["kind"] == "request" and not v.get("retransmission")
    }
    wrong = {
        v["packet_no"]: number_of_pair[v["pair"]]
        for v in views
        if v["direction"] == "s2c"
        and v.get("pair") in number_of_pair
        and not v.get("retransmission")
        and v.get("request_number") != number_of_pair[v["pair"]]
    }
    assert wrong, "the fault should make replies echo wrong numbers"
    report = verify_capture(out)
    assert report.exit_code == 1
    named = {
        v.packet.packet_no: int(m.group(1))
        for r in report.results
        for v in r.violations
        if v.clause == "response.echoes-request-number" and v.packet is not None
        for m in [re.search(r"request number (\d+)", v.expected)]
        if m
    }
    assert named == wrong  # verify judges each against the request the view pairs it with
    assert not any(v.clause == "request.one-reply" for r in report.results for v in r.violations)
