"""The conformance framework itself: selection patterns, pure checkers, case declaration, runner
semantics (known-failing, errors, deadlines, unreachable targets) and the report formats."""

from __future__ import annotations

import asyncio
import json
import struct
import xml.etree.ElementTree as ET
from collections.abc import Awaitable, Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from manip.codecs.error_string import ErrorMessage
from manip.codecs.messages import encode_error, encode_reply
from manip.conformance.cli import main as conform_main
from manip.conformance.judge.checks import (
    WirePacket,
    check_error_packet,
    check_reply,
    check_transcript,
    required_refusal,
)
from manip.conformance.judge.violation import missing, showing
from manip.conformance.output.report import load_schema, report_json, report_junit
from manip.conformance.suite.case import Case, CaseError, all_cases, case
from manip.conformance.suite.context import CaseContext, RunOptions
from manip.conformance.suite.results import ExitCode, RunReport
from manip.conformance.suite.runner import RunConfig, Runner, case_seed
from manip.conformance.suite.selection import PatternError, PatternSet, match_id
from manip.reference_server.driver import serve
from manip.spec import SPEC
from manip.spec.constants import ServerOp
from tests.support.json_schema import validate as _validate

HERE = SPEC.request("here").opcode


# ------------------------------------------------------------------------------------------- selection


@pytest.mark.parametrize(
    ("pattern", "case_id", "expected"),
    [
        ("server.reply.here", "server.reply.here", True),
        ("server.reply", "server.reply.here", True),
        ("server.*.here", "server.reply.here", True),
        ("server.*", "server.reply.here", True),
        ("*.here", "server.reply.here", False),
        ("**.here", "server.reply.here", True),
        ("server.reply.h*", "server.reply.here", True),
        ("server.reply.here.x", "server.reply.here", False),
        ("server.describe", "server.reply.here", False),
    ],
)
def test_pattern_matching(pattern: str, case_id: str, expected: bool) -> None:
    assert match_id(pattern, case_id) is expected


def test_pattern_file_and_stale_entries(tmp_path: Path) -> None:
    listing = tmp_path / "kf.txt"
    listing.write_text("# known failing\nserver.reply.here  # echo bug\n\nserver.nothing.*\n")
    patterns = PatternSet.of([f"@{listing}"], "--known-failing")
    assert [p.text for p in patterns.patterns] == ["server.reply.here", "server.nothing.*"]
    assert patterns.matches("server.reply.here")
    assert [p.text for p in patterns.unmatched()] == ["server.nothing.*"]
    with pytest.raises(PatternError):
        PatternSet.of([f"@{tmp_path / 'missing'}"], "--select")
    with pytest.raises(PatternError):
        PatternSet.of(["server..x"], "--select")


# ------------------------------------------------------------------------------------------- checkers


def _req(no: int, opcode: int = HERE, data: bytes = b"") -> WirePacket:
    return WirePacket("c2s", opcode, no, 0, data)


def _srv(opcode: int, data: bytes, no: int = 0) -> WirePacket:
    return WirePacket("s2c", opcode, no, 0, data)


def test_check_reply_catches_wrong_echo_and_layout() -> None:
    good = encode_reply("here", 7, transform=[1.0] * 12)
    assert check_reply(_req(7), [_srv(ServerOp.RESPONSE, good)]) == []
    wrong = check_reply(_req(7), [_srv(ServerOp.RESPONSE, good[:0] + struct.pack("<H", 8) + good[2:])])
    assert [f.clause for f in wrong] == ["response.echoes-request-number"]
    short = check_reply(_req(7), [_srv(ServerOp.RESPONSE, good[:-4])])
    assert {f.clause for f in short} == {"response.data-layout"}


