"""``manip-conform diff`` end to end against embedded reference servers in virtual time: two clean
servers never differ, a protocol fault shows as a violation of the clause the fault matrix names, the
two error-argument layouts differ only as both allowed, the guide-only profile's differences are all
classified; the same seed sends the same streams, a difference that comes and goes is unstable, and
the reports follow their schema."""

from __future__ import annotations

import json
import socket
from dataclasses import replace
from pathlib import Path

import pytest
from click.testing import CliRunner

from manip.conformance.cli import main as conform_main
from manip.conformance.diff import driver, sides
from manip.conformance.diff.driver import DiffConfig, diff_stream, run_diff
from manip.conformance.diff.pairing import SideEvent
from manip.conformance.diff.report import load_schema
from manip.conformance.diff.scenarios import chaos, scenario
from manip.conformance.diff.sides import Observation, Side, input_link
from manip.conformance.diff.streams import make_streams
from manip.conformance.fuzz.generators import GenOptions
from manip.conformance.fuzz.session import Allowance
from manip.conformance.suite.embedded import SimulatedLink
from manip.reference_server import FaultSet, ServerConfig
from manip.reference_server.faults import Fault
from tests.support.json_schema import validate

pytestmark = pytest.mark.timeout(300)

CLEAN = Side("A", "clean", config=ServerConfig())
ERRORS = GenOptions(select=("manip.unknown-opcode", "manip.wrong-length"))
"""Inputs that draw error strings with numbers: every fault below shows in their answers."""


def _findings(b: Side, seed: int, *, streams: int = 2, length: int = 4, gen: GenOptions = ERRORS) -> list:  # type: ignore[type-arg]
    results = run_diff(CLEAN, b, make_streams(seed, streams, length, gen), DiffConfig(seed, shrink=False))
    assert not any(r.unstable for r in results)
    return [f for r in results for f in r.findings]


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(10))
def test_two_clean_servers_never_differ(seed: int) -> None:
    results = run_diff(
        CLEAN,
        Side("B", "clean", config=ServerConfig()),
        make_streams(seed, 1, 3, GenOptions()),
        DiffConfig(seed),
    )
    assert results[0].findings == [] and not results[0].unstable


@pytest.mark.slow
@pytest.mark.parametrize(
    "fault", [Fault.UOP_OPCODE_SWAPPED, Fault.BDL_COUNTS_SWAPPED, Fault.ERROR_PAD_MISPLACED], ids=str
)
def test_a_protocol_fault_is_a_violation_of_its_clause(fault: Fault) -> None:
    faulty = Side("B", fault.value, config=ServerConfig(faults=FaultSet.parse([fault.value])))
    gen = GenOptions(select=("manip.wrong-length",)) if fault == Fault.BDL_COUNTS_SWAPPED else ERRORS
    found = _findings(faulty, 7, streams=3, length=6, gen=gen)
    violations = [f for f in found if f.cls == "violation" and not f.follows]
    assert violations, [(f.cls, f.names) for f in found]
    assert all(f.violator == "B" for f in violations)
    assert set(fault.clauses) <= {n for f in violations for n in f.names}


@pytest.mark.slow
def test_the_two_error_argument_layouts_are_both_allowed() -> None:
    packed = Side("B", "packed", config=ServerConfig(error_args="packed"))
    found = _findings(packed, 3)
    assert found
    assert {f.cls for f in found} == {"allowed"}
    assert all(f.names[0] == "error-arg-layout" for f in found)


@pytest.mark.slow
def test_every_difference_from_the_guide_profile_is_classified() -> None:
    guide = Side("B", "guide", config=ServerConfig.guide_profile())
    found = _findings(guide, 5, streams=3, length=8, gen=GenOptions())
    assert found
    assert all(f.cls in ("violation", "allowed", "unexplained") and f.names for f in found)
    assert not [f for f in found if f.cls == "violation"], "the guide profile conforms"
    assert {"allowed"} <= {f.cls for f in found}


