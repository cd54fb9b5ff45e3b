"""manip-conform as a user meets it: output that survives a pipe, failures grouped by the clause they
break, usage errors instead of empty passes, and a target that is not a manip server said to be so."""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import shlex
import subprocess
import sys
import threading
import xml.etree.ElementTree as ET
from collections.abc import Awaitable, Callable, Iterator
from pathlib import Path

import pytest
from click.testing import CliRunner

from manip.codecs.error_string import ErrorMessage
from manip.codecs.messages import encode_error, encode_reply, encode_request, segment_completed
from manip.codecs.packet import Packet
from manip.conformance.cli import main
from manip.conformance.judge.checks import WirePacket, describe
from manip.conformance.output.packet_text import packet_listing
from manip.conformance.output.report import by_clause, clause_lines, load_schema, report_json
from manip.conformance.suite.case import all_cases
from manip.conformance.suite.context import RunOptions
from manip.conformance.suite.rawchaos import RawError, RawPeer, format_packet
from manip.conformance.suite.results import CaseResult, ExitCode, RunReport, Violation
from manip.conformance.suite.runner import RunConfig, Runner
from manip.conformance.suite.selection import PatternSet
from manip.spec import SPEC
from manip.spec.constants import ChaosOp, ServerOp
from tests.support.json_schema import validate as _validate
from tests.support.paths import ROOT

GOLDEN = ROOT / "captures"
ECHO = "response.echoes-request-number"


# ------------------------------------------------------------------------------------------- pipes


def test_output_to_a_pipe_is_never_wrapped(tmp_path: Path) -> None:
    """A failing replay of a capture under a 150+ character directory, stdout a pipe: every reproduce
    line is one command naming the whole path, and every hex dump is whole."""
    deep = tmp_path / ("a-directory-name-long-enough-to-break-any-line-" * 4)
    assert len(deep.name) > 150
    deep.mkdir()
    capture = deep / "describe-self.mcap"
    capture.write_bytes((GOLDEN / "describe-self.mcap").read_bytes())
    report = deep / "report.json"
    proc = subprocess.run(
        [sys.executable, "-m", "manip.conformance.cli", "replay", str(capture),
         "--server-fault", "wrong-request-number", "--json", str(report)],
        check=False, capture_output=True, text=True, timeout=60,
        env={**os.environ, "COLUMNS": "40", "FORCE_COLOR": "1"},
    )  # fmt: skip
    assert proc.returncode == 1, proc.stdout + proc.stderr
    lines = proc.stdout.splitlines()
    assert "\x1b" not in proc.stdout  # no colour in a pipe, whatever FORCE_COLOR says
    reproduce = [line.removeprefix("reproduce: ") for line in lines if line.startswith("reproduce: ")]
    data = json.loads(report.read_text())
    failed = [c for c in data["cases"] if c["outcome"] == "fail"]
    assert failed and len(reproduce) == len(failed)
    for line, case in zip(reproduce, failed, strict=True):
        words = shlex.split(line)
        assert words[:3] == ["manip-conform", "replay", str(capture)], line
        assert line == case["reproduce"]
    dumps = [line.removeprefix("  bytes:    ") for line in lines if line.startswith("  bytes:    ")]
    expected = [v["bytes"] for c in failed for v in c["violations"] if v["bytes"]]
    assert [bytes.fromhex(d).hex() for d in dumps] == expected
    assert max(map(len, dumps)) > 80  # long enough that a wrapping console would have broken them


# ------------------------------------------------------------------------------------------- by clause


def _result(case_id: str, outcome: str, *violations: Violation) -> CaseResult:
    return CaseResult(
        id=case_id,
        clauses=(ECHO,),
        level="MUST",
        kind="scripted",
        hazard="read-only",
        summary="",
        outcome=outcome,  # type: ignore[arg-type]
        seed=1,
        deadline=1.0,
        violations=list(violations),
    )


def _violation(clause: str | None, level: str = "MUST", kind: str = "wrong_value") -> Violation:
    return Violation("m", clause, level, "e", "a", b"\x01", kind)


