"""``manip-conform replay``: golden captures replay cleanly against the current server, a changed server
is caught with the field named, masks hold, and ``--serve`` plays the recorded server to a client."""

from __future__ import annotations

import asyncio
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from manip.captures import read_session
from manip.conformance.cli import main
from manip.conformance.judge.checks import WirePacket
from manip.conformance.output.report import load_schema
from manip.conformance.replay.against import AnswerSorter, ReplayOptions, replay_capture, script_of
from manip.conformance.replay.masking import (
    NumberMap,
    SegmentBase,
    compare_answer,
    compare_async,
    floats_equal,
)
from manip.conformance.replay.serve import ServeOptions, serve_capture
from manip.conformance.suite.embedded import EmbeddedServer
from manip.conformance.suite.results import RunReport
from manip.reference_client import aconnect
from manip.reference_client.errors import ResponseDataError
from manip.reference_server import FaultSet, ServerConfig
from manip.spec.constants import ServerOp
from tests.support.json_schema import validate as _validate
from tests.support.paths import ROOT

GOLDEN = ROOT / "captures"
NAMES = ("describe-self", "motion", "errors")
FAST = ReplayOptions(reply_timeout=0.5, async_timeout=2.0, settle=0.05)


def replay(name: str, *faults: str, options: ReplayOptions = FAST) -> RunReport:
    config = ServerConfig(faults=FaultSet.parse(faults)) if faults else ServerConfig()
    with EmbeddedServer(config, time_scale=20, seed=1985) as address:
        return asyncio.run(replay_capture(GOLDEN / f"{name}.mcap", address, options, embedded=True))


def mismatch_messages(report: RunReport) -> list[str]:
    return [v.message for r in report.results if r.id.endswith(".exchange") for v in r.violations]


@pytest.mark.parametrize("name", NAMES)
def test_golden_capture_replays_cleanly(name: str) -> None:
    report = replay(name)
    assert report.exit_code == 0, [(r.id, [v.message for v in r.violations]) for r in report.results]
    assert [r.id for r in report.results] == ["replay.session-1.exchange", "replay.session-1.checks"]
    sent = [p for p in report.results[0].packets if p.direction == "c2s" and not p.is_close]
    assert len(sent) == len(read_session(GOLDEN / f"{name}.mcap").requests)


@pytest.mark.parametrize(
    ("name", "fault", "path"),
    [
        ("motion", "wrong-request-number", "request_number"),
        ("motion", "swapped-float-words", "joints["),
        ("describe-self", "no-describe-terminator", "terminator"),
        ("errors", "wrong-severity", "error.severity"),
        ("motion", "async-stray-byte", "asynchronous packet 1"),
    ],
)
def test_a_changed_server_is_caught_with_the_field(name: str, fault: str, path: str) -> None:
    report = replay(name, fault)
    assert report.exit_code == 1
    messages = mismatch_messages(report)
    assert any(path in m for m in messages), messages
    exchange = report.results[0]
    assert exchange.outcome == "fail" and all(v.data or v.kind != "mismatch" for v in exchange.violations)
    # expected and actual describe the same thing, the field compared; the packet's bytes are said to be that
    mismatches = [v for v in exchange.violations if v.kind == "mismatch"]
    for v in mismatches:
        field_name = v.expected.split(":", 1)[0]
        assert v.actual.startswith(f"{field_name}:"), (v.expected, v.actual)
        assert "recorded bytes" not in v.expected
    assert any("the recorded packet's data:" in v.expected for v in mismatches)


def test_ignore_drops_mismatches_by_path() -> None:
    options = ReplayOptions(reply_timeout=0.5, settle=0.05, ignore=("error.severity", "error"))
    report = replay("errors", "wrong-severity", options=options)
    exchange = report.results[0]
    assert exchange.outcome == "pass" and any("left out by --ignore" in n for n in exchange.notes)
    assert report.results[1].outcome == "fail"  # the live checks still see the wrong severity letter


def test_an_async_in_the_guides_layout_is_compared_without_a_request_number() -> None:
    def guide(condition: int, word2: int = 1) -> WirePacket:
        return WirePacket("s2c", ServerOp.ASYNCHRONOUS_RESPONSE, 9, 7, bytes([condition, 0, word2, 0, 3, 0]))

    numbers = NumberMap({7: 40})  # the condition code 2 is no request number to renumber
    assert compare_async(guide(1), guide(1), numbers, SegmentBase()) == []
    (m,) = compare_async(guide(1), guide(1, word2=2), numbers, SegmentBase())
    assert m.path == "async.word2"
    numbered = WirePacket("s2c", ServerOp.ASYNCHRONOUS_RESPONSE, 9, 7, bytes([7, 0, 2, 0, 0, 0, 3, 0]))
    assert compare_async(guide(2, 0), numbered, numbers, SegmentBase())  # the layout changed: a mismatch