def test_required_refusal_and_unknown_opcode_answered_normally() -> None:
    assert required_refusal(HERE, b"") is None
    assert required_refusal(HERE, b"\0\0").clause == "request.data-length"  # type: ignore[union-attr]
    assert required_refusal(0o277, b"").clause == "request.unknown-opcode"  # type: ignore[union-attr]
    speed = SPEC.request("set-speed").opcode
    assert required_refusal(speed, struct.pack("<HH", 0x8000, 0)).clause == "request.reserved-float"  # type: ignore[union-attr]
    findings = check_reply(_req(3, 0o277), [_srv(ServerOp.RESPONSE, struct.pack("<H", 3))])
    assert [f.clause for f in findings] == ["request.unknown-opcode"]


def test_check_error_packet_severity_and_format() -> None:
    ok = encode_error(
        ServerOp.NON_FATAL_ERROR, 1, ErrorMessage("dispatch", "C", "UOP", "Unknown opcode ~", (0o277,))
    )
    assert check_error_packet(_srv(ServerOp.NON_FATAL_ERROR, ok)) == []
    fatal_in_202 = encode_error(ServerOp.NON_FATAL_ERROR, 1, ErrorMessage("x", "F", "NZI", "bad"))
    assert [f.clause for f in check_error_packet(_srv(ServerOp.NON_FATAL_ERROR, fatal_in_202))] == [
        "error.severity-matches-opcode"
    ]
    fatal_in_205 = encode_error(ServerOp.ASYNCHRONOUS_WARNING, 0, ErrorMessage("x", "F", "NZI", "bad"))
    (finding,) = check_error_packet(_srv(ServerOp.ASYNCHRONOUS_WARNING, fatal_in_205))
    assert "severity F in an asynchronous-warning (0205) packet" in finding.message  # not "a asynchronous"
    no_colon = struct.pack("<H", 1) + b"dispatch C UOP Unknown"
    assert [f.clause for f in check_error_packet(_srv(ServerOp.NON_FATAL_ERROR, no_colon))] == [
        "error-string.format"
    ]
    long_code = encode_error(ServerOp.NON_FATAL_ERROR, 1, ErrorMessage("x", "Q", "LONG", "m ~", ()))
    clauses = {f.clause for f in check_error_packet(_srv(ServerOp.NON_FATAL_ERROR, long_code))}
    assert clauses == {"error-string.severity", "error-string.code"}


@pytest.mark.parametrize("text", [b"x: C UOP ~", b"xy: C UOP ~"])
def test_check_error_packet_layouts(text: bytes) -> None:
    """Erratum error-arg-layout: the numbers packed after the NUL or aligned by one zero pad conform; a pad
    where none is due, or a pad that is not zero, breaks error-string.arg-layout."""
    number = struct.pack("<H", 1)
    nul_end = 2 + len(text) + 1  # offset of the byte after the NUL in the packet data
    packed = number + text + b"\0" + struct.pack("<H", 0o277)
    pad = b"\0" if nul_end % 2 else b""
    aligned = number + text + b"\0" + pad + struct.pack("<H", 0o277)
    for data in (packed, aligned):
        assert check_error_packet(_srv(ServerOp.NON_FATAL_ERROR, data)) == [], data
    bad_pad = number + text + b"\0" + (b"\x07" if pad else b"\0") + struct.pack("<H", 0o277)
    clauses = [f.clause for f in check_error_packet(_srv(ServerOp.NON_FATAL_ERROR, bad_pad))]
    assert clauses[:1] == ["error-string.arg-layout"], (bad_pad, clauses)


