"""``manip-conform verify``: golden captures pass, captures of faulty servers fail with the clause, the
report is the suite's (schema, exit codes), ``run --record`` makes a capture verify passes."""

from __future__ import annotations

import asyncio
import json
import struct
from pathlib import Path

import pytest
from click.testing import CliRunner

from manip.captures import read_session
from manip.codecs.messages import encode_request
from manip.conformance.cli import main
from manip.conformance.judge.checks import WirePacket
from manip.conformance.judge.client_checks import check_client_guards, check_client_request
from manip.conformance.output.coverage import coverage, gaps
from manip.conformance.output.report import load_schema, report_json
from manip.conformance.replay.against import ReplayOptions, replay_capture
from manip.conformance.replay.cli import recording
from manip.conformance.replay.verify import fatal_close_violations, verify_capture, wire_packets
from manip.conformance.suite.case import all_cases
from manip.conformance.suite.embedded import EmbeddedServer
from manip.reference_server import FaultSet, ServerConfig
from manip.spec import SPEC
from manip.spec.constants import AsyncCondition, ChaosOp, ServerOp
from tests.support.json_schema import validate as _validate
from tests.support.paths import ROOT

GOLDEN = ROOT / "captures"
NAMES = ("describe-self", "motion", "errors")


def record_replay(name: str, fault: str, out: Path) -> None:
    """Record (client side) a replay of golden capture ``name`` against a server with ``fault`` on."""

    async def job() -> None:
        with recording(out, how="test") as wrap:
            options = ReplayOptions(reply_timeout=0.5, async_timeout=2.0, settle=0.05, wrap_link=wrap)
            with EmbeddedServer(ServerConfig(faults=FaultSet.parse([fault])), time_scale=20) as address:
                await replay_capture(GOLDEN / f"{name}.mcap", address, options)

    asyncio.run(job())


@pytest.mark.parametrize("name", NAMES)
def test_golden_capture_verifies(name: str) -> None:
    report = verify_capture(GOLDEN / f"{name}.mcap")
    assert report.exit_code == 0, [(r.id, r.violations) for r in report.results if r.violations]
    outcomes = {r.id.rsplit(".", 1)[1]: r.outcome for r in report.results}
    assert outcomes["initial-response"] == outcomes["request-numbers"] == "pass"
    schema = load_schema()
    _validate(json.loads(json.dumps(report_json(report))), schema, schema)


def test_wire_packets_keep_data_and_closes_in_order() -> None:
    session = read_session(GOLDEN / "describe-self.mcap")
    packets = wire_packets(session)
    assert [p.opcode for p in packets if p.direction == "c2s" and not p.is_close] == [0o200, 0o201]
    assert all(p.opcode >= ChaosOp.DAT or p.is_close for p in packets)
    assert packets[0].direction == "s2c" and packets[0].data == b"\x01\x00"  # the initial RESPONSE
    assert any(p.is_close for p in packets)


@pytest.mark.parametrize(
    ("name", "fault", "clause", "family"),
    [
        ("motion", "wrong-request-number", "response.echoes-request-number", "request-numbers"),
        ("describe-self", "no-describe-terminator", "multi.terminated-by-empty", "describe"),
        ("errors", "wrong-severity", "error.severity-matches-opcode", "error-strings"),
    ],
)
def test_capture_of_a_faulty_server_fails_verify(
    tmp_path: Path, name: str, fault: str, clause: str, family: str
) -> None:
    out = tmp_path / "faulty.mcap"
    record_replay(name, fault, out)
    report = verify_capture(out)
    assert report.exit_code == 1
    failed = {r.id: r for r in report.results if r.outcome in ("fail", "warn")}
    assert f"verify.session-1.{family}" in failed, sorted(failed)
    violation = next(v for v in failed[f"verify.session-1.{family}"].violations if v.clause == clause)
    assert violation.data  # the bytes of the offending packet


def test_fatal_error_then_client_close_is_a_finding() -> None:
    fatal = WirePacket("s2c", ServerOp.FATAL_ERROR, 5, 3, b"\x03\x00x: F ABC boom")
    client_close = WirePacket("c2s", ChaosOp.CLS, 0, 0, b"bye")
    server_close = WirePacket("s2c", ChaosOp.CLS, 0, 0, b"bye")
    (finding,) = fatal_close_violations([fatal, client_close, server_close])
    assert finding.clause == "error.fatal-then-close"
    assert fatal_close_violations([fatal, server_close, client_close]) == []


def test_cli_exit_codes_and_reports(tmp_path: Path) -> None:
    runner = CliRunner()
    json_path, junit_path = tmp_path / "r.json", tmp_path / "r.xml"
    ok = runner.invoke(
        main, ["verify", str(GOLDEN / "errors.mcap"), "--json", str(json_path), "--junit", str(junit_path)]
    )
    assert ok.exit_code == 0, ok.output
    data = json.loads(json_path.read_text())
    schema = load_schema()
    _validate(data, schema, schema)
    assert data["verdict"] == "conformant" and all(c["kind"] == "verify" for c in data["cases"])
    refusals = next(c for c in data["cases"] if c["id"] == "verify.session-1.refusals")
    assert refusals["outcome"] == "pass" and "request.unknown-opcode" in refusals["clauses"]
    assert "<testsuites" in junit_path.read_text()
    assert runner.invoke(main, ["verify", str(tmp_path / "missing.mcap")]).exit_code == 2
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(b"not an mcap file at all")
    unreadable = runner.invoke(main, ["verify", str(garbage), "--json", str(json_path)])
    assert unreadable.exit_code == 3 and "not an MCAP file" in unreadable.output
    data = json.loads(json_path.read_text())
    _validate(data, schema, schema)
    assert data["verdict"] == "capture unusable"  # not "target unreachable": there is no target
    short = tmp_path / "short.mcap"
    short.write_bytes(b"\x89MC")
    assert "ends before an MCAP header" in runner.invoke(main, ["verify", str(short)]).output
    assert runner.invoke(main, ["verify", str(GOLDEN / "errors.mcap"), "--session", "2"]).exit_code == 3


