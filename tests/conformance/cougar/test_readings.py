"""The Cougar suite is fair: the reference Cougar passes with its own declared map and with another one,
the memory cases are not judged without a map (never failed on a different one), and every other reading
of the 1985 guide the simulated Cougar can take (``manip.cougar.readings``) passes."""

from __future__ import annotations

import asyncio
from collections.abc import Iterable
from dataclasses import replace
from pathlib import Path

import pytest
from click.testing import CliRunner

from manip.conformance.cli import main as conform_main
from manip.conformance.cougar.target import CougarTarget, cougar_cases, run_cougar_suite, wait_idle
from manip.conformance.suite.case import all_cases
from manip.conformance.suite.context import RunOptions
from manip.conformance.suite.results import ExitCode, RunReport
from manip.cougar import CougarConfig, CougarSim
from manip.cougar.cli import main as cougar_main
from manip.cougar.cli import serve_cougar
from manip.cougar.memory_map import memory_map_toml
from manip.cougar.readings import MAP_SHIFT, READINGS
from tests.support.paths import ROOT

OPTIONS = RunOptions(reply_timeout=1.0, connect_timeout=2.0)
EXAMPLE_MAP = ROOT / "examples" / "cougar-memory-map.toml"
#: The cases that read or write Cougar memory at the addresses of a map.
MEMORY_CASES = {
    "cougar.memory.deposit-examine",
    "cougar.memory.parameters",
    "cougar.adc8.integer-filter",
    "cougar.forces.conversion",
    "cougar.rst.zeroes-velocities",
    "cougar.filter.output",
    "cougar.jacob.front-buffer-complete",
    "cougar.jacob.transpose-stored",
    "cougar.jacob.values",
    "cougar.npr.damping-matrix",
    "cougar.gravity.nfv-redoes-model",
    "cougar.rraw.before-offsets",
}
#: A reading whose clause is judged only on a Cougar that does what the other reading does not: the case
#: that cannot apply to it, and is skipped.
SKIPPED_BY = {"guts-every-tick": {"cougar.guts.reentry"}}


def outcomes(report: RunReport) -> dict[str, str]:
    return {r.id: r.outcome for r in report.results}


def problems(report: RunReport) -> list[tuple[str, str, object]]:
    return [(r.id, r.outcome, r.violations or r.reason) for r in report.results if r.outcome != "pass"]


def run_external(
    readings: Iterable[str], memory_map: Path | None, options: RunOptions = OPTIONS
) -> RunReport:
    """The Cougar cases against a reference Cougar served over TCP (an external target: no map of its
    own is assumed), with ``readings`` and the map file ``memory_map`` declared (or none)."""

    async def scenario() -> RunReport:
        sim = CougarSim(CougarConfig(readings=frozenset(readings)), seed=2)
        async with serve_cougar(sim, "tcp://127.0.0.1:0") as server:
            target = CougarTarget.parse(server.address, memory_map=memory_map)
            report = await run_cougar_suite(target, seed=3, options=options)
            await wait_idle(server)
            return report

    return asyncio.run(scenario())


# ------------------------------------------------------------------------------------------ the memory map
@pytest.mark.slow
def test_reference_cougar_passes_with_its_own_declared_map() -> None:
    report = run_external((), EXAMPLE_MAP)
    assert set(outcomes(report)) == {c.id for c in cougar_cases(all_cases(), cougar=True)}
    assert not problems(report)
    assert report.exit_code == ExitCode.CONFORMANT


@pytest.mark.slow
def test_reference_cougar_passes_with_another_declared_map(tmp_path: Path) -> None:
    moved = tmp_path / "moved.toml"
    moved.write_text(memory_map_toml(MAP_SHIFT))
    report = run_external(["relocated-map"], moved)
    assert not problems(report)
    assert {i for i, o in outcomes(report).items() if o == "pass"} >= MEMORY_CASES


@pytest.mark.slow
def test_memory_cases_are_not_judged_without_a_map() -> None:
    report = run_external(["relocated-map"], None)
    got = outcomes(report)
    assert {i for i, o in got.items() if o == "not-judged"} == MEMORY_CASES
    assert all(o == "pass" for i, o in got.items() if i not in MEMORY_CASES), problems(report)
    for result in report.results:
        if result.id in MEMORY_CASES:
            assert "--memory-map" in result.reason, result.reason
    assert report.exit_code == ExitCode.CONFORMANT


@pytest.mark.slow
def test_a_wrong_map_declared_is_judged_by_it() -> None:
    """The map is what the cases use: manip's addresses declared for the relocated Cougar fail (the
    check can fail, and a declared map is taken at its word)."""
    report = run_external(["relocated-map"], EXAMPLE_MAP)
    failed = {i for i, o in outcomes(report).items() if o == "fail"}
    assert failed and failed <= MEMORY_CASES