def test_transcript_async_only_when_requested_and_free_joint() -> None:
    initial = _srv(ServerOp.RESPONSE, struct.pack("<H", 1))
    seg = _srv(ServerOp.ASYNCHRONOUS_RESPONSE, struct.pack("<4H", 2, 2, 0, 1))
    findings = check_transcript([initial, seg], rfc_packet_no=1)
    assert [f.clause for f in findings] == ["async.only-when-requested"]
    notify = SPEC.request("request-notifications").opcode
    asked = [
        initial,
        _req(2, notify, struct.pack("<H", 2)),
        _srv(ServerOp.RESPONSE, struct.pack("<H", 2)),
        seg,
    ]
    assert check_transcript(asked, rfc_packet_no=1) == []
    free = SPEC.request("free-joint").opcode
    executed = [
        initial,
        _req(2, free, struct.pack("<H", 1)),
        _srv(ServerOp.RESPONSE, struct.pack("<H", 2)),
        _req(3),
        _srv(ServerOp.RESPONSE, encode_reply("here", 3, transform=[1.0] * 12)),
    ]
    assert [f.clause for f in check_transcript(executed, rfc_packet_no=1)] == ["free-joint.replies"]
    assert [f.clause for f in check_transcript([], rfc_packet_no=1)] == ["connect.initial-response"]


def test_transcript_a_first_packet_answering_a_request_is_no_initial_response() -> None:
    """The first server packet carries a request's number, not the RFC's: the initial RESPONSE never
    came (connect.initial-response), rather than came with a wrong number."""
    answered = [_req(2), _srv(ServerOp.RESPONSE, encode_reply("here", 2, transform=[1.0] * 12))]
    assert [f.clause for f in check_transcript(answered, rfc_packet_no=1)][:1] == ["connect.initial-response"]
    wrong = [_srv(ServerOp.RESPONSE, struct.pack("<H", 5)), _req(2)]
    assert [f.clause for f in check_transcript(wrong, rfc_packet_no=1)] == ["connect.initial-response-number"]


def _describe_packets(number: int) -> list[WirePacket]:
    text = b"((:BRAND-NAME . 1))"
    return [_srv(ServerOp.RESPONSE, struct.pack("<H", number) + text)]


def test_transcript_a_reply_inside_a_multi_packet_reply_is_a_reply_out_of_turn() -> None:
    """A pipelined request's reply inside describe self's, whose terminator comes after it, is that
    request answered out of turn (request.one-reply); describe self's packets numbered as the next
    request, with no packet of its own number after them, are wrong numbers (multi.same-request-number)."""
    describe = SPEC.request("describe-self").opcode
    initial = _srv(ServerOp.RESPONSE, struct.pack("<H", 1))
    sent = [initial, _req(2, describe), _req(3, describe)]
    end = [_srv(ServerOp.RESPONSE, struct.pack("<H", n)) for n in (2, 3)]
    overtaken = [*sent, *_describe_packets(2), *_describe_packets(3), end[0], end[1]]
    clauses = [f.clause for f in check_transcript(overtaken, rfc_packet_no=1)]
    assert clauses[:1] == ["request.one-reply"], clauses
    renumbered = [*sent, *_describe_packets(2), *_describe_packets(3), end[1], *_describe_packets(3), end[1]]
    clauses = [f.clause for f in check_transcript(renumbered, rfc_packet_no=1)]
    assert clauses[:1] == ["multi.same-request-number"], clauses


def test_case_declaration_is_validated() -> None:
    async def body(ctx: CaseContext) -> None:
        return None

    with pytest.raises(CaseError, match="unknown clause"):
        case("test.bad.clause", clauses=["no.such.clause"])(body)
    with pytest.raises(CaseError, match="components"):
        case("Bad Id", clauses=["request.one-reply"])(body)
    with pytest.raises(CaseError, match="names no clause"):
        case("test.no.clause", clauses=[])(body)
    with pytest.raises(CaseError, match="not Puma extension opcodes"):  # Here is the guide's own
        case("test.bad.extension", clauses=["request.one-reply"], extensions=["here"])(body)
    with pytest.raises(CaseError, match="not Puma extension opcodes"):
        case("test.unknown.extension", clauses=["request.one-reply"], extensions=["no-such-opcode"])(body)


