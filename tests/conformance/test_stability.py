"""Verdicts that do not depend on the draw: the embedded suite in virtual time, same seed same packets,
the --repeat stability gate, and reply allowances computed from the spec."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner
from mcap.reader import make_reader

from manip.conformance.cli import main
from manip.conformance.judge.checks import WirePacket
from manip.conformance.suite.results import CaseResult, ExitCode, RunReport
from manip.conformance.suite.stability import instability, repeat_seeds
from tests.support.paths import ROOT


def _invoke(*args: str) -> tuple[int, str]:
    result = CliRunner().invoke(main, ["run", *args])
    return result.exit_code, result.output


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_two_seeds_are_conformant_and_the_first_repeats_itself(tmp_path: Path) -> None:
    # The README's gate is --repeat 20; two seeds (three whole runs) test the same mechanism at a seventh
    # of the CPU: the test suite runs on two cores within the CI budget.
    report_path = tmp_path / "repeat.json"
    code, output = _invoke("--repeat", "2", "-q", "--seed", "20261126", "--json", str(report_path))
    assert code == ExitCode.CONFORMANT, output
    assert output.count("conformant, ") == 3  # 2 seeds, then the first again
    report = json.loads(report_path.read_text())
    assert report["time"] == "virtual"
    assert report["unstable"] == []
    assert report["verdict"] == "conformant"


def _messages(path: Path) -> list[tuple[str, int, bytes]]:
    """Every message as (topic, log time, data), times taken relative to the recording's wall-clock
    anchor (each run is recorded at the date it is made; the virtual times are the seed's)."""
    with path.open("rb") as f:
        reader = make_reader(f)
        meta = next(m for m in reader.iter_metadata() if m.name == "manip.capture").metadata
        anchor = int(meta["wall_origin_ns"])
        out = []
        for _, c, m in reader.iter_messages(log_time_order=False):
            data = m.data
            if b'"timestamp"' in data:  # the arm's poses carry their log time
                body = json.loads(data)
                stamp = body["timestamp"]["sec"] * 10**9 + body["timestamp"]["nsec"] - anchor
                data = json.dumps({**body, "timestamp": stamp}, sort_keys=True).encode()
            out.append((c.topic, m.log_time - anchor, data))
        return out


def test_a_reply_queued_behind_slow_work_gets_the_spec_allowance() -> None:
    # This seed once failed the reference server: a calibrate-wrist (answer within 20 s, at the speed
    # factor in force) came after a crawling speed factor, and a Here behind it got the bare 2 s.
    code, output = _invoke("--seed", "3508145982", "-q", "--select", "property.requests.well-formed")
    assert code == ExitCode.CONFORMANT, output


def test_virtual_time_needs_the_embedded_server() -> None:
    code, output = _invoke("tcp://127.0.0.1:9", "--time", "virtual")
    assert code == ExitCode.USAGE
    assert "embedded" in output


def test_the_embedded_server_still_runs_in_real_time_when_asked(tmp_path: Path) -> None:
    path = tmp_path / "real.json"
    code, output = _invoke("--time", "real", "-q", "--select", "server.reply.here", "--json", str(path))
    assert code == ExitCode.CONFORMANT, output
    assert json.loads(path.read_text())["time"] == "real"
    assert "--time real" in json.loads(path.read_text())["cases"][0]["reproduce"]


def _report(
    seed: int, outcomes: dict[str, str], packets: dict[str, list[WirePacket]] | None = None
) -> RunReport:
    report = RunReport(target="", embedded=True, seed=seed, strict=False, options={}, command="")
    for case_id, outcome in outcomes.items():
        result = CaseResult(
            id=case_id,
            clauses=(),
            level="MUST",
            kind="scripted",
            hazard="read-only",
            summary="",
            outcome=outcome,  # type: ignore[arg-type]
            seed=seed,
            deadline=5.0,
        )
        result.packets = list((packets or {}).get(case_id, []))
        report.results.append(result)
    return report


def test_instability_names_the_case_and_the_seeds() -> None:
    seeds = repeat_seeds(5, 3)
    assert seeds[0] == 5 and len(set(seeds)) == 3
    steady = [_report(s, {"a": "pass", "b": "fail"}) for s in [*seeds, seeds[0]]]
    assert instability(steady, compare_packets=True) == []
    flaky = [
        _report(seeds[0], {"a": "pass"}),
        _report(seeds[1], {"a": "fail"}),
        _report(seeds[0], {"a": "pass"}),
    ]
    (problem,) = instability(flaky, compare_packets=False)
    assert "case a changes its verdict" in problem and str(seeds[1]) in problem
    first = WirePacket("c2s", 0o201, 2, 0, b"", 0.0)
    moved = WirePacket("c2s", 0o201, 2, 0, b"", 0.016)
    twice = [_report(5, {"a": "pass"}, {"a": [first]}), _report(5, {"a": "pass"}, {"a": [moved]})]
    (problem,) = instability(twice, compare_packets=True)
    assert "different packets" in problem and "packet 0" in problem
    assert instability(twice, compare_packets=False) == []
    flipped = [_report(5, {"a": "pass"}), _report(5, {"a": "warn"})]
    assert any("same seed 5" in p for p in instability(flipped, compare_packets=False))


def test_an_unstable_report_exits_4() -> None:
    report = _report(1, {"a": "pass"})
    report.unstable.append("case a changes its verdict with the seed")
    assert report.exit_code == ExitCode.INTERNAL
    assert report.verdict == "unstable suite"


ARRANGED = (
    "server.async.guard-trip-live",
    "server.async.warning-format",
    "server.error.fatal-then-close",
    "server.motion.abort-drops-queue",
    "server.motion.collision",
    "server.wrist.no-answer",
    "server.wrist.force-push",
)
"""Cases that have the world arrange a condition for their connections (a lagging joint, a failing
calibration, an obstacle, a silent Cougar, the panic button, a push on the hand): a capture does not
record the world, so the replay's plain server answers those sessions differently."""


@pytest.mark.slow
def test_one_seed_gives_the_same_capture_message_for_message_and_it_replays_cleanly(tmp_path: Path) -> None:
    # Two recorded runs of one seed, then a replay of the first: three whole runs where the two properties
    # took three and one apart (the CI budget).
    skips = [arg for case_id in ARRANGED for arg in ("--skip", case_id)]
    captures = []
    for name in ("a.mcap", "b.mcap"):
        code, output = _invoke("--seed", "6", "-q", "--record", str(tmp_path / name), *skips)
        assert code == ExitCode.CONFORMANT, output
        captures.append(_messages(tmp_path / name))
    assert len(captures[0]) > 1000
    assert captures[0] == captures[1]
    report_path = tmp_path / "replay.json"
    replay = ["replay", str(tmp_path / "a.mcap"), "-q", "--json", str(report_path)]
    result = CliRunner().invoke(main, replay)
    assert result.exit_code == ExitCode.CONFORMANT, result.output
    report = json.loads(report_path.read_text())
    outcomes = {c["outcome"] for c in report["cases"]}
    assert outcomes <= {"pass", "skip"}
    passed = [c for c in report["cases"] if c["outcome"] == "pass"]
    assert len(passed) > 200  # every session's exchange and checks
    skipped = [c["reason"] for c in report["cases"] if c["outcome"] == "skip"]
    assert all("never opened" in reason for reason in skipped)  # the refused second client only


@pytest.mark.parametrize("seed", [1, 2, 3, 6, 7])
def test_captures_of_motion_replay_exactly(tmp_path: Path, seed: int) -> None:
    # A segment ending on a servo tick once ended a tick later in the replay than in the run (the run's
    # request instants carried sub-nanosecond noise that a capture's nanoseconds cannot keep), and the
    # replay then failed the segment report's request number.
    capture = tmp_path / "motion.mcap"
    motion = ("server.motion.queued-segments", "server.motion.straight-line", "server.motion.ready")
    code, output = _invoke("--seed", str(seed), "-q", "--record", str(capture), *_select(motion))
    assert code == ExitCode.CONFORMANT, output
    result = CliRunner().invoke(main, ["replay", str(capture), "-q"])
    assert result.exit_code == ExitCode.CONFORMANT, result.output


def _select(case_ids: tuple[str, ...]) -> list[str]:
    return [arg for case_id in case_ids for arg in ("--select", case_id)]


# The simulated world: everything that runs on the run's loop in virtual time.  Reading the wall clock
# here makes a verdict depend on how busy the machine is (a case once timed a move with
# time.monotonic and failed at random under load).
SIMULATED = (
    "conformance/cases",
    "conformance/suite",
    "conformance/judge",
    "reference_server",
    "arm",
    "cougar",
    "ncp",
    "links",
)
# The run's own report: when it started and how long it took, in wall time, for people.
WALL_CLOCK_ALLOWED = {"conformance/suite/runner.py": 3, "conformance/suite/context.py": 1}
WALL_CLOCK = ("time.monotonic", "time.perf_counter", "time.time", "datetime.now", "from time import")


def test_the_simulated_world_reads_time_only_from_the_loop() -> None:
    src = ROOT / "src" / "manip"
    found: dict[str, int] = {}
    for area in SIMULATED:
        for path in sorted((src / area).rglob("*.py")):
            code = [line.split("#")[0] for line in path.read_text().splitlines()]
            hits = sum(line.count(word) for line in code for word in WALL_CLOCK)
            if hits:
                found[str(path.relative_to(src))] = hits
    assert found == WALL_CLOCK_ALLOWED


def test_a_guard_left_by_an_earlier_case_does_not_stop_a_later_one() -> None:
    # Seed 1038366354: the well-formed property case leaves a stop guard set on the wrist; a later
    # motion case cleared the guards, but the guard tripped on the tick the clears arrived (Cougar checks
    # guards before it reads commands), and the case skipped.  Pinned, as any seed the gate finds.
    picks = ["property.requests.well-formed", "property.segments.numbering", "server.async.segment-completed"]
    code, output = _invoke("--seed", "1038366354", "-q", *[a for p in picks for a in ("--select", p)])
    assert code == ExitCode.CONFORMANT, output
    assert "3 pass in" in output, output
