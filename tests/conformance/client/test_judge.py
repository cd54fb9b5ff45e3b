"""The client judge's own rules, on hand-made wires and documents: the window as offered at each
moment, and every example of ``docs/client-harness.md`` read by the judge's parser."""

from __future__ import annotations

import json
import re
from typing import Any

import pytest

from manip.codecs.error_string import ErrorMessage
from manip.codecs.messages import encode_request, response_layout
from manip.codecs.packet import Packet
from manip.conformance.cases.client._support import error_parts, raw_words, reply_mismatches
from manip.conformance.client.cli import client_cases
from manip.conformance.client.contract import (
    CHOICE_OPERATIONS,
    REQUEST_OPERATIONS,
    REVISION,
    Op,
    choice_args,
    parse_hello,
    parse_instruction,
    parse_result,
    request_args,
)
from manip.conformance.client.server import WireRecord
from manip.conformance.client.wire import window_violations
from manip.conformance.judge.client_checks import check_client_guards
from manip.conformance.judge.packets import Direction, WirePacket
from manip.ncp.packets import pack_status
from manip.spec import SPEC
from manip.spec.constants import ChaosOp, ServerOp
from manip.spec.model import RequestOpcode
from tests.support.paths import ROOT


def _c2s(t: float, number: int) -> WireRecord:
    return WireRecord(t, "c2s", Packet(0o201, packet_no=number, ack_no=1))


def _sts(t: float, ack: int, window: int) -> WireRecord:
    return WireRecord(t, "s2c", Packet(ChaosOp.STS, ack_no=ack, data=pack_status(ack, window)))


OPN = WireRecord(0.0, "s2c", Packet(ChaosOp.OPN, packet_no=1, ack_no=1, data=pack_status(1, 4)))


def test_the_window_is_the_one_offered_when_the_packet_went_out() -> None:
    filled = [OPN, *(_c2s(0.1, n) for n in range(2, 6))]  # 4 unacknowledged: the window of 4, full
    assert window_violations(filled, 15) == []
    shrunk = [*filled, _sts(0.2, 3, 1), _c2s(0.3, 6)]  # 3 unacknowledged after the shrink to 1
    found = window_violations(shrunk, 15)
    assert [f.clause for f in found] == ["ncp.window"] and "window is 1" in found[0].message
    opened = [*filled, _sts(0.2, 5, 1), _c2s(0.3, 6)]  # all acknowledged: one more is allowed
    assert window_violations(opened, 15) == []


def test_past_the_offered_window_is_found_before_any_status() -> None:
    wire = [OPN, *(_c2s(0.1, n) for n in range(2, 7))]  # 5 unacknowledged, window 4
    assert [f.clause for f in window_violations(wire, 15)] == ["ncp.window"]


def test_an_eof_counts_against_the_window_and_a_retransmission_is_judged_when_first_sent() -> None:
    filled = [OPN, *(_c2s(0.1, n) for n in range(2, 6))]  # 4 unacknowledged: the window of 4, full
    eof = WireRecord(0.2, "c2s", Packet(ChaosOp.EOF, packet_no=6, ack_no=1))
    assert [f.clause for f in window_violations([*filled, eof], 15)] == ["ncp.window"]
    assert "EOF 6" in window_violations([*filled, eof], 15)[0].message
    resent = [*filled, _sts(0.2, 2, 1), _c2s(0.3, 3)]  # packet 3 again, sent first under the window of 4
    assert window_violations(resent, 15) == []


def test_an_sts_that_acknowledges_nothing_new_still_sets_the_window() -> None:
    filled = [OPN, *(_c2s(0.1, n) for n in range(2, 4))]  # 2 unacknowledged
    shrunk = [*filled, _sts(0.2, 1, 1), _c2s(0.3, 4)]  # the same ack, window 1: packet 4 is past it
    assert [f.clause for f in window_violations(shrunk, 15)] == ["ncp.window"]
    opened = [
        WireRecord(0.0, "s2c", Packet(ChaosOp.OPN, packet_no=1, ack_no=1, data=pack_status(1, 1))),
        _c2s(0.1, 2),
        _sts(0.2, 1, 4),  # nothing new acknowledged, window 4
        *(_c2s(0.3, n) for n in range(3, 6)),
    ]
    assert window_violations(opened, 15) == []