def test_by_clause_counts_cases_per_clause_and_kind_of_failure() -> None:
    segment = "segment.number-increases"  # a SHOULD clause
    report = RunReport(target="t", embedded=True, seed=1, strict=False, options={}, command="c")
    report.results = [
        _result("a.one", "fail", _violation(ECHO), _violation(ECHO), _violation(segment, "SHOULD")),
        _result("a.two", "fail", _violation(ECHO)),
        _result("a.three", "warn", _violation(segment, "SHOULD")),
        _result("a.four", "known-fail", _violation(ECHO)),
        _result("a.five", "fail", _violation(None, kind="deadline")),
        _result("a.six", "pass"),
    ]
    tallies = {t.name: t for t in by_clause(report)}
    assert set(tallies) == {ECHO, segment, "(no clause: deadline)"}
    echo = tallies[ECHO]
    assert (echo.failures, echo.warnings, echo.known_failures) == (2, 0, 1)  # a.one counts once
    assert echo.cases == ("a.four", "a.one", "a.two")
    assert (echo.text, echo.section) == (SPEC.clauses[ECHO].text, SPEC.clauses[ECHO].section)
    assert (tallies[segment].failures, tallies[segment].warnings) == (0, 2)  # SHOULD: warnings
    assert tallies["(no clause: deadline)"].failures == 1
    first = clause_lines(report)[0]
    assert first == (
        f"2 failures, 1 known failure: {ECHO} \u2014 {SPEC.clauses[ECHO].text} ({SPEC.clauses[ECHO].section})"
    )
    report.strict = True
    assert {t.name: t.failures for t in by_clause(report)}[segment] == 1  # --strict: a failure in a.one
    data = json.loads(json.dumps(report_json(report)))
    schema = load_schema()
    _validate(data, schema, schema)
    assert [t["clause"] for t in data["by_clause"]] == [ECHO, segment, None]
    assert list(data).index("by_clause") < list(data).index("cases")  # the summary before the details


def test_run_groups_failures_by_clause_in_console_json_and_junit(tmp_path: Path) -> None:
    json_path, junit_path = tmp_path / "r.json", tmp_path / "r.xml"
    selected = ["server.reply.here", "server.reply.joint-angles"]
    result = CliRunner().invoke(
        main,
        ["run", "-q", "--seed", "2", "--server-fault", "wrong-request-number",
         *[w for s in selected for w in ("--select", s)],
         "--json", str(json_path), "--junit", str(junit_path)],
    )  # fmt: skip
    assert result.exit_code == 1, result.output
    clause = SPEC.clauses[ECHO]
    line = f"  2 failures: {ECHO} \u2014 {clause.text} ({clause.section})"
    lines = result.output.splitlines()
    assert line in lines
    assert lines.index(line) < next(i for i, t in enumerate(lines) if t.startswith("non-conformant"))
    data = json.loads(json_path.read_text())
    assert [(t["clause"], t["failures"], t["cases"]) for t in data["by_clause"]] == [(ECHO, 2, selected)]
    suites = [s for s in ET.parse(junit_path).getroot().iter("testsuite") if s.get("name") != "clauses"]
    failures = [f for s in suites for f in s.iter("failure")]
    assert len(failures) == 2
    for failure in failures:
        assert clause.text in failure.get("message", "") and clause.section in failure.get("message", "")
        assert f"clause:   {clause.text} ({clause.section})" in (failure.text or "")


