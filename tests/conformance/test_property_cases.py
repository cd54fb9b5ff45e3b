"""The property-based cases against the embedded reference server: they pass on the clean server, each
fails on the defect it is about (with the packets of the shrunk example in the report), the same seed
gives the same run, hardware targets get no motion, and the Hypothesis bridge stops when cancelled."""

from __future__ import annotations

import asyncio
import re
import threading
import time
from collections.abc import Sequence

import pytest

from manip.conformance.suite import bridge
from manip.conformance.suite.bridge import Bridge, StopRun, run_in_worker
from manip.conformance.suite.case import all_cases
from manip.conformance.suite.results import CaseResult, RunReport
from manip.reference_server.faults import FaultSet
from manip.reference_server.session import ServerConfig
from manip.spec import SPEC
from tests.support.suite import run_suite

TIME_SCALE = 8.0


@pytest.fixture(autouse=True)
def short_shrinking(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(bridge, "DEFAULT_SHRINK_BUDGET", 2.0)


def run(
    ids: Sequence[str], faults: Sequence[str] = (), *, seed: int = 5, examples: int = 10, **options: object
) -> RunReport:
    config = ServerConfig(faults=FaultSet.parse(faults))
    cases = [c for c in all_cases() if c.id in ids]
    assert len(cases) == len(ids)
    opts = {"max_examples": examples, **options}
    return run_suite(cases, config, seed=seed, time_scale=TIME_SCALE, options=opts)


def result(report: RunReport, case_id: str) -> CaseResult:
    return next(r for r in report.results if r.id == case_id)


PROPERTY_CASES = (
    "property.requests.well-formed",
    "property.kinematics.round-trip",
    "property.floats.round-trip",
    "property.segments.numbering",
)


def test_clean_server_passes_the_property_cases() -> None:
    report = run(PROPERTY_CASES)
    for r in report.results:
        assert r.outcome == "pass", (r.id, r.reason, [v.message for v in r.violations])
        assert any("examples run" in n for n in r.notes)


@pytest.mark.parametrize(
    ("case_id", "fault", "outcome", "clauses"),
    [
        (
            "property.requests.well-formed",
            "error-without-colon",
            "fail",
            # the lost ': ' also shifts the numbers: half a word left, or a pad byte no longer due
            {"error-string.format", "error-string.args", "error-string.arg-layout"},
        ),
        ("property.requests.well-formed", "wrong-request-number", "fail", {"response.echoes-request-number"}),
        (
            "property.kinematics.round-trip",
            "swapped-float-words",
            "fail",
            {
                "solve-backwards.data",
                "float.reserved-operand",
                "float.format",
                "solve-forwards.errors",
                "solve-forwards.data",
            },
        ),
        (
            "property.floats.round-trip",
            "swapped-float-words",
            "fail",
            {"float.format", "float.reserved-operand"},
        ),
        ("property.segments.numbering", "segment-number-stuck", "warn", {"segment.number-increases"}),
    ],
)
def test_property_case_catches_its_defect(case_id: str, fault: str, outcome: str, clauses: set[str]) -> None:
    r = result(run([case_id], [fault]), case_id)
    assert r.outcome == outcome, (r.reason, r.traceback)
    assert r.violations[0].clause in clauses
    assert r.violations[0].actual


def test_a_failure_shows_the_falsifying_example_and_the_same_seed_finds_it_again() -> None:
    first = result(
        run(["property.requests.well-formed"], ["error-without-colon"], seed=9),
        "property.requests.well-formed",
    )
    again = result(
        run(["property.requests.well-formed"], ["error-without-colon"], seed=9),
        "property.requests.well-formed",
    )
    assert first.outcome == again.outcome == "fail"
    shown = first.violations[0].actual
    assert "shrunk example: " in shown  # what Hypothesis drew, by request name and octal opcode
    assert "packets of the example" in shown and "RequestOpcode(" not in shown
    requests = [line for line in shown.splitlines() if re.match(r"  [ >] +\d+  c2s ", line)]
    assert requests and all(re.search(r" 0[0-7]{3} \(packet number \d+, ", line) for line in requests)
    assert first.violations[0].actual == again.violations[0].actual
    # the case's packet log is the shrunk example's run, and the violation's culprit is in it
    violation = first.violations[0]
    assert violation.packet is not None and any(p is violation.packet for p in first.packets)
    marked = [line for line in shown.splitlines() if re.match(r"  > +\d+  ", line)]
    assert marked and len(first.packets) <= len(
        [ln for ln in shown.splitlines() if re.match(r"  [ >] +\d+  ", ln)]
    )


def test_a_float_round_trip_names_the_swap() -> None:
    r = result(run(["property.floats.round-trip"], ["swapped-float-words"]), "property.floats.round-trip")
    assert r.outcome == "fail"
    message = r.violations[0].message  # the read-back differs; the bytes swapped back are what was sent
    assert "with the two words of each float swapped, the values expected" in message, message


def test_hardware_target_without_motion_sends_no_motion_or_power_request() -> None:
    report = run(PROPERTY_CASES, target="hardware")
    assert result(report, "property.floats.round-trip").outcome == "skip"
    assert result(report, "property.segments.numbering").outcome == "skip"
    sent = [p.opcode for r in report.results for p in r.packets if p.direction == "c2s" and not p.is_close]
    assert sent
    hazards = {SPEC.requests[o].hazard for o in sent if o in SPEC.requests}
    assert hazards <= {"read-only", "config"}
    assert result(report, "property.requests.well-formed").outcome == "pass"


def test_bridge_runs_coroutines_on_the_loop_and_stops_when_cancelled() -> None:
    calls: list[int] = []
    stopped = threading.Event()

    async def step(i: int) -> int:
        calls.append(i)
        await asyncio.sleep(0.01)
        return i * 2

    def work(b: Bridge) -> None:
        assert b.call(step(1)) == 2
        try:
            for i in range(2, 1000):
                b.call(step(i))
        except StopRun:
            stopped.set()
            raise

    async def go() -> None:
        task = asyncio.create_task(run_in_worker(work))
        for _ in range(500):  # until the worker is well under way
            if len(calls) >= 3:
                break
            await asyncio.sleep(0.01)
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task
        await asyncio.sleep(0.1)

    asyncio.run(go())
    assert stopped.wait(2.0)
    assert 3 <= len(calls) < 400


def test_bridge_budget_ends_the_run_after_a_failure() -> None:
    async def nothing() -> None:
        await asyncio.sleep(0.005)

    def work(b: Bridge) -> str:
        b.failure_seen()
        start = time.monotonic()
        try:
            while True:
                b.call(nothing())
        except StopRun:
            return f"{time.monotonic() - start:.2f}"

    waited = float(asyncio.run(run_in_worker(work, shrink_budget=0.2)))
    assert 0.15 <= waited < 2.0
