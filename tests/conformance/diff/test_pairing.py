"""Pairing two sides' answers and classifying what differs (sans-I/O): error strings by their parts,
asynchronous layouts, floats within tolerance and in other length units, and the freedoms the spec data
declares."""

from __future__ import annotations

import dataclasses

import pytest

from manip.codecs.pdp11float import pack_f
from manip.conformance.diff.classify import classify, declared, in_context
from manip.conformance.diff.pairing import SideEvent, compare, differing_parts
from manip.conformance.fuzz.judge import Sighting
from manip.conformance.fuzz.steps import FuzzInput, RequestStep
from manip.conformance.judge.violation import Violation
from manip.spec import SPEC
from manip.spec.constants import ServerOp
from manip.spec.loader import SpecError, _check_freedoms

NUMBER = b"\x05\x00"


def error(text: bytes, args: bytes = b"") -> SideEvent:
    return SideEvent("packet", ServerOp.NON_FATAL_ERROR, NUMBER + text + (b"\0" + args if args else b""))


def response(*values: float) -> SideEvent:
    return SideEvent("packet", ServerOp.RESPONSE, NUMBER + b"".join(pack_f(v) for v in values))


def test_the_same_answers_do_not_differ() -> None:
    a = {0: [response(1.0, 2.0)], 1: [error(b"dispatch: C UOP Unknown opcode ~", b"\xa3\x00")]}
    assert compare([0, 1], a, {k: list(v) for k, v in a.items()}) == []


def test_an_error_differs_by_its_parts() -> None:
    ours = error(b"dispatch: C UOP Unknown opcode ~", b"\xa3\x00")
    theirs = error(b"wrist: C UIM No wrist ~", b"\xa3\x00")
    assert differing_parts(ours, theirs) == ("error.where", "error.code", "error.message")
    assert differing_parts(ours, error(b"dispatch: C UOP Unknown opcode ~", b"\xa4\x00")) == ("error.args",)


def test_the_pad_byte_before_the_numbers_is_the_layout() -> None:
    # 2 + 8 bytes of text and its NUL: the numbers start at an odd offset, so an aligned writer pads.
    packed = SideEvent("packet", ServerOp.NON_FATAL_ERROR, NUMBER + b"w: C UOP ~\0\xa3\x00")
    aligned = SideEvent("packet", ServerOp.NON_FATAL_ERROR, NUMBER + b"w: C UOP ~\0\0\xa3\x00")
    assert differing_parts(packed, aligned) == ("error.args-layout",)


def test_floats_within_tolerance_are_the_same_and_inches_are_a_length_unit() -> None:
    assert differing_parts(response(1.0, 100.0), response(1.0, 100.0000001)) == ()
    assert differing_parts(response(1.0, 254.0), response(1.0, 10.0)) == ("data.length-unit",)
    assert differing_parts(response(1.0, 254.0), response(2.0, 10.0)) == ("data",)


def test_a_zero_against_the_least_magnitude_differs_whatever_the_tolerance() -> None:
    least = 2.0**-128  # within tolerance of zero, yet float.range sends a smaller magnitude as zero
    assert differing_parts(response(1.0, 0.0), response(1.0, -least)) == ("data",)
    assert differing_parts(response(least, 2.0), response(0.0, 2.0)) == ("data",)
    assert differing_parts(response(1.0, 0.0), response(1.0, 1e-7)) == ()  # rounding, both conform
    assert differing_parts(response(1.0, least), response(1.0, least)) == ()


def test_asynchronous_layouts() -> None:
    words = b"\x01\x00\x00\x00\x07\x00"
    guide = SideEvent("packet", ServerOp.ASYNCHRONOUS_RESPONSE, words)
    numbered = SideEvent("packet", ServerOp.ASYNCHRONOUS_RESPONSE, NUMBER + words)
    assert differing_parts(guide, numbered) == ("async.layout",)
    other = SideEvent("packet", ServerOp.ASYNCHRONOUS_RESPONSE, NUMBER + b"\x01\x00\x00\x00\x08\x00")
    assert differing_parts(guide, other) == ("async.layout", "async.data")


def test_a_missing_answer_and_an_end() -> None:
    assert differing_parts(response(1.0), None) == ("count",)
    assert differing_parts(SideEvent("end", 0o10, text="CLS a"), response(1.0)) == ("end",)