def test_masks_renumber_requests_and_segments_and_tolerate_float_noise() -> None:
    request = WirePacket("c2s", 0o215, 7, 0, bytes(24))
    numbers = NumberMap({7: 40})
    recorded = [WirePacket("s2c", ServerOp.RESPONSE, 9, 7, b"\x07\x00\x03\x00")]
    live = [WirePacket("s2c", ServerOp.RESPONSE, 50, 40, b"\x28\x00\x0b\x00")]
    assert compare_answer(request.opcode, recorded, live, numbers, SegmentBase()) == []
    base = SegmentBase(recorded=3, live=10)  # segment 0 of the recording, segment 1 live
    (m,) = compare_answer(request.opcode, recorded, live, numbers, base)
    assert m.path == "segment"
    wrong = [WirePacket("s2c", ServerOp.RESPONSE, 50, 40, b"\x07\x00\x0b\x00")]
    (m,) = compare_answer(request.opcode, recorded, wrong, numbers, SegmentBase())
    assert m.path == "request_number" and m.clause == "response.echoes-request-number"
    assert floats_equal(100.0, 100.0 * (1 + 2**-23)) and not floats_equal(100.0, 100.01)
    assert floats_equal(0.0, 1e-7) and not floats_equal(0.0, 1e-4)


def test_answer_sorter_cuts_multi_packet_replies_and_asyncs() -> None:
    sorter = AnswerSorter(initial=True)
    sorter.server(WirePacket("s2c", ServerOp.RESPONSE, 2, 1, b"\x01\x00"))
    sorter.request(WirePacket("c2s", 0o200, 2, 0, b""))  # describe-self
    sorter.server(WirePacket("s2c", ServerOp.RESPONSE, 3, 2, b"\x02\x00(a)"))
    sorter.server(WirePacket("s2c", ServerOp.ASYNCHRONOUS_RESPONSE, 4, 2, bytes(8)))
    assert sorter.completed == 1 and len(sorter.asyncs) == 1
    sorter.server(WirePacket("s2c", ServerOp.RESPONSE, 5, 2, b"\x02\x00"))
    sorter.server(WirePacket("s2c", ServerOp.RESPONSE, 6, 2, b"\x02\x00"))
    assert sorter.completed == 2 and len(sorter.answers[1]) == 2 and len(sorter.extras) == 1


def test_script_waits_for_the_recorded_notification() -> None:
    script = script_of(read_session(GOLDEN / "motion.mcap"))
    barriers = [barrier for _, barrier in script.sends]
    assert [b.asyncs for b in barriers] == [0, 0, 0, 0, 1, 1]  # joint-angles after the segment completed
    assert [b.answers for b in barriers] == [1, 2, 3, 4, 5, 6] and not script.server_closes


def test_cli_replay_against_url_and_exit_codes(tmp_path: Path) -> None:
    runner = CliRunner()
    with EmbeddedServer(time_scale=20) as address:
        out = tmp_path / "r.json"
        result = runner.invoke(
            main, ["replay", str(GOLDEN / "errors.mcap"), "--against", address, "--json", str(out), "-q"]
        )
        assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    schema = load_schema()
    _validate(data, schema, schema)
    assert data["cases"][0]["kind"] == "replay"
    faulty = runner.invoke(
        main, ["replay", str(GOLDEN / "motion.mcap"), "--server-fault", "swapped-float-words", "-q"]
    )
    assert faulty.exit_code == 1 and "joints[" in faulty.output
    usage = runner.invoke(main, ["replay", str(GOLDEN / "motion.mcap"), "--against", "x", "--serve", "y"])
    assert usage.exit_code == 2
    dead = runner.invoke(main, ["replay", str(GOLDEN / "motion.mcap"), "--against", "tcp://127.0.0.1:9"])
    assert dead.exit_code == 3 and "unreachable" in dead.output


def test_serve_plays_the_recorded_server_to_a_reference_client() -> None:
    async def job() -> tuple[RunReport, tuple[float, ...], int, tuple[float, ...]]:
        ready: asyncio.Future[str] = asyncio.get_running_loop().create_future()
        options = ServeOptions(seconds=10, on_listening=ready.set_result)
        task = asyncio.create_task(serve_capture(GOLDEN / "motion.mcap", "tcp://127.0.0.1:0", options))
        address = await ready
        async with aconnect(address) as arm:
            await arm.enable_power()
            await arm.request_notifications(2)
            start = await arm.joint_angles()
            segment = await arm.set_joint_angles([5.0, -95.0, 92.5, 0.0, 4.0, -3.0])
            await arm.wait_for_segment(segment, timeout=2)
            end = await arm.joint_angles()
            await arm.here()
        return await task, start, segment, end

    report, start, segment, end = asyncio.run(job())
    assert start == (0.0, -90.0, 90.0, 0.0, 0.0, 0.0) and segment == 1
    assert end == (5.0, -95.0, 92.5, 0.0, 4.0, -3.0)  # the recorded answers, though no arm moved
    assert report.exit_code == 0, [v.message for r in report.results for v in r.violations]


