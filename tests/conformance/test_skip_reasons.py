"""No wrong answer makes a server case skip (issue 32's sweep).

A skip is for a target that cannot offer what a case needs (another link, a key the description may
leave out), never for one that answered wrongly: that fails, or leaves the case not judged naming the
case that judges the answer.  ``tests/conformance/test_faults.py`` checks it for the cases citing each
fault's clauses; a case citing other clauses can still meet the fault (``server.motion.ready-position``
met ``no-describe-terminator`` and skipped).  So every server case that can skip at all (its own code
calls ``ctx.skip``) runs here under every protocol fault of the reference server, and is compared with
its outcome on the clean server.
"""

from __future__ import annotations

import functools
import inspect

import pytest

from manip.conformance.suite.case import Case, all_cases
from manip.conformance.suite.results import RunReport
from manip.reference_server.faults import Fault, FaultSet
from manip.reference_server.session import ServerConfig
from tests.support.suite import run_simulated

SEED = 20261
OPTIONS = {"reply_timeout": 1.0, "max_examples": 5}


def skipping_cases() -> list[Case]:
    """The server cases whose own code may skip."""
    server = [c for c in all_cases() if c.id.startswith(("server.", "property.", "stateful."))]
    return [c for c in server if "ctx.skip(" in inspect.getsource(c.function)]


def run(cases: list[Case], faults: list[str]) -> RunReport:
    return run_simulated(cases, ServerConfig(faults=FaultSet.parse(faults)), seed=SEED, options=OPTIONS)


def unjudged_wrongly(clean: RunReport, faulty: RunReport, case_ids: set[str]) -> list[str]:
    """Cases that passed on the clean server and, under the fault, skip, or end not judged without naming
    a case that judges the answer."""
    passed = {r.id for r in clean.results if r.outcome == "pass"}
    found = []
    for r in faulty.results:
        if r.id not in passed:
            continue
        if r.outcome == "skip" or (r.outcome == "not-judged" and not any(i in r.reason for i in case_ids)):
            found.append(f"{r.id} {r.outcome}: {r.reason}")
    return found


PROTOCOL_FAULTS = sorted((f for f in Fault if f.kind == "protocol"), key=lambda f: f.value)


@functools.cache
def clean_run() -> tuple[RunReport, tuple[Case, ...]]:
    """The skipping cases on the clean server, and those among them that pass there: only such a case can
    be made to skip wrongly (the others, the link cases of the links the run is not on, need not run
    under every fault).  Once per test process."""
    cases = skipping_cases()
    clean = run(cases, [])
    passed = {r.id for r in clean.results if r.outcome == "pass"}
    return clean, tuple(c for c in cases if c.id in passed)


def test_the_sweep_covers_the_cases_that_skip_and_some_pass_cleanly() -> None:
    ids = {c.id for c in skipping_cases()}
    assert {"server.describe.joint-limits", "server.motion.ready-position"} <= ids
    assert clean_run()[1]


@pytest.mark.parametrize("fault", PROTOCOL_FAULTS, ids=lambda f: f.value)
def test_no_protocol_fault_makes_a_case_skip_that_passes_on_the_clean_server(fault: Fault) -> None:
    clean, passing = clean_run()
    wrong = unjudged_wrongly(clean, run(list(passing), [fault.value]), {c.id for c in all_cases()})
    assert not wrong, wrong


def test_the_check_finds_a_skip_on_a_wrong_answer() -> None:
    """Before the sweep, server.motion.ready-position skipped when describe self's reply had no
    terminator; the check must see such a skip (here rebuilt from the reports' records)."""
    ready = [c for c in skipping_cases() if c.id == "server.motion.ready-position"]
    clean = run(ready, [])
    faulty = run(ready, [Fault.NO_DESCRIBE_TERMINATOR.value])
    assert clean.results[0].outcome == "pass"
    assert faulty.results[0].outcome == "not-judged", faulty.results[0].reason
    assert not unjudged_wrongly(clean, faulty, {c.id for c in all_cases()})
    faulty.results[0].outcome = "skip"
    assert unjudged_wrongly(clean, faulty, {c.id for c in all_cases()})
