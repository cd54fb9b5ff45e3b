"""The silent-peer scenario: not sent until the diff is told both sides' broken-connection timers; made
for the longer of them, silent past it by the directed case's margin; a clean server and the guide
profile give the silent connection up and are named by nothing; a server that keeps it is named on its
side, by the command too, whose reproduce line tells the timer again."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from manip.conformance.cases.server.ncp import broken_slack
from manip.conformance.cli import main as conform_main
from manip.conformance.diff import driver
from manip.conformance.diff.driver import DiffConfig, diff_stream, run_diff
from manip.conformance.diff.scenarios import scenario
from manip.conformance.diff.scenarios.silence import NAME, REFERENCE_TIMER, silent_peer
from manip.conformance.diff.sides import BOUND_BASE, Observation, Side, observe, stream_bound
from manip.conformance.diff.streams import Stream
from manip.conformance.fuzz.session import Allowance
from manip.conformance.fuzz.steps import Silence
from manip.reference_server import ServerConfig

pytestmark = pytest.mark.timeout(120)

TIMER = 3.0
"""A short timer (s): the silence costs few servo ticks in virtual time."""
CLEAN = Side("A", "clean", config=ServerConfig(), broken_after=TIMER)


def _unobserved(side: Side, stream: object, allowance: object, seed: int) -> Observation:
    raise AssertionError(f"side {side.name} was sent a scenario it must not be")


def test_the_scenario_is_not_sent_until_both_timers_are_known(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(driver, "observe", _unobserved)
    untold = replace(CLEAN, broken_after=None)
    for a, b, whose in ((untold, replace(untold, name="B"), "sides A and B"), (CLEAN, untold, "side B")):
        result = diff_stream(a, replace(b, name="B"), scenario(NAME), DiffConfig(1))
        assert whose in result.unarranged and "--broken-after" in result.unarranged
        assert result.findings == []


def test_the_silence_outlasts_the_longer_timer_by_the_cases_margin(monkeypatch: pytest.MonkeyPatch) -> None:
    told: list[float] = []

    def observed(side: Side, stream: Stream, allowance: object, seed: int) -> Observation:
        told.extend(s.seconds for i in stream.inputs for s in i.steps if isinstance(s, Silence))
        return Observation()

    monkeypatch.setattr(driver, "observe", observed)
    diff_stream(CLEAN, replace(CLEAN, name="B", broken_after=2 * TIMER), scenario(NAME), DiffConfig(1))
    assert told == [2 * TIMER + broken_slack(2 * TIMER)] * 2
    silent = REFERENCE_TIMER + broken_slack(REFERENCE_TIMER)
    assert stream_bound(silent_peer(REFERENCE_TIMER), Allowance()) > BOUND_BASE + silent  # no runaway


@pytest.mark.slow
def test_a_clean_server_and_the_guide_profile_give_the_silent_connection_up() -> None:
    for b in (
        replace(CLEAN, name="B"),
        Side("B", "guide", config=ServerConfig.guide_profile(), broken_after=TIMER),
    ):
        (result,) = run_diff(CLEAN, b, [scenario(NAME)], DiffConfig(7, shrink=False))
        assert not (result.unarranged or result.unstable or result.runaway or result.findings), b.label
    seen = observe(CLEAN, silent_peer(TIMER), Allowance(), 7)
    assert [e.text.split()[0] for e in seen.events[0] if e.kind == "end"] == ["LOS"]
    assert not seen.sightings


def _cli(tmp_path: Path, *args: str) -> tuple[int, dict[str, Any], str]:
    out = tmp_path / "diff.json"
    result = CliRunner().invoke(
        conform_main, ["diff", *args, "--json", str(out), "--seed", "7", "--scenario", NAME]
    )
    return result.exit_code, json.loads(out.read_text()), result.output


@pytest.mark.slow
def test_a_server_that_keeps_the_silent_connection_is_named_on_its_side(tmp_path: Path) -> None:
    code, report, output = _cli(
        tmp_path,
        "embedded",
        "embedded",
        "--server-fault-a",
        "silent-peer-kept",
        "--broken-after",
        f"{TIMER:g}",
    )
    assert code == 1, output
    violations = [f for f in report["findings"] if f["class"] == "violation"]
    assert violations and {(f["violator"], tuple(f["names"])) for f in violations} == {("A", ("ncp.broken",))}
    assert f"--broken-after {TIMER:g}" in violations[0]["reproduce"]
    code, report, output = _cli(tmp_path, "embedded", "embedded", "--server-fault-a", "silent-peer-kept")
    assert code == 0 and report["findings"] == [], output
    assert "--broken-after" in report["not_arranged"][0]["detail"]