@pytest.mark.slow
def test_the_guide_profile_passes_the_scenarios_of_lengths() -> None:
    """The scenarios whose requests carry lengths (transforms, increments), against the guide profile in
    inches: nothing broken, and what differs is the length unit (erratum units)."""
    guide = Side("B", "guide", config=ServerConfig.guide_profile())
    names = ("configuration", "increments", "paths")
    results = run_diff(CLEAN, guide, [scenario(n) for n in names], DiffConfig(5, shrink=False))
    found = [f for r in results for f in r.findings]
    assert found and not any(r.unarranged or r.unstable for r in results)
    assert {f.cls for f in found} == {"allowed"}, [
        (f.stream, f.cls, f.names) for f in found if f.cls != "allowed"
    ]
    assert {n for f in found for n in f.names} & {"units", "move.transform-data", "solve-forwards.data"}


@pytest.mark.slow
@pytest.mark.parametrize("link", ["unix", "chudp", "chaosd"])
def test_the_chaos_scenarios_name_neither_a_clean_server_nor_the_guide_profile(link: SimulatedLink) -> None:
    """The Chaos level's scenarios, a clean server against another and against the guide profile, over
    each link (CHUDP and chaosd with one stream of their link's inputs too): no violation, none unstable."""
    streams = [scenario(name) for name in chaos.SCENARIOS]
    if link != "unix":
        streams += make_streams(7, 1, 4, GenOptions(link=input_link(link)))
    clean = replace(CLEAN, link=link)
    for b in (
        Side("B", "clean", config=ServerConfig()),
        Side("B", "guide", config=ServerConfig.guide_profile()),
    ):
        results = run_diff(clean, replace(b, link=link), streams, DiffConfig(7, shrink=False))
        assert not any(r.unstable or r.runaway for r in results), b.label
        found = [(r.stream.label, f.cls, f.names) for r in results for f in r.findings]
        assert not [f for f in found if f[1] != "allowed"], (b.label, found)
        assert b.label == "guide" or not found


def test_a_link_other_than_the_unix_socket_needs_embedded_sides(tmp_path: Path) -> None:
    code, _, output = _cli(tmp_path, "tcp://127.0.0.1:1", "embedded", "--link", "chudp")
    assert code == 2 and "--link chudp" in output


def test_the_same_seed_gives_the_same_streams() -> None:
    assert make_streams(11, 3, 5, GenOptions()) == make_streams(11, 3, 5, GenOptions())
    assert make_streams(11, 3, 5, GenOptions()) != make_streams(12, 3, 5, GenOptions())


def test_a_difference_that_comes_and_goes_is_unstable(monkeypatch: pytest.MonkeyPatch) -> None:
    calls = []

    def flaky(side: Side, stream: object, allowance: object, seed: int) -> Observation:
        calls.append(side.name)
        odd = side.name == "B" and len(calls) <= 2
        data = b"\x01\x00" + (b"\x01" if odd else b"\x00")
        return Observation({-1: [SideEvent("packet", 0o200, data)]})

    monkeypatch.setattr(driver, "observe", flaky)
    result = diff_stream(CLEAN, Side("B", "flaky"), make_streams(1, 1, 1, GenOptions())[0], DiffConfig(1))
    assert result.unstable and result.findings == [] and len(calls) == 4


def _cli(tmp_path: Path, *args: str) -> tuple[int, dict, str]:  # type: ignore[type-arg]
    out = tmp_path / "diff.json"
    result = CliRunner().invoke(
        conform_main,
        [
            "diff",
            *args,
            "--json",
            str(out),
            "--markdown",
            str(tmp_path / "d.md"),
            "--junit",
            str(tmp_path / "d.xml"),
            "--html",
            str(tmp_path / "d.html"),
        ],
        catch_exceptions=False,
    )
    report = json.loads(out.read_text()) if out.exists() else {}
    return result.exit_code, report, result.output