def _guard_packet(direction: Direction, opcode: int, number: int, data: bytes) -> WirePacket:
    return WirePacket(direction, opcode, number, 0, data, 0.0)


def test_a_set_guard_answered_by_an_error_arms_nothing() -> None:
    set_guard = SPEC.request("set-guard").opcode
    word = (0x8003).to_bytes(2, "little") + bytes(28)
    notify = _guard_packet("c2s", SPEC.request("request-notifications").opcode, 2, b"\x01\x00")
    first = _guard_packet("c2s", set_guard, 3, word)
    again = _guard_packet("c2s", set_guard, 4, word)
    refused = _guard_packet("s2c", ServerOp.NON_FATAL_ERROR, 5, (3).to_bytes(2, "little") + b"PUMA: E X\0")
    assert [f.clause for f in check_client_guards([notify, first, again])] == ["client.guard-numbers"]
    assert check_client_guards([notify, first, refused, again]) == []


# ------------------------------------------------------------------------ the document's levels

LEVELLED = re.compile(r"`([a-z][a-z0-9-]*(?:\.[a-z0-9-]+)+)`\s+\((MUST|SHOULD|MAY|INFO)\)")
"""An id in backticks followed by its level in brackets, as the contract names levels."""


def test_every_level_the_contract_states_is_the_judges() -> None:
    """Each case or clause the contract names with a level has that level: a case's as
    ``manip-conform cases`` lists it, a clause's as the spec says."""
    cases = {c.id: c.level for c in client_cases()}
    stated = LEVELLED.findall(" ".join(DOC.read_text().split()))
    assert len(stated) >= 8
    for ident, level in stated:
        assert ident in cases or ident in SPEC.clauses, f"{ident} is neither a client case nor a clause"
        actual = cases[ident] if ident in cases else SPEC.clauses[ident].level
        assert actual == level, f"the contract says {ident} is {level}; the judge has {actual}"


def test_the_deadline_counts_a_timeout_per_request_a_choice_operation_may_send() -> None:
    """Section 4.4: the timeout applies to each request; the deadline counts arm-guard as one request
    and change-load as four (section 5: the ops' timeouts and waits, plus the slack)."""
    assert Op(1, "here").budget(2.0) == 2.0
    assert Op(1, "arm-guard").budget(2.0) == 2.0
    assert Op(1, "change-load", timeout=3.0).budget(2.0) == 12.0
    assert Op(1, "wait", seconds=0.5).budget(2.0) == 0.5
    text = " ".join(DOC.read_text().split())
    assert "counts `arm-guard` as one request and `change-load` as four" in text


def test_the_out_of_sequence_case_is_a_should_case() -> None:
    (case,) = [c for c in client_cases() if c.id == "client.reply.out-of-sequence"]
    assert case.level == "SHOULD"


# ------------------------------------------------------------------------ the document's examples

DOC = ROOT / "docs" / "client-harness.md"


