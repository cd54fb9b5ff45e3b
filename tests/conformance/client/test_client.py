"""manip-conform client: the contract's parsing, the reference client's harness passing every case (TCP
and CHUDP), unsupported cases, and clear verdicts for harnesses that crash, hang, write garbage, omit
``done`` or never say hello."""

from __future__ import annotations

import asyncio
import json
import os
import sys
import textwrap
from pathlib import Path

import pytest
from click.testing import CliRunner

from manip.conformance.cli import main
from manip.conformance.client.cli import client_cases
from manip.conformance.client.contract import ContractError, parse_hello, parse_result
from manip.conformance.client.runner import DEFAULT_CLIENT_TIMEOUT, ClientRunConfig, run_client_suite
from manip.conformance.suite.context import RunOptions
from manip.conformance.suite.results import CaseResult, ExitCode, RunReport
from manip.conformance.suite.selection import PatternSet
from manip.spec import SPEC

HARNESS = [sys.executable, "-m", "manip.reference_client.harness"]
SEED = 1985


def run(
    argv: list[str], *, link: str = "tcp", select: tuple[str, ...] = (), slack: float = 10.0
) -> RunReport:
    config = ClientRunConfig(
        argv=argv,
        link=link,
        seed=SEED,
        options=RunOptions(reply_timeout=1.0),
        select=PatternSet.of(select, "--select"),
        slack=slack,
    )
    return asyncio.run(run_client_suite(config, client_cases()))


def outcomes(report: RunReport) -> dict[str, str]:
    return {r.id: r.outcome for r in report.results}


def failures(report: RunReport) -> str:
    lines = []
    for r in report.results:
        if r.outcome not in ("pass", "skip"):
            lines.append(f"{r.id}: {r.outcome} {r.reason} {[str(v) for v in r.violations]}")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------ the contract


def test_hello_needs_contract_1_links_and_operations() -> None:
    hello = parse_hello(
        json.dumps(
            {
                "type": "hello",
                "contract": 1,
                "name": "x",
                "version": "1",
                "links": ["tcp"],
                "operations": ["connect", "here"],
            }
        )
    )
    assert hello.operations == {"connect", "here"} and hello.features == frozenset()
    with pytest.raises(ContractError, match="contract 2"):
        parse_hello(
            json.dumps(
                {"type": "hello", "contract": 2, "name": "x", "version": "1", "links": [], "operations": []}
            )
        )
    with pytest.raises(ContractError, match="first line must be a hello"):
        parse_hello(json.dumps({"type": "done", "case": "x"}))
    with pytest.raises(ContractError, match="not JSON"):
        parse_hello("hello")


@pytest.mark.parametrize(
    ("line", "problem"),
    [
        ('{"type": "reply", "case": "other", "op": 1, "values": {}, "raw": {}}', "while case"),
        ('{"type": "teapot", "case": "c"}', "unknown result type"),
        ('{"type": "state", "case": "c", "op": 0, "state": "melted"}', "state"),
        ('{"type": "error", "case": "c", "op": 1, "origin": "client", "kind": "oops"}', "client error kind"),
        ('{"type": "async", "case": "c", "op": null, "code": "1"}', "integer"),
        ("[1, 2]", "not a JSON object"),
    ],
)
def test_results_outside_the_contract_are_refused(line: str, problem: str) -> None:
    with pytest.raises(ContractError, match=problem):
        parse_result(line, "c")


# ------------------------------------------------------------------------------------------ the reference


def test_the_reference_harness_passes_every_case_over_tcp() -> None:
    report = run(HARNESS)
    assert report.exit_code == ExitCode.CONFORMANT, failures(report)
    got = outcomes(report)
    assert len(got) == len(client_cases()) >= 60
    assert {o for o in got.values()} <= {"pass", "skip"}
    assert got["client.chudp.duplicate-reorder"] == "skip"  # TCP neither duplicates nor reorders


def test_the_reference_harness_passes_over_chudp() -> None:
    report = run(
        HARNESS,
        link="chudp",
        select=(
            "client.chudp.**",
            "client.describe.**",
            "client.async.**",
            "client.ncp.**",
            "client.conn.**",
        ),
    )
    got = outcomes(report)
    assert report.exit_code == ExitCode.CONFORMANT, failures(report)
    assert got["client.chudp.duplicate-reorder"] == "pass"


def test_the_reference_harness_passes_over_chaosd_with_the_judge_as_the_daemon() -> None:
    report = run(HARNESS, link="chaosd", select=("client.describe.**", "client.conn.**", "client.error.**"))
    got = outcomes(report)
    assert report.exit_code == ExitCode.CONFORMANT, failures(report)
    assert got["client.conn.lost-mid-request"] == "pass"  # a stream link: the drop is seen at once
    hello_links = [r for r in report.results if r.outcome == "unsupported"]
    assert not hello_links  # the reference harness dials chaosd


def test_operations_the_harness_does_not_declare_are_unsupported_never_passed() -> None:
    only = "connect,close,wait,await-replies,here,joint-angles"
    report = run([*HARNESS, "--operations", only], select=("client.reply.**", "client.describe.**"))
    got = outcomes(report)
    assert got["client.reply.here"] == "pass" and got["client.reply.joint-angles"] == "pass"
    assert got["client.describe.split-mid-token"] == "unsupported"
    assert got["client.reply.read-forces"] == "unsupported"
    assert report.exit_code == ExitCode.CONFORMANT  # unsupported fails nothing; it passes nothing either
    assert report.counts()["unsupported"] == sum(o == "unsupported" for o in got.values()) > 0


# ------------------------------------------------------------------------------------------ bad harnesses

