"""Cases report only the clauses they declare, at the clauses' levels.

The proof over every registered case is static (``tests/support/clause_scan.py`` reads the code each case can
reach, and resolves every clause it can name): running each case against the reference server with every
fault switch would reach only the branches some fault drives, and take minutes.  What the scan leaves to
other code it checks here too: the checkers' clauses are the transcript invariant's closed set, and the
stateful model's are declared by the stateful case.  At run time ``ctx.expect``/``ctx.fail`` raise at
once on an undeclared clause, and the runner turns any violation that slips past them into an error.
"""

from __future__ import annotations

import ast
import asyncio
import importlib
import inspect
import struct
import sys
from collections.abc import Awaitable, Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import manip.conformance.judge.checks as checks_module
import manip.conformance.judge.model as model_module
from manip.codecs.error_string import ErrorMessage
from manip.codecs.messages import encode_async, encode_error, encode_reply
from manip.conformance.judge.checks import TRANSCRIPT_CLAUSES, WirePacket, check_transcript
from manip.conformance.judge.model import MODEL_CLAUSES
from manip.conformance.judge.violation import Violation
from manip.conformance.output.coverage import coverage
from manip.conformance.suite.case import Case, CaseError, CaseFailure, UndeclaredClauseError, all_cases, case
from manip.conformance.suite.context import CaseContext, RunOptions
from manip.conformance.suite.invariants import COUGAR_LINK, INVARIANTS, TRANSCRIPT, attribution_problem
from manip.conformance.suite.runner import RunConfig, Runner
from manip.reference_server.driver import serve
from manip.spec import SPEC
from manip.spec.constants import ChaosOp, ServerOp
from tests.support.clause_scan import Index, Scanner, scan_all
from tests.support.contexts import bare_context

CASES = all_cases()


# ------------------------------------------------------------------------------- the static proof
def test_no_case_can_report_a_clause_it_does_not_declare() -> None:
    scans = scan_all(CASES)
    wrong: dict[str, dict[str, list[str]]] = {}
    for item in CASES:
        found = scans[item.id].clauses
        extra = {c: found[c] for c in sorted(set(found) - set(item.clauses))}
        if extra:
            wrong[item.id] = extra
    unresolved = {item.id: scans[item.id].unresolved for item in CASES if scans[item.id].unresolved}
    assert not unresolved, f"clause expressions the scan cannot resolve (make them resolvable): {unresolved}"
    assert not wrong, f"cases reporting clauses they do not declare (clause: where): {wrong}"


_PLANTED = """
from manip.conformance.suite.case import CaseFailure
from manip.conformance.cases._support import Evidence

TABLE = {"a": "async.codes", "b": "async.layout"}


def _helper(ctx, answer, clause, why):
    ctx.expect(answer, clause=clause, expected=why)


def _deep(ctx, name):
    _helper(ctx, True, "hand.data", name)


async def direct(ctx):
    ctx.expect(True, clause="here.transform")


async def through_helpers(ctx):
    _deep(ctx, "x")


async def table_lookup(ctx, key="a"):
    ctx.fail("x", clause=TABLE[key])


async def evidence_and_failures(ctx):
    raise Evidence("speed.range", "m", "e", "a")


async def raised(ctx):
    raise CaseFailure("m", clause="motion.abort")


async def relayed_and_attributed(ctx, failure=None):
    ctx.fail("m", clause=failure.clause)
    ctx.fail("m", clause="request.one-reply", invariant="transcript")


async def dynamic(ctx, name="x"):
    ctx.expect(True, clause=f"{name}.done")


def make(chosen, key):
    async def body(ctx):
        ctx.expect(True, clause=chosen)
        ctx.fail("x", clause=TABLE[key])

    return body
"""