def test_cases_that_use_an_extension_say_so() -> None:
    """The cases whose first route is a Puma extension carry the mark, which the listing shows."""
    marked = {c.id: c.extensions for c in all_cases() if c.extensions}
    assert "request-notifications" in marked["server.speed.scales"]
    assert "reset-abort" in marked["server.motion.awa-reset-abort"]
    assert marked["server.reply.read-forces"] == ("read-forces",)
    assert "server.reply.here" not in marked
    assert all(SPEC.request(name).extension for names in marked.values() for name in names)
    result = CliRunner().invoke(conform_main, ["cases", "--format", "json", "--select", "server.speed.*"])
    listed = {item["id"]: item["extensions"] for item in json.loads(result.output)}
    assert listed["server.speed.scales"] == ["request-notifications"]
    assert listed["server.speed.bounds"] == []


def test_case_seed_depends_on_run_seed_and_id_only() -> None:
    assert case_seed(1, "a.b") == case_seed(1, "a.b")
    assert case_seed(1, "a.b") != case_seed(2, "a.b")
    assert case_seed(1, "a.b") != case_seed(1, "a.c")


# ------------------------------------------------------------------------------------------- runner


def _case(case_id: str, body: Callable[[CaseContext], Awaitable[None]], **kw: Any) -> Case:
    defaults: dict[str, Any] = {
        "clauses": ("request.one-reply",),
        "level": "MUST",
        "technique": "scripted",
        "hazard": "read-only",
        "deadline": 2.0,
        "summary": "",
        "module": __name__,
    }
    defaults.update(kw)
    return Case(id=case_id, function=body, **defaults)


async def _passes(ctx: CaseContext) -> None:
    probe = await ctx.connect()
    answer = await probe.call("here")
    ctx.expect(answer.is_response, clause="request.one-reply", expected="a reply", seen=answer)


async def _fails(ctx: CaseContext) -> None:
    probe = await ctx.connect()
    await probe.call("here")
    ctx.expect(False, clause="response.echoes-request-number", expected="x", seen=showing(b"\x01\x02", "y"))


async def _warns(ctx: CaseContext) -> None:
    ctx.expect(False, clause="segment.number-increases", expected="n+1", seen="n")


async def _crashes(ctx: CaseContext) -> None:
    raise RuntimeError("bug in the case")


async def _sleeps(ctx: CaseContext) -> None:
    await asyncio.sleep(10)


CASES = [
    _case("t.pass", _passes),
    _case("t.fail", _fails, clauses=("response.echoes-request-number",)),
    _case("t.warn", _warns, clauses=("segment.number-increases",), level="SHOULD"),
    _case("t.error", _crashes),
    _case("t.slow", _sleeps, deadline=0.2),
    _case("t.motion", _passes, hazard="motion"),
]


async def _fails_twice(ctx: CaseContext) -> None:
    probe = await ctx.connect()
    answer = await probe.call("here")
    ctx.expect(False, clause="response.echoes-request-number", expected="first", seen="a")
    ctx.expect(answer.is_response, clause="request.one-reply", expected="a reply")
    ctx.expect(False, clause="here.transform", expected="second", seen="b")


async def _stumbles(ctx: CaseContext) -> None:
    ctx.expect(False, clause="here.transform", expected="a transform", seen="garbage")
    raise KeyError("what the violation left")  # e.g. decoding what was not there


async def _requires(ctx: CaseContext) -> None:
    ctx.require(False, clause="here.transform", expected="a transform", seen=missing("nothing"))
    ctx.expect(False, clause="request.one-reply", expected="never checked")


async def _silent(ctx: CaseContext) -> None:
    await ctx.connect()


async def _unjudged(ctx: CaseContext) -> None:
    ctx.not_judged("needs a world that can arrange it (--world)")


