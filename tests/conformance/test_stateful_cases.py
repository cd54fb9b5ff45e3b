"""The stateful case against the embedded reference server: it passes on the clean server, a defect of
the arm's state rules fails it with a shrunk, replayable request list, the same seed finds the same
counterexample, and a hardware target without --allow-motion gets no motion or power request."""

from __future__ import annotations

import ast
import asyncio
import re
from collections.abc import Sequence

import pytest

from manip.conformance.cases.server.stateful import replay_async
from manip.conformance.judge.model import MAX_DISTINCT_VIOLATIONS, DistinctViolations
from manip.conformance.output.culprit import culprit_index
from manip.conformance.suite import bridge
from manip.conformance.suite.case import all_cases
from manip.conformance.suite.results import CaseResult
from manip.reference_server.driver import serve
from manip.reference_server.faults import FaultSet
from manip.reference_server.session import ServerConfig
from manip.spec import SPEC
from tests.support.suite import run_simulated, run_suite

CASE = "stateful.arm-model"
TIME_SCALE = 8.0


@pytest.fixture(autouse=True)
def short_shrinking(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(bridge, "DEFAULT_SHRINK_BUDGET", 1.0)


def run(faults: Sequence[str] = (), *, seed: int = 5, examples: int = 10, **options: object) -> CaseResult:
    config = ServerConfig(faults=FaultSet.parse(faults))
    cases = [c for c in all_cases() if c.id == CASE]
    opts = {"max_examples": examples, **options}
    return run_suite(cases, config, seed=seed, time_scale=TIME_SCALE, options=opts).results[0]


def replay_steps(actual: str) -> list[object]:
    """The request list of the replay line of a counterexample."""
    match = re.search(r"replay\('[^']*', (\[.*\])\)", actual)
    assert match, actual
    steps = ast.literal_eval(match.group(1))
    assert isinstance(steps, list)
    return steps


def test_clean_server_passes() -> None:
    r = run(examples=10)
    assert r.outcome == "pass", (r.reason, [v.actual for v in r.violations], r.traceback)
    assert any("runs of up to" in n and "motion and power rules on" in n for n in r.notes)
    sent = {p.opcode for p in r.packets if p.direction == "c2s" and not p.is_close}
    names = {SPEC.requests[o].name for o in sent if o in SPEC.requests}
    assert {"enable-power", "set-joint-angles", "kill-power"} <= names  # the machine really explores
    assert any(o not in SPEC.requests for o in sent)  # and sends malformed requests too


def test_a_server_written_from_the_guide_alone_passes() -> None:
    # the guide profile: no extensions, inches, the 6-byte 0203, configuration bits answered done
    cases = [c for c in all_cases() if c.id == CASE]
    config = ServerConfig.guide_profile()
    report = run_suite(cases, config, seed=5, time_scale=TIME_SCALE, options={"max_examples": 10})
    (r,) = report.results
    assert r.outcome == "pass", (r.reason, [v.actual for v in r.violations], r.traceback)
    sent = {p.opcode for p in r.packets if p.direction == "c2s" and not p.is_close}
    assert {"enable-power", "set-joint-angles"} <= {SPEC.requests[o].name for o in sent if o in SPEC.requests}


@pytest.mark.parametrize(
    ("fault", "clauses"),
    [
        ("no-nap", {"motion.no-power"}),
        ("awa-ignored", {"motion.abort"}),  # found through the abort rule (power killed mid-move)
    ],
)
def test_state_rule_defects_fail_with_a_replayable_counterexample(fault: str, clauses: set[str]) -> None:
    r = run([fault])
    assert r.outcome == "fail", (r.reason, r.traceback)
    violation = r.violations[0]
    assert violation.clause in clauses
    assert "requests of the shrunk counterexample" in violation.actual
    steps = replay_steps(violation.actual)
    assert steps and all(isinstance(s, float) or (isinstance(s, tuple) and len(s) == 2) for s in steps)
    sent = [line for line in violation.actual.splitlines() if re.match(r" +\d+\. #\d+ +0[0-7]{3} ", line)]
    assert len(sent) == sum(1 for s in steps if isinstance(s, tuple))  # each request with its number
    assert "packets of the failing run" in violation.actual
    # the case's packet log is that failing run, and the violation names its culprit there
    assert violation.packet is not None and culprit_index(r.packets, violation) is not None
    assert violation.packet.direction == "s2c"  # what the server got wrong, not the request before it


def test_an_embedded_target_is_reproduced_by_the_command_not_its_socket() -> None:
    """The embedded server's socket is gone after the run: the counterexample says to run the case again
    (the same seed draws it again), not to replay its requests at that address."""
    r = run(["no-nap"], embedded=True)
    actual = r.violations[0].actual
    assert "replay(" not in actual and "reproduce with" in actual
    assert f"--select {CASE} --seed 5" in actual


def test_the_same_seed_finds_the_same_counterexample(monkeypatch: pytest.MonkeyPatch) -> None:
    # no shrinking: a shrink cut short by its time budget depends on timing, generation does not
    monkeypatch.setattr(bridge, "DEFAULT_SHRINK_BUDGET", 0.0)
    first = run(["speed-unchecked"], seed=21)
    again = run(["speed-unchecked"], seed=21)
    assert first.outcome == again.outcome == "fail"
    assert replay_steps(first.violations[0].actual) == replay_steps(again.violations[0].actual)


def test_replay_sends_the_counterexample_again() -> None:
    r = run(["no-nap"])
    steps = replay_steps(r.violations[0].actual)

    async def go() -> list[str]:
        async with serve("tcp://127.0.0.1:0", ServerConfig(faults=FaultSet.parse(["no-nap"]))) as server:
            return await replay_async(server.address, steps, timeout=0.2)  # type: ignore[arg-type]

    lines = asyncio.run(go())
    sent = [line for line in lines if line.startswith("->")]
    assert len(sent) == sum(1 for s in steps if isinstance(s, tuple))
    assert sum(1 for line in lines if line.startswith("  <- 0200")) >= len(sent)  # each answered


def test_hardware_target_without_motion_keeps_to_read_only_and_config() -> None:
    r = run(robot="hardware", examples=8)
    assert r.outcome == "pass", (r.reason, [v.actual for v in r.violations], r.traceback)
    assert any("motion and power rules off" in n for n in r.notes)
    sent = [p.opcode for p in r.packets if p.direction == "c2s" and not p.is_close]
    hazards = {SPEC.requests[o].hazard for o in sent if o in SPEC.requests}
    assert hazards <= {"read-only", "config"}


def test_the_model_goes_on_after_a_disagreement_and_reports_each_distinct_one(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Two defects of the state rules in one server: the run does not stop at the first, so both show,
    the first shrunk, the others with the run up to them; each kind once."""
    # In virtual time (a loaded host cannot end the examples early), with the 25 examples of a run and
    # a shrinking budget of simulated seconds: the run goes on after the first disagreement, so the
    # other defect shows too.
    config = ServerConfig(faults=FaultSet.parse(["no-nap", "speed-unchecked"]))
    cases = [c for c in all_cases() if c.id == CASE]
    r = run_simulated(cases, config, seed=7, options={"max_examples": 25}).results[0]
    assert r.outcome == "fail", (r.reason, r.traceback)
    clauses = [v.clause for v in r.violations]
    assert {"motion.no-power", "speed.range"} <= set(clauses), (clauses, r.notes)
    assert "requests of the shrunk counterexample" in r.violations[0].actual
    assert any("requests of the run up to it (not shrunk)" in v.actual for v in r.violations[1:])
    assert len(r.violations) <= MAX_DISTINCT_VIOLATIONS + 1
    assert "motion.no-power" in r.reached and "speed.range" in r.reached


def test_distinct_violations_keep_each_kind_once_up_to_the_bound() -> None:
    found: DistinctViolations[int] = DistinctViolations(bound=2)
    assert found.add(("speed.range", "set_speed"), 1)
    assert not found.add(("speed.range", "set_speed"), 2)  # the same kind again
    assert found.add(("motion.no-power", "move"), 3)
    assert not found.add(("motion.abort", "move"), 4)  # past the bound: counted
    assert list(found.kept.values()) == [1, 3] and found.dropped == 1