@pytest.mark.slow
def test_the_command_reports_a_violation_and_replays_it(tmp_path: Path) -> None:
    args = [
        "embedded",
        "embedded",
        "--server-fault-b",
        "error-pad-misplaced",
        "--seed",
        "7",
        "--streams",
        "3",
        "--length",
        "6",
        "--class",
        "manip.unknown-opcode",
        "--class",
        "manip.wrong-length",
        "--no-scenarios",
    ]
    code, report, output = _cli(tmp_path, *args)
    validate(report, load_schema())
    assert code == 1 and report["counts"]["violation"] >= 1, output
    finding = next(f for f in report["findings"] if f["class"] == "violation")
    assert finding["names"] == ["error-string.arg-layout"] and finding["violator"] == "B"
    assert "<failure" in (tmp_path / "d.xml").read_text()
    assert "error-string.arg-layout" in (tmp_path / "d.md").read_text()
    page = (tmp_path / "d.html").read_text()
    assert "error-string.arg-layout" in page and "<mark>" in page
    assert "\n" not in finding["reproduce"] and finding["reproduce"].startswith("manip-conform diff ")
    replay = finding["reproduce"].split()[2:]  # without "manip-conform diff"
    code_again, again, _ = _cli(tmp_path, *replay)
    assert code_again == 1 and any(f["class"] == "violation" for f in again["findings"])


@pytest.mark.slow
def test_the_command_passes_two_clean_servers_and_allowed_differences(tmp_path: Path) -> None:
    code, report, output = _cli(
        tmp_path, "embedded", "embedded", "--seed", "2", "--streams", "2", "--length", "3"
    )
    assert code == 0 and report["counts"] == {"violation": 0, "allowed": 0, "unexplained": 0}, output
    args = [
        "embedded",
        "embedded",
        "--error-args-b",
        "packed",
        "--seed",
        "2",
        "--streams",
        "2",
        "--class",
        "manip.unknown-opcode",
        "--no-scenarios",
    ]
    code, report, output = _cli(tmp_path, *args)
    assert code == 0 and report["counts"]["allowed"] >= 1 and report["counts"]["violation"] == 0, output


def test_server_options_apply_to_an_embedded_side_only(tmp_path: Path) -> None:
    code, _, output = _cli(tmp_path, "tcp://127.0.0.1:1", "embedded", "--server-fault-a", "keeps-speed")
    assert code == 2 and "embedded side A only" in output
    code, _, output = _cli(tmp_path, "embedded", "embedded", "--server-fault-b", "no-such-fault")
    assert code == 2 and "--server-fault-b" in output


def test_a_side_that_does_not_finish_its_stream_is_a_runaway(monkeypatch: pytest.MonkeyPatch) -> None:
    """The bound is in virtual seconds for an embedded side, where a request takes none: a bound of 0 ends
    the stream at once."""
    monkeypatch.setattr(sides, "stream_bound", lambda stream, allowance: 0.0)
    stream = make_streams(1, 1, 2, GenOptions(select=("manip.sequence",)))[0]
    seen = sides.observe(CLEAN, stream, Allowance(), 1)
    assert seen.runaway is not None and "did not finish the stream" in seen.runaway
    assert [s.violation.kind for s in seen.sightings] == ["timeout"]
    last = stream.all_inputs[-1].number
    assert seen.events[last][0].kind == "stream"


def test_an_unreachable_side_exits_3(tmp_path: Path) -> None:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    code, report, output = _cli(tmp_path, f"tcp://127.0.0.1:{port}", "embedded", "--connect-timeout", "1")
    assert code == 3 and report["verdict"] == "a side unreachable", output
    assert "side A" in report["problems"][0]


@pytest.mark.slow
def test_the_same_seed_gives_the_same_report(tmp_path: Path) -> None:
    args = [
        "embedded",
        "embedded",
        "--server-profile-b",
        "guide",
        "--seed",
        "4",
        "--streams",
        "2",
        "--no-scenarios",
    ]
    first = _cli(tmp_path, *args)[1]
    second = _cli(tmp_path, *args)[1]
    assert first["counts"]["allowed"] > 0
    assert first["findings"] == second["findings"] and first["counts"] == second["counts"]