MANY = [
    _case(
        "u.twice",
        _fails_twice,
        clauses=("response.echoes-request-number", "request.one-reply", "here.transform"),
    ),
    _case("u.stumbles", _stumbles, clauses=("here.transform",)),
    _case("u.requires", _requires, clauses=("here.transform", "request.one-reply")),
    _case("u.silent", _silent, clauses=("joint-angles.reply",)),
    _case("u.unjudged", _unjudged, clauses=("motion.abort",)),
    _case("u.skipped", _passes, clauses=("request.one-reply", "kill-power.done"), hazard="motion"),
]


def _run(
    select: list[str],
    *,
    known: list[str] = (),
    strict: bool = False,  # type: ignore[assignment]
    robot: str = "sim",
    address: str | None = None,
    cases: list[Case] = CASES,
) -> RunReport:
    async def go() -> RunReport:
        options = RunOptions(strict=strict, robot=robot, reply_timeout=0.5, connect_timeout=1.0)  # type: ignore[arg-type]
        if address is not None:
            config = RunConfig(
                options=replace(options, address=address),
                seed=3,
                select=PatternSet.of(select, "--select"),
                known_failing=PatternSet.of(known, "--known-failing"),
            )
            return await Runner(config, cases).run()
        async with serve("tcp://127.0.0.1:0") as server:
            config = RunConfig(
                options=replace(options, address=server.address),
                seed=3,
                select=PatternSet.of(select, "--select"),
                known_failing=PatternSet.of(known, "--known-failing"),
            )
            return await Runner(config, cases).run()

    return asyncio.run(go())


def _outcomes(report: RunReport) -> dict[str, str]:
    return {r.id: r.outcome for r in report.results}


def test_runner_outcomes_and_exit_codes() -> None:
    report = _run(["t"])
    assert _outcomes(report) == {
        "t.error": "error",
        "t.fail": "fail",
        "t.motion": "pass",
        "t.pass": "pass",
        "t.slow": "fail",
        "t.warn": "warn",
    }
    slow = next(r for r in report.results if r.id == "t.slow")
    assert slow.failure is not None and slow.failure.kind == "deadline"
    assert 0.15 < slow.duration < 1.5
    error = next(r for r in report.results if r.id == "t.error")
    assert "bug in the case" in error.traceback
    failed = next(r for r in report.results if r.id == "t.fail")
    assert failed.failure is not None and failed.failure.data == b"\x01\x02"
    assert "--select t.fail --seed 3" in failed.reproduce
    assert report.exit_code == ExitCode.NON_CONFORMANT
    assert all(c.alive for c in report.liveness)
    assert _run(["t.pass", "t.warn"]).exit_code == ExitCode.CONFORMANT
    assert _run(["t.warn"], strict=True).exit_code == ExitCode.NON_CONFORMANT
    assert _run(["t.pass", "t.error"]).exit_code == ExitCode.INTERNAL


def test_known_failing_semantics() -> None:
    report = _run(["t.fail", "t.pass"], known=["t.fail"])
    assert _outcomes(report)["t.fail"] == "known-fail"
    assert report.exit_code == ExitCode.CONFORMANT
    fixed = _run(["t.pass"], known=["t.pass"])
    assert _outcomes(fixed)["t.pass"] == "fixed"
    assert fixed.exit_code == ExitCode.NON_CONFORMANT
    stale = _run(["t.pass"], known=["t.no-such-case"])
    assert stale.exit_code == ExitCode.NON_CONFORMANT
    assert any("matches no case" in p for p in stale.problems)


def test_hardware_target_skips_motion_and_unreachable_target() -> None:
    report = _run(["t.motion"], robot="hardware")
    assert _outcomes(report) == {"t.motion": "skip"}
    dead = _run(["t.pass"], address="tcp://127.0.0.1:1")
    assert dead.exit_code == ExitCode.UNREACHABLE
    assert _outcomes(dead) == {"t.pass": "skip"}


