"""The one verdict (``manip.conformance.judge.verdict``): what outcomes mean, which violations count, and
the same outcome for the same violations whichever command judged them (``run``, ``client``,
``verify``, ``fuzz``), each through its own code path."""

from __future__ import annotations

import asyncio
import subprocess
from pathlib import Path
from types import SimpleNamespace

import pytest

from manip.conformance.client.runner import ClientRunConfig
from manip.conformance.client.runner import _judge as client_judge
from manip.conformance.fuzz.campaign import Campaign, CampaignConfig
from manip.conformance.fuzz.generators import GenOptions
from manip.conformance.fuzz.judge import Sighting
from manip.conformance.judge.verdict import Outcome, counts, grade
from manip.conformance.judge.violation import Violation
from manip.conformance.replay.verify import judge_violations
from manip.conformance.suite.context import RunOptions
from manip.conformance.suite.results import CaseResult
from manip.conformance.suite.runner import RunConfig, Runner

ROOT = Path(__file__).resolve().parents[3]

MUST = Violation("a MUST broke", "request.one-reply")
SHOULD = Violation("a SHOULD broke", "multi.not-split")
MAY = Violation("a MAY broke", None, "MAY")
UNKNOWN = Violation("no clause, no level", None)

SETS: dict[str, list[Violation]] = {
    "none": [],
    "must": [MUST],
    "should": [SHOULD],
    "may": [MAY],
    "unknown level": [UNKNOWN],
    "should and must": [SHOULD, MUST],
    "may and should": [MAY, SHOULD],
}


def test_levels_of_the_fixtures() -> None:
    assert MUST.level == "MUST" and SHOULD.level == "SHOULD" and UNKNOWN.level is None


def _blank(outcome: Outcome = Outcome.PASS, kind: str = "protocol") -> CaseResult:
    return CaseResult(
        id="server.x", clauses=(), level="MUST", kind=kind, hazard="read-only", summary="", outcome=outcome,
        seed=0, deadline=1.0,
    )  # fmt: skip


def by_run(violations: list[Violation], strict: bool) -> Outcome:
    runner = Runner(RunConfig(options=RunOptions(address="tcp://127.0.0.1:1", strict=strict), seed=0), [])
    result = _blank()
    runner._judge(result, SimpleNamespace(reached=set(), recorded=list(violations)), None)  # type: ignore[arg-type]
    return result.outcome


def by_client(violations: list[Violation], strict: bool) -> Outcome:
    config = ClientRunConfig(argv=["harness"], link="tcp", seed=0, options=RunOptions(strict=strict))
    result = _blank()
    client_judge(config, result, SimpleNamespace(reached=set(), recorded=list(violations)), None)  # type: ignore[arg-type]
    return result.outcome


def by_verify(violations: list[Violation], strict: bool) -> Outcome:
    result = _blank(kind="verify")
    judge_violations(result, violations, strict=strict)
    return result.outcome


def by_fuzz(violations: list[Violation], strict: bool) -> Outcome:
    """Each violation sighted by a campaign on one input of one class; the class's case in the report."""
    gen = GenOptions(select=("manip.wrong-length",))
    (kind,) = [c.id for c in gen.classes()]
    options = RunOptions(strict=strict, embedded=True)
    config = CampaignConfig(seed=0, gen=gen, options=options, only=(0,), shrink=False)
    campaign = Campaign(config, SimpleNamespace(embedded=True))  # type: ignore[arg-type]
    campaign.facts.classes[kind].inputs = 1
    item = SimpleNamespace(number=0, kind=kind, note="", steps=[], requests=1)

    async def record() -> None:
        for v in violations:
            await campaign._record(Sighting(v, 0), [item], 0)  # type: ignore[list-item]

    asyncio.run(record())
    (result,) = [r for r in campaign.finish().results if r.id == kind]
    return result.outcome