def test_a_map_without_an_object_leaves_its_cases_not_judged(tmp_path: Path) -> None:
    partial = tmp_path / "partial.toml"
    partial.write_text("format = 1\n[objects]\nversion = { address = 0o1000 }\n")
    report = run_external((), partial)
    got = outcomes(report)
    assert got["cougar.memory.deposit-examine"] == "pass"
    result = next(r for r in report.results if r.id == "cougar.memory.parameters")
    assert result.outcome == "not-judged" and "k, b, bji, fc" in result.reason


# ------------------------------------------------------------------------------------------ the readings
@pytest.mark.slow
@pytest.mark.parametrize("reading", sorted(READINGS))
def test_every_reading_the_guide_allows_passes(reading: str) -> None:
    options = replace(OPTIONS, length_unit="inch") if reading == "lengths-in-inches" else OPTIONS
    report = asyncio.run(
        run_cougar_suite(CougarTarget.parse("sim", readings=[reading]), seed=4, options=options)
    )
    got = outcomes(report)
    skipped = {i for i, o in got.items() if o == "skip"}
    assert skipped == SKIPPED_BY.get(reading, set()), problems(report)
    assert all(o in ("pass", "skip") for o in got.values()), problems(report)
    assert report.exit_code == ExitCode.CONFORMANT


@pytest.mark.slow
def test_the_length_unit_is_what_judges_a_cougar_in_inches() -> None:
    """Judged in millimetres, the Cougar in inches fails the conversion: --length-unit is what passes it."""
    report = asyncio.run(
        run_cougar_suite(
            CougarTarget.parse("sim", readings=["lengths-in-inches"]),
            select=["cougar.forces.conversion"],
            options=OPTIONS,
        )
    )
    assert outcomes(report) == {"cougar.forces.conversion": "fail"}


def test_readings_of_an_external_cougar_are_refused() -> None:
    with pytest.raises(ValueError, match="embedded"):
        CougarTarget.parse("tcp://127.0.0.1:1", readings=["out-of-sync-bare"])
    with pytest.raises(ValueError, match="unknown Cougar reading"):
        CougarTarget.parse("sim", readings=["nope"])


# ------------------------------------------------------------------------------------------ the CLI
def test_cli_declares_a_map_and_a_unit(tmp_path: Path) -> None:
    moved = tmp_path / "moved.toml"
    moved.write_text(memory_map_toml(MAP_SHIFT))
    args = ["run", "--cougar", "sim", "--cougar-reading", "relocated-map", "--memory-map", str(moved)]
    args += ["--cougar-reading", "lengths-in-inches", "--length-unit", "inch", "-q", "--seed", "2"]
    args += ["--select", "cougar.memory.*", "--select", "cougar.forces.*"]
    result = CliRunner().invoke(conform_main, args)
    assert result.exit_code == 0, result.output


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--memory-map", "{map}"], "add --cougar"),
        (["--cougar", "sim", "--length-unit", "auto"], "with --cougar name it"),
        (["--cougar-reading", "out-of-sync-bare"], "add --cougar"),
        (["--cougar", "sim", "--memory-map", "{missing}"], "cannot read"),
        (["--cougar", "sim", "--memory-map", "{bad}"], "even byte address 0..0o177776, not 0o1001"),
        (["--cougar", "tcp://127.0.0.1:1", "--cougar-reading", "out-of-sync-bare"], "embedded"),
    ],
)
def test_cli_map_and_reading_usage_errors(tmp_path: Path, args: list[str], says: str) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("format = 1\n[objects]\nversion = { address = 0o1001 }\n")
    paths = {"map": str(EXAMPLE_MAP), "missing": str(tmp_path / "none.toml"), "bad": str(bad)}
    result = CliRunner().invoke(conform_main, ["run", *(a.format(**paths) for a in args)])
    assert result.exit_code == 2, result.output
    assert says in result.output
    assert "Traceback" not in result.output


def test_manip_cougar_prints_its_map_and_offers_the_readings() -> None:
    assert CliRunner().invoke(cougar_main, ["--print-memory-map"]).output == memory_map_toml()
    moved = CliRunner().invoke(cougar_main, ["--print-memory-map", "--cougar-reading", "relocated-map"])
    assert moved.output == memory_map_toml(MAP_SHIFT)
    assert "--cougar-reading" in CliRunner().invoke(cougar_main, ["--help"]).output
    assert CliRunner().invoke(cougar_main, ["--cougar-reading", "nope", "--print-memory-map"]).exit_code == 2


def test_a_reproduce_line_repeats_the_readings_and_the_unit() -> None:
    args = ["run", "--cougar", "sim", "--cougar-reading", "lengths-in-inches", "--length-unit", "cm"]
    result = CliRunner().invoke(conform_main, [*args, "--select", "cougar.forces.conversion", "-q"])
    assert result.exit_code == 1, result.output
    assert (
        "manip-conform run --cougar sim --cougar-reading lengths-in-inches --select cougar.forces.conversion"
        in result.output
    )
    assert "--length-unit cm" in result.output