HELLO = json.dumps(
    {
        "type": "hello",
        "contract": 1,
        "name": "bad",
        "version": "0",
        "links": ["tcp"],
        "operations": ["connect", "close", "here", "joint-angles"],
    }
)


def _script(tmp_path: Path, body: str) -> list[str]:
    path = tmp_path / "harness.py"
    path.write_text(
        "import json, sys, time\n"
        f"print({HELLO!r}, flush=True)\n"
        "for line in sys.stdin:\n"
        "    case = json.loads(line)['case']\n" + textwrap.indent(textwrap.dedent(body), "    ")
    )
    return [sys.executable, str(path)]


@pytest.mark.waits
@pytest.mark.parametrize(
    ("body", "words", "kind"),
    [
        ("sys.exit(3)\n", "crashed", "closed"),
        ("time.sleep(60)\n", "hung", "deadline"),
        ("print('this is not json', flush=True)\n", "garbage", "malformed"),
        (
            "print(json.dumps({'type': 'state', 'case': case, 'op': 0, 'state': 'connected'}), flush=True)\n"
            "time.sleep(60)\n",
            "hung",
            "deadline",
        ),
    ],
    ids=["crash", "hang", "garbage", "no-done"],
)
def test_a_broken_harness_gets_a_clear_verdict_not_a_hang(
    tmp_path: Path, body: str, words: str, kind: str
) -> None:
    report = run(
        _script(tmp_path, body), select=("client.reply.here", "client.reply.joint-angles"), slack=1.0
    )
    assert [r.outcome for r in report.results] == ["fail", "fail"]  # restarted for the second case
    for result in report.results:
        assert result.failure is not None
        assert words in result.failure.message and result.failure.kind == kind
    assert report.exit_code == ExitCode.NON_CONFORMANT


def test_a_harness_without_hello_is_unreachable(tmp_path: Path) -> None:
    path = tmp_path / "silent.py"
    path.write_text("import sys\nprint('oops', file=sys.stderr)\nsys.exit(1)\n")
    report = run([sys.executable, str(path)], select=("client.reply.here",))
    assert report.exit_code == ExitCode.UNREACHABLE
    assert "exited before its hello" in report.problems[0] and "oops" in report.problems[0]


# ------------------------------------------------------------------------------------------ the command


def test_the_command_runs_selects_and_writes_reports(tmp_path: Path) -> None:
    out = tmp_path / "r.json"
    junit = tmp_path / "r.xml"
    result = CliRunner().invoke(
        main,
        [
            "client",
            "--seed",
            "7",
            "--select",
            "client.reply.here",
            "--json",
            str(out),
            "--junit",
            str(junit),
            "--",
            *HARNESS,
        ],
    )
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert [c["id"] for c in data["cases"]] == ["client.reply.here"]
    assert data["counts"]["pass"] == 1 and "unsupported" in data["counts"]
    assert "client.reply.here" in junit.read_text()
    (case,) = data["cases"]
    instruction_ops = 3  # connect, here, close: the contract's deadline is their timeouts plus 10 s
    assert case["harness_deadline"] == pytest.approx(instruction_ops * DEFAULT_CLIENT_TIMEOUT + 10.0)


def test_a_client_case_tells_its_time_budget_from_the_contracts_deadline() -> None:
    """ "took 13.22 s of its 5 s deadline" read as if the harness had overrun the contract's deadline;
    a client case names both, a server case only its own."""
    result = CaseResult(
        "client.x.y", (), "MUST", "scripted", "read-only", "", "pass", 1, 5.0, 13.22, harness_deadline=30.0
    )
    assert result.timing() == (
        "took 13.22 s of its 5 s time budget; the contract's deadline for the harness was 30 s"
    )
    result.harness_deadline = None
    assert result.timing() == "took 13.22 s of its 5 s time budget"


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full")
def test_a_report_that_cannot_be_written_is_a_usage_error_naming_it(tmp_path: Path) -> None:
    """A disk found full at the end of the run: one line naming the path, exit 2, the other report
    still written, never a traceback."""
    out = tmp_path / "r.json"
    args = ["client", "--seed", "7", "--select", "client.reply.here", "--junit", "/dev/full"]
    result = CliRunner().invoke(main, [*args, "--json", str(out), "--", *HARNESS])
    assert result.exit_code == 2, result.output
    assert "cannot write /dev/full" in result.output and "Traceback" not in result.output
    assert json.loads(out.read_text())["cases"][0]["id"] == "client.reply.here"


def test_the_command_refuses_selections_of_nothing() -> None:
    result = CliRunner().invoke(main, ["client", "--select", "client.nothing.here", "--", *HARNESS])
    assert result.exit_code == 2 and "matches no case" in result.output
    result = CliRunner().invoke(
        main, ["client", "--clause", "client.fatal-ends", "--select", "client.reply.**", "--", *HARNESS]
    )
    assert result.exit_code == 2


def test_coverage_of_the_client_party_has_no_gap() -> None:
    result = CliRunner().invoke(main, ["coverage", "--party", "client", "--format", "json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    client_rows = [r for r in data["clauses"] if r["party"] == "client"]
    assert client_rows and data["uncovered_must"] == []
    for row in client_rows:
        if SPEC.clauses[row["clause"]].judged_from == "recording":  # what a client sends of its own accord
            assert any(c.startswith("verify:") for c in row["cases"]), row
            assert any(c.startswith("client.choice.") for c in row["cases"]), row  # and live
        assert any(c.startswith("client.") for c in row["cases"]), row
    assert {c.judged_from for c in SPEC.clauses.values() if c.party == "client"} == {"live", "recording"}