@pytest.mark.parametrize("strict", [False, True])
@pytest.mark.parametrize("name", list(SETS))
def test_every_command_grades_the_same_violations_alike(name: str, strict: bool) -> None:
    violations = SETS[name]
    expected = grade(Outcome.PASS, violations, strict)
    got = {
        "run": by_run(violations, strict),
        "client": by_client(violations, strict),
        "verify": by_verify(violations, strict),
        "fuzz": by_fuzz(violations, strict),
    }
    assert got == dict.fromkeys(got, expected)


@pytest.mark.parametrize(
    ("name", "lenient", "strict"),
    [
        ("none", Outcome.PASS, Outcome.PASS),
        ("must", Outcome.FAIL, Outcome.FAIL),
        ("should", Outcome.WARN, Outcome.FAIL),
        ("may", Outcome.WARN, Outcome.WARN),
        ("unknown level", Outcome.FAIL, Outcome.FAIL),
        ("may and should", Outcome.WARN, Outcome.FAIL),
    ],
)
def test_grade(name: str, lenient: Outcome, strict: Outcome) -> None:
    assert grade(Outcome.PASS, SETS[name], False) == lenient
    assert grade(Outcome.PASS, SETS[name], True) == strict


def test_counts_a_must_and_a_level_not_known_always_a_should_only_under_strict() -> None:
    assert counts(MUST, False) and counts(UNKNOWN, False)
    assert not counts(SHOULD, False) and counts(SHOULD, True)
    assert not counts(MAY, True)


@pytest.mark.parametrize("ended", [Outcome.SKIP, Outcome.NOT_JUDGED, Outcome.UNSUPPORTED])
def test_a_violation_seen_is_never_hidden_behind_how_the_case_ended(ended: Outcome) -> None:
    assert grade(ended, [], False) == ended
    assert grade(ended, [SHOULD], False) == Outcome.WARN
    assert grade(ended, [MUST], False) == Outcome.FAIL


def test_an_error_after_a_counted_violation_fails_unless_the_suite_is_at_fault() -> None:
    assert grade(Outcome.ERROR, [MUST], False) == Outcome.FAIL
    assert grade(Outcome.ERROR, [MUST], False, suite_bug=True) == Outcome.ERROR
    assert grade(Outcome.ERROR, [SHOULD], False) == Outcome.ERROR


@pytest.mark.parametrize(
    ("ended", "violations", "expected"),
    [
        (Outcome.PASS, [MUST], Outcome.KNOWN_FAIL),
        (Outcome.ERROR, [], Outcome.KNOWN_FAIL),
        (Outcome.PASS, [], Outcome.FIXED),
        (Outcome.PASS, [MAY], Outcome.FIXED),
        (Outcome.SKIP, [], Outcome.SKIP),
    ],
)
def test_known_failing(ended: Outcome, violations: list[Violation], expected: Outcome) -> None:
    assert grade(ended, violations, False, known_failing=True) == expected


def test_outcome_facts() -> None:
    failing = {o for o in Outcome if o.fails_run}
    assert failing == {Outcome.FAIL, Outcome.ERROR, Outcome.FIXED}
    assert {o for o in Outcome if o.needs_attention} == failing | {Outcome.WARN, Outcome.KNOWN_FAIL}
    assert {o for o in Outcome if o.judged} == {
        Outcome.PASS, Outcome.FAIL, Outcome.WARN, Outcome.KNOWN_FAIL, Outcome.FIXED,
    }  # fmt: skip
    ranked = Outcome.by_rank()
    assert ranked[0] == Outcome.FAIL and ranked[-1] == Outcome.PASS
    assert sorted(o.rank for o in Outcome) == list(range(len(Outcome)))
    assert all(o.rank < p.rank for o in Outcome for p in Outcome if o.fails_run and not p.fails_run)


def test_the_grading_rule_is_written_once() -> None:
    """No module but the verdict's spells out which levels count (its rule: ``strength == "SHOULD"``)."""
    found = subprocess.run(
        ["grep", "-rlE", r'\{"MUST", "SHOULD"\}|== "SHOULD"', "src/manip/conformance"],
        cwd=ROOT, capture_output=True, text=True, check=False,
    ).stdout.split()  # fmt: skip
    assert found == ["src/manip/conformance/judge/verdict.py"], found
