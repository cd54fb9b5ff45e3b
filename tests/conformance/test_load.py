"""Timing checks on a busy host: a check that times the arm allows the delays it measured and, when they
(or the gaps between its samples) are larger than what it measures, says not-judged with those figures;
it never passes then, and never fails a conforming server for them.

The host's load is played in virtual time, so these tests give the same answer on any machine: samples
taken far apart (a longer sampling interval) stand for a loaded host's late timers, and
``host_delay`` is made to report a large delay."""

from __future__ import annotations

import re

import pytest

from manip.conformance.cases.server import motion, trajectory
from manip.conformance.suite.case import all_cases
from manip.conformance.suite.results import CaseResult
from manip.reference_server import FaultSet, ServerConfig
from tests.support.suite import run_simulated

SEED = 5
COARSE_S = 0.05
"""A sampling interval as a loaded host leaves it: 50 ms, three servo cycles."""


def _run(case_id: str, faults: tuple[str, ...] = ()) -> CaseResult:
    cases = [c for c in all_cases() if c.id == case_id]
    (result,) = run_simulated(cases, ServerConfig(faults=FaultSet.parse(list(faults))), seed=SEED).results
    return result


@pytest.mark.parametrize("faults", [(), ("segments-stop",), ("servo-double-rate",)], ids=str)
def test_the_embedded_target_is_judged_exactly(faults: tuple[str, ...]) -> None:
    result = _run("server.motion.queued-segments", faults)
    assert result.outcome == ("warn" if faults else "pass"), (
        result.outcome,
        result.reason,
        result.violations,
    )


@pytest.mark.parametrize("faults", [(), ("segments-stop",), ("servo-double-rate",)], ids=str)
def test_samples_too_far_apart_never_pass_nor_fail_a_clean_server(
    monkeypatch: pytest.MonkeyPatch, faults: tuple[str, ...]
) -> None:
    monkeypatch.setattr(trajectory, "SAMPLE_S", COARSE_S)
    result = _run("server.motion.queued-segments", faults)
    if result.outcome == "not-judged":
        assert "motion.servo-period: two samples in a row typically spanned 100.0 ms" in result.reason
        assert "timers up to 0.0 ms late" in result.reason, result.reason
    else:
        assert faults and result.outcome == "warn", (result.outcome, result.reason, result.violations)
    if not faults:
        assert result.outcome == "not-judged"
        assert re.search(
            r"motion.smooth-transitions: a stop of up to \d+ ms could have gone unseen", result.reason
        )


@pytest.mark.parametrize(
    ("case_id", "clause"),
    [("server.speed.scales", "speed"), ("server.connect.fresh-state", "per-connection-state (speed)")],
)
def test_a_timing_the_host_delays_more_than_it_measures_is_not_judged(
    monkeypatch: pytest.MonkeyPatch, case_id: str, clause: str
) -> None:
    async def late(_: object) -> float:
        return 30.0

    monkeypatch.setattr(motion, "host_delay", late)
    result = _run(case_id)
    assert result.outcome == "not-judged", (result.outcome, result.reason, result.violations)
    assert "ended up to 30000.0 ms late: too close to tell" in result.reason and clause in result.reason