def test_the_spec_declares_the_freedoms_the_diff_names() -> None:
    assert declared("error.args-layout")[0] == "error-arg-layout"
    assert "async-request-number" in declared("async.layout")
    assert "error-string.code" in declared("error.code")
    assert declared("units") == ()
    assert set(SPEC.errata["units"].freedom) == {"data.length-unit", "answer.length-unit"}
    assert declared("answer.length-unit") == (
        "units",
        "move.transform-data",
        "incremental-move.data",
        "incremental-straight-move.data",
        "solve-forwards.data",
    )


def test_a_transform_out_of_reach_in_one_sides_length_unit_is_both_allowed() -> None:
    """Solve forwards of a transform in millimetres, solved on one side and refused TOR on a side of
    another length unit: both conform (erratum units); of one unit, a gap."""
    solve = SPEC.request("solve-forwards").opcode
    item = FuzzInput(5, "scenario.x", (RequestStep(solve, bytes(74)),), "")
    refused = error(b"solve-forwards: E TOR Transform cannot be reached")
    diffs = compare([5], {5: [response(*[1.0] * 6)]}, {5: [refused]})
    (other_unit,) = classify("s", diffs, [], [], {5: item}, units_differ=True)
    assert other_unit.cls == "allowed" and "units" in other_unit.names
    (same_unit,) = classify("s", diffs, [], [], {5: item})
    assert same_unit.cls == "unexplained"


def test_an_unknown_freedom_is_refused() -> None:
    clause = dataclasses.replace(SPEC.clauses["error-string.code"], freedom=("error.colour",))  # type: ignore[arg-type]
    spec = dataclasses.replace(SPEC, clauses={**SPEC.clauses, clause.id: clause})
    with pytest.raises(SpecError, match=r"unknown freedom 'error\.colour'"):
        _check_freedoms(spec)


def _seen(clause: str, number: int) -> Sighting:
    return Sighting(Violation("broken", clause), number)


def test_classes() -> None:
    args_a, args_b = error(b"d: C UOP x ~", b"\xa3\x00"), error(b"d: C UOP x ~", b"\x00\xa3")
    diffs = compare([1, 2], {1: [args_a], 2: [response(1.0)]}, {1: [args_b], 2: [response(2.0)]})
    found = classify("s", diffs, [], [_seen("error-string.arg-values", 1)], {})
    assert [(f.cls, f.names, f.violator) for f in found] == [
        ("violation", ("error-string.arg-values",), "B"),
        ("violation", ("error-string.arg-values",), "B"),
    ]
    assert found[1].follows == "error-string.arg-values (input 1)"
    free = classify("s", compare([1], {1: [error(b"a: C UOP x")]}, {1: [error(b"b: C XYZ y")]}), [], [], {})
    assert free[0].cls == "allowed" and "error-string.format" in free[0].names
    gap = classify("s", compare([2], {2: [response(1.0)]}, {2: [response(2.0)]}), [], [], {})
    assert gap[0].cls == "unexplained" and gap[0].section


def test_an_extension_request_and_describe_self_explain_their_answers() -> None:
    extension = next(op for op in SPEC.requests.values() if op.extension)
    describe = SPEC.request("describe-self")
    ext_input = FuzzInput(3, "manip.valid", (RequestStep(extension.opcode, b""),), "")
    describe_input = FuzzInput(4, "manip.valid", (RequestStep(describe.opcode, b""),), "")
    assert in_context(("opcode",), ext_input) == ("request.extension-served",)
    assert in_context(("data", "count"), describe_input) == ("data", "count")
    listed = b"\x05\x00 (:OPERATIONS 200 201%s) (:DOF 6)"
    ours = SideEvent("packet", ServerOp.RESPONSE, listed % f" {extension.opcode:o}".encode())
    theirs = SideEvent("packet", ServerOp.RESPONSE, listed % b" 202")
    served = SideEvent("packet", ServerOp.RESPONSE, listed % b"")
    lying = compare([4], {4: [ours]}, {4: [theirs]})
    assert in_context(lying[0].parts, describe_input, lying[0]) == ("data",)
    extension_listed = compare([4], {4: [ours]}, {4: [served]})
    assert in_context(extension_listed[0].parts, describe_input, extension_listed[0]) == (
        "request.extension-served",
    )
    diffs = compare([3], {3: [response(1.0)]}, {3: [error(b"dispatch: C UOP Unknown opcode ~", b"\xa3\x00")]})
    found = classify("s", diffs, [], [], {3: ext_input})
    assert found[0].cls == "allowed" and found[0].names == ("extension-range",)