@pytest.fixture
def planted(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Any:
    """A module of case-like functions, planted beside the real ones for the scanner to read."""
    (tmp_path / "planted_cases.py").write_text(_PLANTED)
    monkeypatch.syspath_prepend(str(tmp_path))
    module = importlib.import_module("planted_cases")
    yield module
    sys.modules.pop("planted_cases", None)


def _fake_case(function: Callable[..., Awaitable[None]], *clauses: str) -> Case:
    return Case(
        id="planted.case",
        function=function,
        clauses=clauses or ("request.one-reply",),
        level="MUST",
        technique="scripted",
        hazard="read-only",
        deadline=1.0,
        summary="",
        module=function.__module__,
    )


def test_the_scan_finds_what_a_case_reports(planted: Any) -> None:
    """The scan can fail: it finds clauses however they are passed, and flags what it cannot resolve."""
    live = importlib.import_module("manip.conformance.cases._support")
    scanner = Scanner(Index([planted, live]))

    def found(function: Callable[..., Awaitable[None]]) -> set[str]:
        return set(scanner.scan(_fake_case(function)).clauses)

    assert found(planted.direct) == {"here.transform"}
    assert found(planted.through_helpers) == {"hand.data"}
    assert found(planted.evidence_and_failures) == {"speed.range"}
    assert found(planted.raised) == {"motion.abort"}
    assert found(planted.relayed_and_attributed) == set()  # a relay, and an invariant's finding
    dynamic = scanner.scan(_fake_case(planted.dynamic))
    assert dynamic.unresolved and "name" in dynamic.unresolved[0]
    assert found(planted.table_lookup) == {"async.codes", "async.layout"}  # key unknown: any value
    assert found(planted.make("motion.reset", "b")) == {"motion.reset", "async.layout"}  # the closure's


def test_case_levels_agree_with_their_clauses() -> None:
    for item in CASES:
        strongest = max((SPEC.clauses[c].level for c in item.clauses), key=_strength)
        assert item.level == strongest, (item.id, item.level, strongest)
    # and no check overrides the level of the clause it names
    overrides = []
    for module in Index().modules:
        for node in ast.walk(ast.parse(inspect.getsource(module))):
            names = {kw.arg for kw in node.keywords} if isinstance(node, ast.Call) else set()
            if {"level", "clause"} <= names:
                overrides.append(f"{module.__name__}:{getattr(node, 'lineno', '?')}")
    assert not overrides, overrides


def _strength(level: str) -> int:
    return {"MUST": 3, "SHOULD": 2, "MAY": 1, "INFO": 0}[level]


def test_a_level_weaker_than_the_clause_is_refused() -> None:
    async def body(ctx: CaseContext) -> None:
        return None

    with pytest.raises(CaseError, match="strongest"):
        case("test.level.weak", clauses=["cougar.guts-reentry"], level="SHOULD")(body)


# ------------------------------------------------------------------------------- closed sets
def _reachable_literals(module: Any, start: str) -> set[str]:
    """Clause-id literals of the functions (and module constants) ``start`` can reach by name."""
    tree = ast.parse(inspect.getsource(module))
    named: dict[str, ast.AST] = {}
    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            named[node.name] = node
        elif isinstance(node, ast.Assign | ast.AnnAssign):
            target = node.targets[0] if isinstance(node, ast.Assign) else node.target
            if isinstance(target, ast.Name):
                named[target.id] = node
    seen: set[str] = set()
    todo = [start]
    while todo:
        name = todo.pop()
        if name in seen or name not in named:
            continue
        seen.add(name)
        for n in ast.walk(named[name]):
            if isinstance(n, ast.Name):
                todo.append(n.id)
            elif isinstance(n, ast.Attribute):
                todo.append(n.attr)
    literals = set()
    for name in seen - {"TRANSCRIPT_CLAUSES", "MODEL_CLAUSES"}:
        for n in ast.walk(named[name]):
            if isinstance(n, ast.Constant) and isinstance(n.value, str) and n.value in SPEC.clauses:
                literals.add(n.value)
    return literals


def test_the_transcript_invariant_names_every_clause_its_checkers_name() -> None:
    literals = _reachable_literals(checks_module, "check_transcript")
    assert literals, "the scan of checks.py found nothing"
    assert literals <= TRANSCRIPT_CLAUSES, sorted(literals - TRANSCRIPT_CLAUSES)
    assert TRANSCRIPT.clauses == TRANSCRIPT_CLAUSES
    assert all(c in SPEC.clauses for inv in INVARIANTS.values() for c in inv.clauses)


_SERVER_OPCODES = [0o200, 0o201, 0o202, 0o203, 0o204, 0o205, 0o250, 0o300, ChaosOp.CLS, ChaosOp.EOF]
_REQUESTS = [*sorted(SPEC.requests), 0o222, 0o277]


@st.composite
def _packets(draw: st.DrawFn) -> list[WirePacket]:
    out: list[WirePacket] = [WirePacket("s2c", ServerOp.RESPONSE, 1, 0, b"\x01\x00")]
    number = 2
    for _ in range(draw(st.integers(0, 12))):
        if draw(st.booleans()):
            opcode = draw(st.sampled_from(_REQUESTS))
            data = draw(st.binary(max_size=80))
            out.append(WirePacket("c2s", opcode, number, 0, data))
            number += 1
            continue
        opcode = draw(st.sampled_from(_SERVER_OPCODES))
        echo = draw(st.integers(0, number))
        kind = draw(st.sampled_from(["raw", "reply", "error", "async"]))
        if kind == "reply" and opcode == ServerOp.RESPONSE:
            op = SPEC.requests[draw(st.sampled_from(sorted(SPEC.requests)))]
            try:
                data = encode_reply(op.opcode, echo, **_values(op))
            except Exception:
                data = struct.pack("<H", echo)
        elif kind == "error":
            severity = draw(st.sampled_from(["F", "E", "C", "W", "X", ""]))
            message = ErrorMessage(
                "where", severity or "E", "ABC", draw(st.sampled_from(["m", "m ~", "$ m"]))
            )
            try:
                data = encode_error(ServerOp.NON_FATAL_ERROR, echo, message)
            except Exception:
                data = struct.pack("<H", echo) + b"where E ABC m"
        elif kind == "async":
            data = encode_async(echo, draw(st.integers(0, 4)), draw(st.integers(0, 3)), 1)
        else:
            data = draw(st.binary(max_size=40))
        out.append(WirePacket("s2c", opcode, 0, 0, data))
    return out


def _values(op: Any) -> dict[str, Any]:
    values: dict[str, Any] = {}
    for f in op.response.data.fields:
        ft = f.type
        if ft.element == "float":
            values[f.name] = 0.0 if ft.count == 1 else [0.0] * (ft.count or 0)
        elif ft.element in ("word", "int16", "small"):
            values[f.name] = 0 if ft.count == 1 else [0] * (ft.count or 0)
        else:
            values[f.name] = "(:a 1)"
    if op.response.form == "segment":
        values = {"segment": 1}
    return values


@settings(max_examples=300, deadline=None)
@given(_packets(), st.booleans())
def test_check_transcript_stays_inside_its_clauses(packets: list[WirePacket], complete: bool) -> None:
    for finding in check_transcript(packets, rfc_packet_no=1, complete=complete):
        assert finding.clause in TRANSCRIPT_CLAUSES, finding


def test_the_stateful_case_declares_every_clause_of_the_model() -> None:
    tree = ast.parse(inspect.getsource(model_module))
    literals = {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant) and n.value in SPEC.clauses}
    literals.discard("float.reserved-operand")  # compared with a codec error's clause, never reported
    assert literals <= MODEL_CLAUSES, sorted(literals - MODEL_CLAUSES)
    stateful = next(c for c in CASES if c.id == "stateful.arm-model")
    assert set(MODEL_CLAUSES) <= set(stateful.clauses)
    with pytest.raises(ValueError, match="MODEL_CLAUSES"):
        model_module.violation("describe.brand-name", "x", "y")