def test_a_case_reports_every_violation_and_goes_on_until_it_cannot() -> None:
    report = _run(["u"], robot="hardware", cases=MANY)
    results = {r.id: r for r in report.results}
    twice = results["u.twice"]
    assert twice.outcome == "fail"
    assert [v.clause for v in twice.violations] == ["response.echoes-request-number", "here.transform"]
    assert set(twice.reached) == {"response.echoes-request-number", "request.one-reply", "here.transform"}
    stumbled = results["u.stumbles"]  # an exception after a violation follows it: a fail, not an error
    assert stumbled.outcome == "fail" and not stumbled.traceback
    assert any("could not go on" in n and "what the violation left" in n for n in stumbled.notes)
    required = results["u.requires"]  # require stops the case: the check after it never ran
    assert [v.clause for v in required.violations] == ["here.transform"]
    assert "request.one-reply" not in required.reached


def test_every_clause_has_one_status_and_the_verdict_says_how_many_were_judged() -> None:
    report = _run(["u", "t.pass"], robot="hardware", cases=[*MANY, *CASES])
    statuses = report.clause_statuses()
    got = {c: v.status for c, v in statuses.items()}
    assert got == {
        "response.echoes-request-number": "broken",
        "here.transform": "broken",
        "request.one-reply": "held",  # reached by t.pass and u.twice
        "joint-angles.reply": "not-exercised",  # u.silent passed without a check reaching it
        "kill-power.done": "not-exercised",  # its one case was skipped
        "motion.abort": "not-judged",
    }
    assert statuses["motion.abort"].hint == "--world" and "u.unjudged" in statuses["motion.abort"].why
    assert "u.silent" in statuses["joint-angles.reply"].why
    assert report.not_judged_clauses() == ["motion.abort"]
    data = json.loads(json.dumps(report_json(report)))
    must = data["completeness"]["levels"]["MUST"]
    assert (must["judged"], must["total"], must["not-exercised"]) == (3, 6, 2)
    assert data["completeness"]["text"] == "3 of 6 MUST clauses judged"
    assert {c["clause"]: c["status"] for c in data["clause_status"]} == got
    root = ET.fromstring(ET.tostring(report_junit(report)))
    clauses = next(s for s in root.iter("testsuite") if s.get("name") == "clauses")
    rows = {tc.get("name"): tc for tc in clauses.iter("testcase")}
    assert rows["here.transform"].find("failure") is not None
    assert (
        rows["request.one-reply"].find("failure") is None
        and rows["request.one-reply"].find("skipped") is None
    )
    skipped = rows["motion.abort"].find("skipped")
    assert skipped is not None and "not-judged" in (skipped.get("message") or "")


# ------------------------------------------------------------------------------------------- reports


def test_json_report_matches_schema_and_junit_parses() -> None:
    report = _run(["t"])
    data = json.loads(json.dumps(report_json(report)))
    schema = load_schema()
    _validate(data, schema, schema)
    by_id = {c["id"]: c for c in data["cases"]}
    assert by_id["t.fail"]["bytes"] == "0102" and by_id["t.fail"]["expected"] == "x"
    assert by_id["t.pass"]["packets"], "the packets both ways are in the report"
    broken = dict(data, exit_code=7)
    with pytest.raises(AssertionError):
        _validate(broken, schema, schema)
    xml = ET.tostring(report_junit(report))
    root = ET.fromstring(xml)
    cases = {tc.get("name"): tc for tc in root.iter("testcase")}
    assert cases["t.fail"].find("failure") is not None
    assert cases["t.error"].find("error") is not None
    assert cases["t.pass"].find("failure") is None


def test_a_refused_puma_extension_is_judged_by_a_target_that_serves_the_extensions() -> None:
    from manip.conformance.suite.results import judging_hint

    reason = "the target serves no wrist (it refused 0240, wrist version, a Puma extension: C UOP)"
    assert judging_hint(reason) == "a target that serves the Puma extensions"
    assert judging_hint("the world offers no obstacle: run with --world") == "--world"