def test_serve_reports_requests_that_differ_from_the_recording() -> None:
    async def job() -> RunReport:
        ready: asyncio.Future[str] = asyncio.get_running_loop().create_future()
        options = ServeOptions(seconds=10, on_listening=ready.set_result)
        task = asyncio.create_task(serve_capture(GOLDEN / "describe-self.mcap", "tcp://127.0.0.1:0", options))
        address = await ready
        async with aconnect(address) as arm:
            await arm.describe()
            with pytest.raises(ResponseDataError):  # the recorded answer is here's (0201)
                await arm.joint_angles()
        return await task

    report = asyncio.run(job())
    assert report.exit_code == 1
    (message,) = [v.message for v in report.results[0].violations]
    assert "request 2" in message and "opcode" in message


def test_serve_cli_prints_the_real_address_and_stops_after_seconds() -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "manip.conformance.cli", "replay", str(GOLDEN / "errors.mcap"),
         "--serve", "tcp://127.0.0.1:0", "--seconds", "0.3"],
        check=False, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    served = re.search(r"serving the recorded sessions of .*?at (tcp://\S+)", proc.stdout, re.S)
    assert served is not None and not served.group(1).endswith(":0"), proc.stdout
    assert proc.returncode == 3, proc.stdout + proc.stderr  # no client came


def test_embedded_replay_server_gets_a_wrist_only_when_the_recording_had_one(tmp_path: Path) -> None:
    from manip.conformance.replay.cli import _capture_settings

    assert _capture_settings(GOLDEN / "describe-self.mcap").wrist is False  # recorded without a wrist
    recorded = tmp_path / "wrist.mcap"
    args = ["run", "--select", "server.reply.wrist-version", "--record", str(recorded), "-q", "--seed", "1"]
    run = CliRunner().invoke(main, args)
    assert run.exit_code == 0, run.output  # the embedded robot of `run` has the simulated wrist
    assert _capture_settings(recorded).wrist is True
    replayed = CliRunner().invoke(main, ["replay", str(recorded), "-q"])
    assert replayed.exit_code == 0, replayed.output


def test_replay_waits_for_an_answer_the_spec_lets_take_longer(tmp_path: Path) -> None:
    """calibrate-wrist answers after moving the arm (answer_within 20 s): far beyond --reply-timeout."""
    recorded, report = tmp_path / "calibrate.mcap", tmp_path / "replay.json"
    args = ["run", "--select", "server.reply.calibrate-wrist", "--record", str(recorded), "-q", "--seed", "3"]
    run = CliRunner().invoke(main, args)
    assert run.exit_code == 0, run.output
    CliRunner().invoke(main, ["replay", str(recorded), "-q", "--reply-timeout", "0.3", "--json", str(report)])
    cases = json.loads(report.read_text())["cases"]
    calibrating = [
        c for c in cases if c["id"].endswith(".exchange") and any(p["opcode"] == "243" for p in c["packets"])
    ]
    assert len(calibrating) == 1 and calibrating[0]["outcome"] == "pass", calibrating


def test_a_simulated_run_is_recorded_at_its_wall_clock_start_and_replays(tmp_path: Path) -> None:
    """The log times of ``run --record`` are dates (a viewer shows the day of the run, not 1970); the
    virtual clock's origin is kept in the metadata, and replay takes the difference off to put each
    request at its recorded virtual instant."""
    import time

    from manip.captures import read_capture

    recorded = tmp_path / "run.mcap"
    before = time.time_ns()
    args = ["run", "--select", "server.reply.here", "--record", str(recorded), "-q", "--seed", "4"]
    assert CliRunner().invoke(main, args).exit_code == 0
    after = time.time_ns()
    capture = read_capture(recorded)
    meta = capture.metadata["manip.capture"]
    assert meta["time"] == "virtual" and int(meta["wall_origin_ns"]) >= before
    starts = [s.start_ns for s in capture.sessions]
    assert starts and all(before <= t <= after + 3600 * 10**9 for t in starts), (before, starts)
    replayed = CliRunner().invoke(main, ["replay", str(recorded), "-q"])
    assert replayed.exit_code == 0, replayed.output