# ------------------------------------------------------------------------------- at run time
def _context(*clauses: str) -> CaseContext:
    return bare_context("t.ctx", *clauses)


def test_expect_and_fail_refuse_an_undeclared_clause_even_when_it_holds() -> None:
    ctx = _context("segment.number-increases")
    assert ctx.expect(True, clause="segment.number-increases")
    with pytest.raises(UndeclaredClauseError, match=r"case t\.ctx .*clause here\.transform"):
        ctx.expect(True, clause="here.transform")
    with pytest.raises(UndeclaredClauseError, match=r"motion\.abort"):
        ctx.fail("x", clause="motion.abort")
    with pytest.raises(UndeclaredClauseError, match="not one of its clauses"):
        ctx.fail("x", clause="motion.abort", invariant=TRANSCRIPT.name)
    with pytest.raises(CaseError, match="as MUST; the spec says SHOULD"):
        ctx.expect(True, clause="segment.number-increases", level="MUST")
    with pytest.raises(CaseFailure) as raised:
        ctx.fail("x", clause="response.echoes-request-number", invariant=TRANSCRIPT.name)
    assert raised.value.invariant == "transcript"
    assert not ctx.expect(False, clause="segment.number-increases")
    assert [s.invariant for s in ctx.recorded] == [None]