def test_the_numbers_of_another_message_are_part_of_its_difference() -> None:
    refused = error(b"request-notifications: C BVA Mask ~ has undefined bits", b"\xff\x00")
    unknown = error(b"dispatch: C UOP Unknown opcode ~", b"\xa3\x00")
    assert differing_parts(refused, unknown) == ("error.where", "error.code", "error.message")


def test_a_gap_names_the_clause_nearest_its_part() -> None:
    a, b = (
        error(b"s: E JOR Joint(s) $ out of range", b"\x04\x00"),
        error(b"s: E JOR Joint(s) $ out of range", b"\x00\x04"),
    )
    gap = classify("s", compare([1], {1: [a]}, {1: [b]}), [], [], {})
    assert gap[0].cls == "unexplained" and gap[0].names == ("error-string.arg-values",)
    assert gap[0].section == SPEC.clauses["error-string.arg-values"].section


def test_two_of_the_guides_own_codes_are_no_choice() -> None:
    jor = error(b"move: E JOR Joint(s) $ out of range", b"\x04\x00")
    tor = error(b"move: E TOR Joint(s) $ out of range", b"\x04\x00")
    assert differing_parts(jor, tor) == ("error.guide-code",)
    assert classify("s", compare([1], {1: [jor]}, {1: [tor]}), [], [], {})[0].cls == "unexplained"
    own = error(b"move: E XYZ Joint(s) $ out of range", b"\x04\x00")
    assert differing_parts(jor, own) == ("error.code",)


def test_answers_to_different_requests_are_out_of_step() -> None:
    here, angles = SPEC.request("here").opcode, SPEC.request("joint-angles").opcode
    a = [
        SideEvent("packet", 0o200, b"\x01\x00", request=here),
        SideEvent("packet", 0o200, b"\x02\x00", request=angles),
    ]
    b = [SideEvent("packet", 0o200, b"\x02\x00", request=angles)]
    found = compare([1], {1: a}, {1: b})
    assert [d.parts for d in found] == [("step",)]


def test_awa_for_a_request_that_may_move_the_arm_is_the_servers_choice() -> None:
    hand, here = SPEC.request("hand").opcode, SPEC.request("here").opcode
    awa = dataclasses.replace(error(b"hand: E AWA Arm motion was aborted"), request=hand)
    nap = dataclasses.replace(error(b"hand: E NAP No arm power"), request=hand)
    assert differing_parts(awa, nap) == ("error.abort-scope", "error.message")
    assert declared("error.abort-scope") == ("awa-scope",)
    on_here = [dataclasses.replace(e, request=here) for e in (awa, nap)]
    assert differing_parts(*on_here) == ("error.guide-code", "error.message")


def test_answers_out_of_step_after_an_extension_one_side_served_follow_from_it() -> None:
    extension = next(op for op in SPEC.requests.values() if op.extension)
    ext_input = FuzzInput(3, "manip.valid", (RequestStep(extension.opcode, b""),), "")
    later = FuzzInput(4, "manip.valid", (RequestStep(SPEC.request("here").opcode, b""),), "")
    refused = error(b"dispatch: C UOP Unknown opcode ~", b"\xa3\x00")
    here, angles = SPEC.request("here").opcode, SPEC.request("joint-angles").opcode
    a = {3: [response(1.0)], 4: [SideEvent("packet", ServerOp.RESPONSE, b"\x07\x00", request=here)]}
    b = {3: [refused], 4: [SideEvent("packet", ServerOp.RESPONSE, b"\x08\x00", request=angles)]}
    found = classify("s", compare([3, 4], a, b), [], [], {3: ext_input, 4: later})
    assert [f.cls for f in found] == ["allowed", "allowed"]
    alone = classify("s", compare([4], {4: a[4]}, {4: b[4]}), [], [], {4: later})
    assert [(f.cls, f.difference.parts) for f in alone] == [("unexplained", ("step",))]