def _blocks(language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", DOC.read_text(), flags=re.S)


def _objects(block: str) -> list[dict[str, Any]]:
    """The JSON objects of a code block: one object laid out over lines, or one per line."""
    try:
        return [json.loads(block)]
    except json.JSONDecodeError:
        return [json.loads(line) for line in block.splitlines() if line.strip()]


def _examples() -> list[dict[str, Any]]:
    return [obj for block in _blocks("json") for obj in _objects(block)]


def _inline_objects() -> list[dict[str, Any]]:
    """The JSON objects quoted inline (in backticks) in the prose."""
    out = []
    for text in re.findall(r"`(\{[^`]*\})`", DOC.read_text()):
        try:
            out.append(json.loads(text))
        except json.JSONDecodeError:
            continue
    return out


def _payload(op: RequestOpcode, raw: dict[str, Any]) -> bytes:
    """Reply data rebuilt from an example's ``raw`` (a float's sign/exponent word first)."""
    out = b""
    for f in response_layout(op).fields:
        words = raw_words(raw[f.name]) or []
        if f.type.element == "counted":
            out += len(words).to_bytes(2, "little")
        for w in words:
            out += b"".join(int(w[i : i + 4], 16).to_bytes(2, "little") for i in range(0, len(w), 4))
    return out


def test_the_document_has_the_examples_this_test_reads() -> None:
    kinds = [obj["type"] for obj in _examples()]
    assert {"hello", "case", "state", "reply", "error", "async", "unsupported", "done"} <= set(kinds)
    assert len(_inline_objects()) >= 3


def test_every_example_line_is_read_by_the_judges_parser() -> None:
    for obj in _examples():
        line = json.dumps(obj)
        if obj["type"] == "hello":
            assert parse_hello(line).operations
        elif obj["type"] == "case":
            assert obj["revision"] == REVISION  # the example shows the revision the suite sends
            instruction = parse_instruction(line)
            for op in instruction.operations:
                if op.op in REQUEST_OPERATIONS and op.args:
                    encode_request(op.op, **request_args(op.op, op.args))
        else:
            assert parse_result(line, obj["case"]).type == obj["type"]


def test_the_reply_example_is_exact_by_the_judges_rule() -> None:
    replies = [obj for obj in _examples() if obj["type"] == "reply"]
    assert replies
    for obj in replies:
        op = SPEC.requests_by_name[obj["request"]]
        payload = _payload(op, obj["raw"])
        assert reply_mismatches(op, payload, obj["request_number"], obj) == []


def test_the_server_error_example_is_rendered_as_the_judge_renders_it() -> None:
    errors = [obj for obj in _examples() if obj["type"] == "error" and obj["origin"] != "client"]
    assert errors
    for obj in errors:
        error = ErrorMessage(
            obj["where"], obj["severity"], obj["code"], obj["template"], tuple(obj["arguments"])
        )
        assert {k: obj[k] for k in error_parts(error)} == error_parts(error)


def test_the_inline_operation_examples_encode() -> None:
    ops = [obj for obj in _inline_objects() if "op" in obj]
    assert len(ops) >= 4
    for obj in ops:
        op = Op(0, obj["op"], obj.get("args"))
        if op.op in CHOICE_OPERATIONS:
            choice_args(op.op, op.args)
        else:
            assert op.op in REQUEST_OPERATIONS
            encode_request(op.op, **request_args(op.op, op.args))


@pytest.mark.parametrize("form", ["bare", "array"])
def test_a_one_element_raw_is_accepted_bare_or_in_an_array_for_every_opcode(form: str) -> None:
    """The document's segment example is a bare string and its rule allows an array of one: the judge
    takes both, for segment replies and for every one-element field of a data reply."""
    assert '"raw": {"segment": "0007"}' in DOC.read_text()
    segment = SPEC.requests_by_name["set-joint-angles"]
    raw: Any = "0007" if form == "bare" else ["0007"]
    assert (
        reply_mismatches(segment, b"\x07\x00", 3, {"values": {"segment": 7}, "raw": {"segment": raw}}) == []
    )
    version = SPEC.requests_by_name["wrist-version"]
    raw = "028C" if form == "bare" else ["028c"]
    data = {"values": {"version": 0o1214}, "raw": {"version": raw}}
    assert reply_mismatches(version, b"\x8c\x02", 3, data) == []
    wrong = {"values": {"version": 0o1214}, "raw": {"version": "028D"}}
    assert reply_mismatches(version, b"\x8c\x02", 3, wrong)


def test_the_sequence_diagram_uses_operations_of_the_contract() -> None:
    (diagram,) = _blocks("mermaid")
    named = re.search(r'"operations":\[([^\]]*)\]', diagram)
    assert named is not None
    for name in (n.strip() for n in named.group(1).split(",")):
        assert name in REQUEST_OPERATIONS or name in ("connect", "close", "wait", "await-replies"), name