def test_the_embedded_server_runs_with_the_guide_profile(tmp_path: Path) -> None:
    json_path = tmp_path / "r.json"
    result = CliRunner().invoke(
        main,
        ["run", "-q", "--seed", "3", "--server-profile", "guide", "--select", "server.reply.here",
         "--select", "server.negative.set-configuration-sizes", "--json", str(json_path)],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    cases = json.loads(json_path.read_text())["cases"]
    assert {c["outcome"] for c in cases} == {"pass"}
    assert all("--server-profile guide" in c["reproduce"] for c in cases)


# ------------------------------------------------------------------------------------------- usage errors


def _usage(args: list[str]) -> str:
    """The error message of a command that must end as a usage error (exit 2) before running anything."""
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 2, result.output
    assert "embedded reference server at" not in result.output  # nothing ran
    message = result.output.strip().splitlines()[-1]
    assert message.startswith("Error: "), result.output
    return message


def test_a_selection_that_matches_nothing_is_a_usage_error(tmp_path: Path) -> None:
    assert "'nomatch.*' matches no case" in _usage(["run", "--select", "nomatch.*"])
    typo = _usage(["run", "--select", "server.reply.heer", "--select", "server.describe"])
    assert "'server.reply.heer' matches no case" in typo and "close matches: server.reply.here" in typo
    assert "close matches: server.reply" in _usage(["run", "--select", "server.repyl.*"])
    other = _usage(["run", "--select", "cougar.reply"])  # Cougar cases, in a server run
    assert "of --cougar" in other and "cougar.reply." in other
    server_only = _usage(["run", "--cougar", "--select", "server.reply.here"])
    assert "a server run (without --cougar)" in server_only
    listing = tmp_path / "select.txt"
    listing.write_text("server.reply.here\nserver.nothing-here\n")
    assert f"({listing}:2)" in _usage(["run", "--select", f"@{listing}"])
    emptied = _usage(["run", "--select", "server.reply.here", "--skip", "server.reply"])
    assert "leave no case to run" in emptied
    assert "matches no case" in _usage(["cases", "--select", "nomatch"])


def test_an_option_of_a_target_not_chosen_is_a_usage_error() -> None:
    assert "add --cougar sim" in _usage(["run", "--cougar-fault", "no-out-of-sync"])
    assert "--target hardware" in _usage(["run", "--allow-motion"])
    assert "embedded server only" in _usage(["run", "tcp://127.0.0.1:1", "--server-profile", "guide"])
    for option in (["--broken-after", "3"], ["--max-examples", "3"], ["--record", "x.mcap"]):
        assert "not with --cougar" in _usage(["run", "--cougar", "sim", *option])
    for option in (["--settle", "1"], ["--reply-timeout", "1"], ["--async-timeout", "1"]):
        message = _usage(["replay", str(GOLDEN / "errors.mcap"), "--serve", "tcp://127.0.0.1:0", *option])
        assert f"{option[0]} applies to a replay against a server" in message


def test_report_paths_are_checked_before_the_run(tmp_path: Path) -> None:
    missing = tmp_path / "no-such-dir" / "r.json"
    not_a_dir = tmp_path / "file"
    not_a_dir.write_text("")
    capture = str(GOLDEN / "errors.mcap")
    for option in ("--json", "--junit", "--record"):
        message = _usage(["run", "--select", "server.reply.here", option, str(missing)])
        assert f"{option}: the directory {missing.parent} of {missing} does not exist" in message
        inside_a_file = str(not_a_dir / "r.out")
        assert "is not a directory" in _usage(["run", option, inside_a_file])
        assert "does not exist" in _usage(["replay", capture, option, str(missing)])
    for option in ("--json", "--junit"):
        assert "does not exist" in _usage(["verify", capture, option, str(missing)])
    assert not missing.parent.exists()


# ------------------------------------------------------------------------------------ not a manip server

Handler = Callable[[asyncio.StreamReader, asyncio.StreamWriter], Awaitable[None]]
HTTP_ANSWER = b"HTTP/1.0 400 Bad Request\r\nContent-Type: text/html\r\n\r\n<h1>Bad Request</h1>\r\n"


async def _http(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    """What a web server does with a Chaos RFC frame: reads a little, answers 400, hangs up."""
    with contextlib.suppress(TimeoutError):
        await asyncio.wait_for(reader.read(64), 0.5)
    writer.write(HTTP_ANSWER)
    await writer.drain()
    writer.close()


async def _silent(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    """Accepts the TCP connection and never says a word."""
    await reader.read()
    writer.close()


@contextlib.contextmanager
def foreign_server(handler: Handler) -> Iterator[str]:
    """A TCP server on 127.0.0.1:0 in its own thread and loop (the command under test runs its own)."""
    loop = asyncio.new_event_loop()
    ready = threading.Event()
    stop = asyncio.Event()
    ports: list[int] = []

    async def serve() -> None:
        server = await asyncio.start_server(handler, "127.0.0.1", 0)
        ports.append(server.sockets[0].getsockname()[1])
        ready.set()
        async with server:
            await stop.wait()

    thread = threading.Thread(target=loop.run_until_complete, args=(serve(),), daemon=True)
    thread.start()
    try:
        assert ready.wait(5), "the foreign server did not start"
        yield f"tcp://127.0.0.1:{ports[0]}"
    finally:
        loop.call_soon_threadsafe(stop.set)
        thread.join(5)
        loop.close()


def test_a_web_server_at_the_address_is_said_not_to_be_a_chaos_link(tmp_path: Path) -> None:
    json_path = tmp_path / "r.json"
    with foreign_server(_http) as address:
        result = CliRunner().invoke(
            main, ["run", address, "-q", "--select", "server.reply.here", "--json", str(json_path)]
        )
    assert result.exit_code == 3, result.output
    said = "the peer answered `HTTP/1.0 400 Bad Request`: not a Chaos link"
    assert said in result.output
    (before,) = json.loads(json_path.read_text())["liveness"]
    assert before["when"] == "before" and not before["alive"] and said in before["detail"]


def test_the_raw_peer_says_so_too() -> None:
    async def go() -> str:
        with foreign_server(_http) as address:
            async with await RawPeer.open(address) as peer:
                with pytest.raises(RawError) as caught:
                    await peer.handshake(0x0A01, 1, timeout=2.0)
        return str(caught.value)

    assert "the peer answered `HTTP/1.0 400 Bad Request`: not a Chaos link" in asyncio.run(go())


def test_a_silent_peer_names_the_default_chaos_address_as_such() -> None:
    async def go() -> RunReport:
        with foreign_server(_silent) as address:
            options = RunOptions(address=address, reply_timeout=0.2, connect_timeout=0.3)
            select = PatternSet.of(["server.reply.here"], "--select")
            config = RunConfig(options, seed=1, select=select)
            return await Runner(config, all_cases()).run()

    report = asyncio.run(go())
    assert report.exit_code == ExitCode.UNREACHABLE
    detail = report.liveness[0].detail
    assert "Chaos host 0440 (the robot's default address)" in detail and "contact 'PUMA'" in detail


# ------------------------------------------------------------------------------------ readable packets


def _c2s(name: str, number: int, **values: object) -> WirePacket:
    return WirePacket("c2s", SPEC.request(name).opcode, number, 0, encode_request(name, **values))


def _s2c(opcode: int, data: bytes) -> WirePacket:
    return WirePacket("s2c", opcode, 0, 0, data)


def test_a_request_is_described_with_its_packet_number_and_octal_opcode() -> None:
    assert describe(_c2s("here", 23)) == "here 0201 (packet number 23, 0 data bytes)"
    reply = _s2c(ServerOp.RESPONSE, encode_reply("here", 23, transform=[0.0] * 12))
    assert describe(reply) == "response 0200 (request number 23, 50 data bytes)"


def test_packets_are_listed_numbered_and_decoded() -> None:
    joints = [10.5, -90.0, 90.0, 0.0, 0.25, 1e-3]
    transform = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 100.0, 200.0, 300.0]
    move = _c2s("set-joint-angles", 3, joints=joints)
    wrong = _s2c(ServerOp.RESPONSE, encode_reply("set-joint-angles", 4, segment=7))  # names request 4
    nap = ErrorMessage("move", "E", "NAP", "No arm power")
    packets = [
        _s2c(ServerOp.RESPONSE, b"\x01\x00"),
        _c2s("here", 2),
        _s2c(ServerOp.RESPONSE, encode_reply("here", 2, transform=transform)),
        move,
        wrong,
        _c2s("move", 5, transform=transform),
        _s2c(ServerOp.NON_FATAL_ERROR, encode_error(ServerOp.NON_FATAL_ERROR, 5, nap)),
        _s2c(ServerOp.ASYNCHRONOUS_RESPONSE, segment_completed(3, 7)),
        WirePacket("c2s", 0o276, 6, 0, b"\xab\xcd"),
        WirePacket("s2c", ChaosOp.CLS, 0, 0, b"closed by the server"),
    ]
    lines = packet_listing(packets, marked=[move, wrong], from_open=True)
    assert [int(line[4:7]) for line in lines] == list(range(1, len(packets) + 1))
    assert [line[2] for line in lines] == [" ", " ", " ", ">", ">", " ", " ", " ", " ", " "]
    text = [line.split(": ", 1)[1] for line in lines]
    assert "initial RESPONSE" in text[0]
    assert lines[1].endswith("c2s here 0201 (packet number 2, 0 data bytes): no data")
    assert text[2] == "transform N=(1, 0, 0) O=(0, 1, 0) A=(0, 0, 1) P=(100, 200, 300)"
    assert text[3] == "joints=(10.5, -90, 90, 0, 0.25, 0.001)"
    assert text[4] == "segment=7"  # decoded by the last request, though it names another
    assert text[6] == repr(nap.render())
    assert text[7].startswith("segment-completed") and "request number 3" in text[7]
    assert text[8] == "unknown opcode, data ab cd"
    assert text[9] == "closed by the server"
    assert len(packet_listing(packets, limit=4)) == 5  # a line saying what was left out, then the last 4


def test_raw_packets_say_what_their_chaos_addresses_are() -> None:
    rfc = Packet(ChaosOp.RFC, dest_host=0o440, dest_index=0, src_host=0o401, src_index=0x0A01, packet_no=1)
    shown = format_packet(rfc)
    assert shown.startswith("RFC 01 Chaos host 0401 (the client's default address) index 05001 -> ")
    assert "Chaos host 0440 (the robot's default address) index 0 pkt#1" in shown
    other = Packet(ChaosOp.LOS, dest_host=0o3001, dest_index=1, src_host=0o440, src_index=2)
    assert "-> Chaos host 03001 index 01" in format_packet(other)


def test_a_reproduce_line_names_the_target_as_it_was_given(reference_server_url: str, tmp_path: Path) -> None:
    """Every query parameter the user wrote stays, even one that only repeats a default (me=0401)."""
    given = f"{reference_server_url}?me=0401&contact=PUMA"
    report = tmp_path / "r.json"
    result = CliRunner().invoke(
        main, ["run", given, "--select", "server.describe.alist", "--json", str(report)]
    )
    assert result.exit_code == 0, result.output
    (case,) = json.loads(report.read_text())["cases"]
    assert shlex.split(case["reproduce"])[:3] == ["manip-conform", "run", given]


@pytest.mark.parametrize("command", ["run", "client", "verify", "replay", "fuzz"])
def test_every_judging_command_takes_every_report_format(command: str) -> None:
    """The report options come from one declaration (``REPORT_FORMATS``): the same option, help and
    writer on each command, so a new format reaches them all."""
    from manip.conformance.output.documents import REPORT_FORMATS

    found = main.commands[command]
    options = {p.opts[0]: p for p in found.params if p.opts and p.opts[0].startswith("--")}
    for form in REPORT_FORMATS:
        assert form.option in options, (command, form.option)
        assert options[form.option].help == form.help


def test_a_report_path_that_cannot_be_written_is_a_usage_error_on_fuzz_too(tmp_path: Path) -> None:
    missing = tmp_path / "no-such-directory" / "fuzz.html"
    result = CliRunner().invoke(main, ["fuzz", "--inputs", "1", "--html", str(missing)])
    assert result.exit_code == 2 and "--html" in result.output, result.output
