"""The suite against the reference server: the clean server passes every case, injected faults are
caught by the cases named for them, the CLI's exit codes and reports, and clause coverage."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from click.testing import CliRunner

from manip.codecs.error_string import ErrorMessage
from manip.conformance.cli import main
from manip.conformance.output.coverage import coverage, gaps
from manip.conformance.suite.case import all_cases
from manip.conformance.suite.results import ExitCode, RunReport
from manip.conformance.suite.selection import PatternSet
from manip.reference_server import FaultSet, ServerConfig, errors
from manip.reference_server.errors import RequestError
from tests.support.suite import run_simulated


def _run(faults: list[str], select: list[str], *, strict: bool = False) -> RunReport:
    """The selected cases against the embedded target, in virtual time (the timing cases' verdicts then
    never depend on how busy the machine is)."""
    config_server = ServerConfig(faults=FaultSet.parse(faults))
    select_cases = PatternSet.of(select, "--select")
    options = {"strict": strict}
    return run_simulated(all_cases(), config_server, seed=11, options=options, select=select_cases)


@pytest.mark.slow
@pytest.mark.timeout(600)  # the whole suite in virtual time: about 30 s of CPU, longer on a loaded host
def test_clean_reference_server_passes_every_case() -> None:
    report = _run([], ["server", "property"], strict=True)  # the stateful cases are tested by their module
    bad = {
        r.id: (r.outcome, r.failure, r.reason)
        for r in report.results
        if r.outcome not in ("pass", "skip", "not-judged")
    }
    assert not bad
    # the embedded target has the simulated wrist and its world: every case is judged but one
    unjudged = {r.id for r in report.results if r.outcome == "not-judged"}
    assert unjudged == {"server.ncp.broken"}  # it needs the run to know the target's timer
    assert report.exit_code == ExitCode.CONFORMANT
    skipped = {r.id for r in report.results if r.outcome == "skip"}
    assert not any(s.startswith(("server.reply.here", "server.describe", "server.negative")) for s in skipped)


@pytest.mark.parametrize(
    ("fault", "select", "case_id", "clause"),
    [
        (
            "wrong-request-number",
            ["server.reply.here"],
            "server.reply.here",
            "response.echoes-request-number",
        ),
        (
            "no-describe-terminator",
            ["server.describe.reply-shape"],
            "server.describe.reply-shape",
            "multi.terminated-by-empty",
        ),
        (
            "wrong-severity",
            ["server.error.severity-matches-opcode"],
            "server.error.severity-matches-opcode",
            "request.unknown-opcode",
        ),
        (
            "unknown-opcode-answered",
            ["server.negative.unknown-opcodes"],
            "server.negative.unknown-opcodes",
            "request.unknown-opcode",
        ),
        (
            "length-unchecked",
            ["server.negative.data-length.safe"],
            "server.negative.data-length.safe",
            "request.data-length",
        ),
        ("no-jor", ["server.motion.jor"], "server.motion.jor", "motion.checked-before-queue"),
        ("swap-tor-jor", ["server.motion.jor"], "server.motion.jor", "motion.checked-before-queue"),
        ("swap-tor-jor", ["server.motion.tor-limits"], "server.motion.tor-limits", "solve-forwards.errors"),
        ("speed-unchecked", ["server.speed.bounds"], "server.speed.bounds", "speed.range"),
        (
            "free-joint-executes",
            ["server.free-joint.discard"],
            "server.free-joint.discard",
            "free-joint.awaits-next-packet",
        ),
        ("swapped-float-words", ["server.float.here-consistent"], "server.float.here-consistent", None),
        (
            "no-protocol-version",
            ["server.describe.protocol-version"],
            "server.describe.protocol-version",
            "describe.protocol-version",
        ),
        (
            "unrequested-async",
            ["server.async.segment-completed"],
            "server.async.segment-completed",
            "async.only-when-requested",
        ),
        ("no-nap", ["server.motion.nap"], "server.motion.nap", "motion.no-power"),
        ("awa-ignored", ["server.motion.awa-reset-abort"], "server.motion.awa-reset-abort", "motion.abort"),
        (
            "no-initial-response",
            ["server.connect.initial-response"],
            "server.connect.initial-response",
            "connect.initial-response",
        ),
        (
            "describe-wrong-dof",
            ["server.describe.degrees-of-freedom"],
            "server.describe.degrees-of-freedom",
            "describe.dof-joint-vectors",
        ),
    ],
)
def test_fault_is_caught_by_its_case(fault: str, select: list[str], case_id: str, clause: str | None) -> None:
    report = _run([fault], select)
    result = next(r for r in report.results if r.id == case_id)
    assert result.outcome == "fail", (result.outcome, result.reason, result.violations)
    if clause is not None:
        assert result.failure is not None and result.failure.clause == clause, result.failure
    assert report.exit_code == ExitCode.NON_CONFORMANT


def test_refusing_everything_after_an_abort_warns_only() -> None:
    # E.2: "no further commands will be processed until a reset operation is requested" (erratum awa-scope)
    report = _run(["awa-refuses-all"], ["server.motion.awa-reset-abort"])
    (result,) = report.results
    assert result.outcome == "warn", (result.outcome, result.reason, result.violations)
    assert {v.clause for v in result.violations} == {"motion.abort-serves-others"}
    assert report.exit_code == 0


def test_a_server_with_its_own_code_for_unknown_opcodes_is_judged_by_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # E.2 names no code for an unknown opcode: a server written from the guide picks its own
    def own_code(opcode: int) -> RequestError:
        return RequestError(ErrorMessage("cmd", "C", "UNK", "No such command ~", (opcode,)))

    monkeypatch.setattr(errors, "unknown_opcode", own_code)
    selected = ["server.describe.operations-served", "server.negative.unknown-opcodes"]
    report = _run([], selected)
    outcomes = {r.id: (r.outcome, [v.message for v in r.violations]) for r in report.results}
    assert {o for o, _ in outcomes.values()} == {"pass"}, outcomes
    served = next(r for r in report.results if r.id == "server.describe.operations-served")
    assert any("with C UNK" in n for n in served.notes)


def test_fatal_without_close_is_caught_with_a_calibration_failure() -> None:
    honest = _run(["calibrate-nzi"], ["server.error.fatal-then-close"])
    assert [r.outcome for r in honest.results] == ["pass"]
    faulty = _run(["calibrate-nzi", "fatal-without-close"], ["server.error.fatal-then-close"])
    result = faulty.results[0]
    assert result.outcome == "fail" and result.failure is not None
    assert result.failure.clause == "error.fatal-then-close"


# ------------------------------------------------------------------------------------------- the CLI


def test_cli_exit_codes_and_reports(tmp_path: Path) -> None:
    runner = CliRunner()
    json_path, junit_path = tmp_path / "r.json", tmp_path / "r.xml"
    ok = runner.invoke(
        main,
        [
            "run",
            "--select",
            "server.describe",
            "--seed",
            "4",
            "-q",
            "--json",
            str(json_path),
            "--junit",
            str(junit_path),
        ],
    )
    assert ok.exit_code == 0, ok.output
    assert "seed 4" in ok.output
    data = json.loads(json_path.read_text())
    assert data["exit_code"] == 0 and data["seed"] == 4 and data["cases"]
    assert ET.parse(junit_path).getroot().tag == "testsuites"

    bad = runner.invoke(
        main,
        [
            "run",
            "--select",
            "server.reply.here",
            "--server-fault",
            "wrong-request-number",
            "-q",
            "--seed",
            "4",
            "--json",
            str(json_path),
        ],
    )
    assert bad.exit_code == 1, bad.output
    case = json.loads(json_path.read_text())["cases"][0]
    assert (
        case["outcome"] == "fail"
        and case["bytes"]
        and "--server-fault wrong-request-number" in case["reproduce"]
    )

    assert runner.invoke(main, ["run", "--no-such-option"]).exit_code == 2
    assert runner.invoke(main, ["run", "ftp://x"]).exit_code == 2
    assert runner.invoke(main, ["run", "--select", "a..b"]).exit_code == 2
    assert runner.invoke(main, ["run", "--server-fault", "no-such-fault"]).exit_code == 2

    dead = runner.invoke(
        main, ["run", "tcp://127.0.0.1:1", "-q", "--reply-timeout", "0.2", "--json", str(json_path)]
    )
    assert dead.exit_code == 3, dead.output
    assert json.loads(json_path.read_text())["verdict"] == "target unreachable"


def test_cli_cases_and_coverage() -> None:
    runner = CliRunner()
    listed = json.loads(runner.invoke(main, ["cases", "--format", "json"]).output)
    ids = {c["id"] for c in listed}
    assert {"server.reply.here", "server.describe.reply-shape", "server.negative.unknown-opcodes"} <= ids
    assert all(c["clauses"] and c["level"] in ("MUST", "SHOULD", "MAY", "INFO") for c in listed)
    result = runner.invoke(main, ["coverage", "--format", "json"])
    data = json.loads(result.output)
    # CI's coverage gate: every MUST clause in the default scope has at least one case.
    assert data["uncovered_must"] == [] and result.exit_code == 0, data["uncovered_must"]


def test_every_server_must_clause_has_a_case() -> None:
    rows = coverage(all_cases(), {"server", "both"})
    assert [r.clause for r in gaps(rows)] == []


def test_cli_broken_after_gives_the_embedded_server_the_timer_and_the_case_its_wait(tmp_path: Path) -> None:
    json_path = tmp_path / "r.json"
    result = CliRunner().invoke(
        main,
        ["run", "--select", "server.ncp.broken", "--broken-after", "1", "-q", "--json", str(json_path)],
    )
    assert result.exit_code == 0, result.output
    case = json.loads(json_path.read_text())["cases"][0]
    assert case["outcome"] == "pass" and "--broken-after 1" in case["reproduce"]