def test_check_attributes_the_checkers_findings_to_the_transcript_invariant() -> None:
    ctx = _context("describe.brand-name")
    ctx.check([Violation("m", "describe.brand-name"), Violation("m", "connect.initial-response-number")])
    assert [(s.clause, s.invariant) for s in ctx.recorded] == [
        ("describe.brand-name", None),
        ("connect.initial-response-number", "transcript"),
    ]
    assert not ctx.check([Violation("m", "response.echoes-request-number")])  # recorded, the case goes on
    assert (ctx.recorded[-1].clause, ctx.recorded[-1].invariant) == (
        "response.echoes-request-number",
        "transcript",
    )
    with pytest.raises(CaseFailure) as raised:
        ctx.check([Violation("m", "response.echoes-request-number")], stop=True)
    assert raised.value.invariant == "transcript"
    with pytest.raises(UndeclaredClauseError, match=r"here\.transform"):
        ctx.check([Violation("m", "here.transform")])  # no checker names it: a bug of the suite


def test_attribution_problem_names_case_and_clause() -> None:
    assert attribution_problem("a.b", ("x",), None, None) is None
    assert attribution_problem("a.b", ("here.transform",), "here.transform", None) is None
    assert attribution_problem("a.b", (), "cougar.word-link", COUGAR_LINK.name) is None
    problem = attribution_problem("a.b", ("x",), "here.transform", None)
    assert problem is not None and "a.b" in problem and "here.transform" in problem
    assert "unknown invariant" in (attribution_problem("a.b", (), "here.transform", "nope") or "")


async def _raises_undeclared(ctx: CaseContext) -> None:
    raise CaseFailure("a failure raised past ctx.fail", clause="motion.abort")


async def _expects_undeclared(ctx: CaseContext) -> None:
    ctx.expect(True, clause="motion.abort", expected="x")


async def _times_out(ctx: CaseContext) -> None:
    probe = await ctx.connect()
    await probe.reply(await probe.request("here", b"\x00"), timeout=0.0)  # a probe failure: an invariant's


def test_the_runner_turns_an_undeclared_report_into_an_error() -> None:
    def item(case_id: str, body: Callable[[CaseContext], Awaitable[None]]) -> Case:
        return Case(case_id, body, ("here.transform",), "MUST", "scripted", "read-only", 2.0, "", __name__)

    cases = [item("t.raised", _raises_undeclared), item("t.expected", _expects_undeclared)]
    cases.append(item("t.probe", _times_out))

    async def go() -> dict[str, tuple[str, str]]:
        async with serve("tcp://127.0.0.1:0") as server:
            options = RunOptions(reply_timeout=0.5, connect_timeout=1.0)
            config = RunConfig(options=replace(options, address=server.address), seed=1)
            report = await Runner(config, cases).run()
        return {r.id: (r.outcome, r.reason) for r in report.results}

    outcomes = asyncio.run(go())
    assert (
        outcomes["t.raised"][0] == "error"
        and "t.raised reported clause motion.abort" in outcomes["t.raised"][1]
    )
    assert outcomes["t.expected"][0] == "error" and "motion.abort" in outcomes["t.expected"][1]
    assert outcomes["t.probe"][0] in ("fail", "pass"), outcomes["t.probe"]  # never an error


# ------------------------------------------------------------------------------- coverage
def test_coverage_lists_invariants_beside_the_cases() -> None:
    rows = {row.clause: row for row in coverage(CASES)}
    assert rows["response.echoes-request-number"].invariants == (TRANSCRIPT.label,)
    assert rows["link.drv11j.framing"].invariants == (COUGAR_LINK.label,)
    assert rows["here.transform"].invariants == ()
    for row in rows.values():  # a case is listed for exactly the clauses it declares
        listed = {c for c in row.cases if ":" not in c}
        assert listed == {item.id for item in CASES if row.clause in item.clauses}, row.clause