def test_run_record_produces_a_capture_that_verifies(tmp_path: Path) -> None:
    out = tmp_path / "run.mcap"
    args = ["run", "-q", "--seed", "3", "--select", "server.reply", "--select", "server.free-joint"]
    result = CliRunner().invoke(main, [*args, "--record", str(out)])
    assert result.exit_code == 0, result.output
    report = verify_capture(out)
    assert report.exit_code == 0, [(r.id, r.violations) for r in report.results if r.violations]
    sessions = {r.id.split(".")[1] for r in report.results}
    assert len(sessions) > 5  # every case's connection and the liveness probes


# ------------------------------------------------------------------------------ the client's side


def _request(opcode: int, data: bytes = b"", number: int = 5) -> WirePacket:
    return WirePacket("c2s", opcode, number, 0, data, 0.0, 0)


def test_client_requests_are_judged_by_opcode_and_layout() -> None:
    here, move = SPEC.request("here").opcode, SPEC.request("move").opcode
    assert check_client_request(_request(here)) == []
    assert check_client_request(_request(move, encode_request("move", transform=(0.0,) * 12))) == []
    assert check_client_request(_request(0o276, b"xy")) == []  # undefined: the server's to refuse
    [dwd] = check_client_request(_request(0o300))
    assert dwd.clause == "request.opcode-range" and "opcode 0300" in dwd.message
    [short] = check_client_request(_request(move, bytes(44)))
    assert short.clause == "move.transform-data" and "48 bytes" in short.expected
    [extra] = check_client_request(_request(here, b"\x01\x02"))
    assert extra.clause == "request-data.types" and extra.data == b"\x01\x02"


def test_verify_judges_the_client_side_when_asked() -> None:
    clean = verify_capture(GOLDEN / "motion.mcap", judge="both")
    assert clean.exit_code == 0
    assert any(r.id == "verify.session-1.client-requests" and r.outcome == "pass" for r in clean.results)
    server_only = verify_capture(GOLDEN / "errors.mcap")
    assert server_only.exit_code == 0  # the errors session's malformed requests are refused as they must be
    client = verify_capture(GOLDEN / "errors.mcap", judge="client")
    [result] = [r for r in client.results if r.outcome != "skip"]  # the session arms no guard
    assert result.outcome == "fail" and client.exit_code == 1
    assert {v.clause for v in result.violations} == {"request-data.types"}
    assert "--judge client" in result.reproduce


def test_coverage_names_verify_for_the_client_clauses() -> None:
    rows = {r.clause: r for r in coverage(all_cases(), {"client"})}
    # the live client cases (manip-conform client) come first; the offline verify family stays beside them
    cases = rows["request-data.types"].cases
    assert "verify:client-requests" in cases and any(c.startswith("client.request.") for c in cases)
    assert not gaps(rows.values())


def _asked(op: str, number: int, **values: object) -> WirePacket:
    return WirePacket("c2s", SPEC.request(op).opcode, number, 0, encode_request(op, **values))  # type: ignore[arg-type]


def _guard_hit(index: int) -> WirePacket:
    data = struct.pack("<HHHH", 0, AsyncCondition.GUARD_HIT, 2, index)
    return WirePacket("s2c", ServerOp.ASYNCHRONOUS_RESPONSE, 90, 0, data)


def test_client_guards_are_judged_over_the_connection() -> None:
    guard = {"dvec": [0.0] * 6, "tol": 1.0}
    notify = _asked("request-notifications", 1, mask=1)
    fine = [
        notify,
        _asked("set-frame-vector", 2, offset=[0.0, 0.0, 50.0]),
        _asked("set-weight", 3, weight=8.0, cg=[0.0, 0.0, 0.0]),
        _asked("set-guard", 4, type_index=3, **guard),
        _guard_hit(3),
        _asked("set-guard", 5, type_index=3, **guard),
        _asked("clear-guard", 6, index=3),
        _asked("set-guard", 7, type_index=3, **guard),
    ]
    assert check_client_guards(fine) == []
    reused = [
        notify,
        _asked("set-guard", 2, type_index=3, **guard),
        _asked("set-guard", 3, type_index=3, **guard),
    ]
    assert [v.clause for v in check_client_guards(reused)] == ["client.guard-numbers"]
    assert check_client_guards(reused[1:]) == []  # without guard-hit reports the client cannot know
    weight_under_guard = [
        _asked("set-guard", 2, type_index=1, **guard),
        _asked("set-weight", 3, weight=1.0, cg=[0.0] * 3),
    ]
    assert [v.clause for v in check_client_guards(weight_under_guard)] == ["client.no-newwc-with-guard"]
    stale_weight = [_asked("set-frame-vector", 2, offset=[0.0, 0.0, 50.0]), _asked("read-forces", 3)]
    assert [v.clause for v in check_client_guards(stale_weight)] == ["client.newwc-on-load"]
