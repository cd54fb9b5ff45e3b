"""Mutation testing of the conformance suite: every protocol fault of the reference server is caught.

Each fault switch of :class:`manip.reference_server.faults.Fault` is switched on alone, the embedded
reference server (``serve`` on port 0, in this process) runs with it, and the suite's server cases run
against it; at least one case must end ``fail`` (or ``warn``, for a fault that breaks a SHOULD clause).
The clean server must pass every case.

To stay within the CI budget each fault runs only the cases that cite one of the clauses the fault
breaks, plus the stateful case (which checks the whole protocol model), with a reduced number of
Hypothesis examples and a short shrinking budget (only *that* a case fails matters here).  Every run is
the embedded target's (the simulated Cougar wrist included) in virtual time: the timing faults
(``segments-stop``'s 0.1 s rests, ``servo-double-rate``'s 8 ms servo) are judged from exact sample times,
so no verdict depends on how busy the machine is.  (Once, under load, real-time runs missed
``segments-stop``: samples of a time-scaled server came too far apart to show its rests.  Against a
real-time target the case says not-judged then, with the delays it measured: see
``test_segments_stop_of_a_server_process_in_real_time``.)  A fault whose defect can only show under a
condition of the arm's world runs with the environment fault that creates the condition
(:data:`CONDITIONS`): the reference arm never sends a fatal error unless calibration fails.

No fault may make a case skip that passes on the conforming server: a skip is for a target that cannot
offer what the case needs, and a wrong answer fails (or leaves the case not judged, naming the case that
judges the answer).
"""

from __future__ import annotations

import asyncio
import re
from collections.abc import Iterator, Sequence

import pytest

from manip.conformance.suite import bridge
from manip.conformance.suite.case import Case, all_cases
from manip.conformance.suite.context import RunOptions
from manip.conformance.suite.results import RunReport
from manip.conformance.suite.runner import RunConfig, Runner
from manip.cougar.faults import CougarFault
from manip.reference_client.faults import ClientFault
from manip.reference_server.faults import WRIST_SIDE, Fault, FaultSet
from manip.reference_server.session import ServerConfig
from manip.spec import SPEC
from manip.spec.faults import FaultSwitch
from tests.support.culprits import unnamed_violations
from tests.support.servers import StartServer
from tests.support.suite import run_over_link, run_simulated

SEED = 20260
MAX_EXAMPLES = 10
SHRINK_BUDGET = 0.2
REPLY_TIMEOUT = 1.0
"""Seconds to wait for an answer: loopback answers take well under a millisecond; a fault that drops a
packet costs this much per wait."""
SUITE_PREFIXES = ("server.", "property.", "stateful.")
"""The cases that judge a server over the default link (the Cougar cases need --cougar)."""
GENERIC = ("stateful.arm-model",)
"""Cases run under every protocol fault: those citing none of its clauses show the suite survives it
(no error, every violation named)."""
GENERIC_EXAMPLES = 3
"""Examples of a generic case under a fault none of its clauses names: a few show it survives the fault,
at a third of the CPU (the fault matrix's largest cost was the model run whole under every fault)."""
CONDITIONS: dict[Fault, tuple[str, ...]] = {}
PATHS = (
    Fault.FATAL_WITHOUT_CLOSE,
    Fault.FATAL_NUMBER_PREVIOUS,
    Fault.FATAL_SEVERITY_E,
    Fault.FATAL_DROPS_LINK,
    Fault.WARNING_INTERRUPTS,
    Fault.ASYNC_NUMBER_PREVIOUS,
    Fault.GUARD_HIT_WORD_SWAPPED,
    Fault.WRIST_TIMEOUT_SILENT,
    Fault.WRIST_ERROR_FATAL,
    Fault.ABORT_KEEPS_QUEUE,
    Fault.FATAL_EOF_WITHOUT_CLS,
    Fault.NZI_MASK_SHIFTED,
    Fault.FORCES_STALE,
)
"""The faults on a path the target's world arranges (their case needs the world to catch them)."""
CATCHERS = {fault: fault.caught_by for fault in Fault}
"""The cases each fault's declaration says catch it (``caught_by``): each must fail, or warn for a SHOULD
clause (others may catch the fault too)."""
CAUGHT = ("fail", "warn")

LINK_CASES = {"server.link.chudp-frames": "chudp", "server.link.chaosd-frames": "chaosd"}
"""The cases that judge the frames of a link the embedded target is not on, and that link."""
OVER_LINKS = {fault: LINK_CASES[c] for fault in Fault for c in fault.caught_by if c in LINK_CASES}
"""The faults of a link's framing, each caught over its link (``test_link_fault_is_caught_over_its_link``):
the embedded target's Unix socket carries the TCP link framing."""
CHAOS_LEVEL = frozenset(f for f in Fault if all(SPEC.clauses[c].party == "link" for c in f.clauses))
"""The faults of the NCP and the links: their catching case must fail on one of their clauses."""
BROKEN_AFTER = {Fault.SILENT_PEER_KEPT: 5.0}
"""The server's broken-connection timer (and the suite's --broken-after) in a fault's run: the case waits
it out, in virtual time."""

PROTOCOL_FAULTS = sorted(
    (f for f in Fault if f not in WRIST_SIDE and f not in OVER_LINKS), key=lambda f: f.value
)
"""The wrist side's defects are caught by the puma cases (tests/conformance/puma/test_puma.py), those of
the CHUDP and chaosd framings over their links."""


@pytest.fixture(autouse=True)
def short_shrinking(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    monkeypatch.setattr(bridge, "DEFAULT_SHRINK_BUDGET", SHRINK_BUDGET)
    yield


def suite() -> list[Case]:
    return [c for c in all_cases() if c.id.startswith(SUITE_PREFIXES)]


def cases_for(fault: Fault) -> list[Case]:
    """The cases citing a clause the fault breaks (the generic ones among them only if they do)."""
    broken = set(fault.clauses)
    return [c for c in suite() if broken & set(c.clauses)]


def generic_for(fault: Fault) -> list[Case]:
    """The generic cases citing none of the fault's clauses: run with :data:`GENERIC_EXAMPLES`."""
    broken = set(fault.clauses)
    return [c for c in suite() if c.id in GENERIC and not broken & set(c.clauses)]


def run_suite(
    faults: FaultSet,
    cases: Sequence[Case],
    config: ServerConfig | None = None,
    broken_after: float | None = None,
    max_examples: int = MAX_EXAMPLES,
) -> RunReport:
    """The cases against the embedded target set up by ``config`` (``faults`` without one), in virtual
    time; ``broken_after`` is the server's broken-connection timer, and the suite is told it."""
    config = ServerConfig(faults=faults) if config is None else config
    options = {"max_examples": max_examples, "reply_timeout": REPLY_TIMEOUT, "broken_after": broken_after}
    return run_simulated(cases, config, seed=SEED, options=options, broken_after=broken_after)


@pytest.mark.parametrize("registry", [Fault, ClientFault, CougarFault], ids=lambda r: r.__name__)
def test_every_fault_names_the_cases_that_catch_it(registry: type[FaultSwitch]) -> None:
    """Each defect of the server, the client and the Cougar says which cases its fault matrix requires to
    catch it (``caught_by``), and each of those cases cites one of the clauses it breaks; a reading names
    none."""
    cases = {c.id: c for c in all_cases()}
    for fault in registry:
        assert bool(fault.caught_by) == (fault.kind == "protocol"), fault
        for case_id in fault.caught_by:
            assert case_id in cases, (fault, case_id)
            assert set(fault.clauses) & set(cases[case_id].clauses), (fault, case_id)


def test_every_protocol_fault_has_a_case_citing_its_clauses() -> None:
    """The selection is not empty beyond the generic cases: some case names each fault's clauses."""
    for fault in PROTOCOL_FAULTS:
        specific = [c.id for c in cases_for(fault) if c.id not in GENERIC]
        assert specific, f"no case cites a clause of fault {fault.value}: {fault.clauses}"


@pytest.mark.slow
@pytest.mark.timeout(600)  # the whole suite in virtual time: about 30 s of CPU, longer on a loaded host
def test_clean_server_passes_every_case() -> None:
    report = run_suite(FaultSet(), suite())
    bad = [
        (r.id, r.outcome, r.reason or [v.message for v in r.violations])
        for r in report.results
        if r.outcome not in ("pass", "skip") and r.id != "server.ncp.broken"  # it needs --broken-after
    ]
    print(f"clean server: {len(report.results)} cases in {report.duration:.1f} s")
    assert not bad, bad
    assert not report.problems, report.problems
    assert sum(r.outcome == "pass" for r in report.results) > len(report.results) // 2


@pytest.mark.parametrize("fault", PROTOCOL_FAULTS, ids=lambda f: f.value)
def test_protocol_fault_is_caught(fault: Fault) -> None:
    faults = FaultSet.parse([fault.value, *CONDITIONS.get(fault, ())])
    cases, generic = cases_for(fault), generic_for(fault)
    report = run_suite(faults, cases, broken_after=BROKEN_AFTER.get(fault))
    if generic:
        survived = run_suite(
            faults, generic, broken_after=BROKEN_AFTER.get(fault), max_examples=GENERIC_EXAMPLES
        )
        report.results += survived.results
        cases += generic
    caught = [r for r in report.results if r.outcome in CAUGHT]
    errors = [(r.id, r.reason) for r in report.results if r.outcome == "error"]
    shown = ", ".join(
        f"{r.id} ({r.outcome}: {r.violations[0].clause if r.violations else r.reason})" for r in caught
    )
    print(f"fault {fault.value}: caught by {shown or 'NO CASE'} [{report.duration:.1f} s]")
    assert not errors, errors
    assert not unnamed_violations(report), unnamed_violations(report)  # every culprit named and kept
    assert caught, f"no case caught fault {fault.value} ({fault.breaks})"
    assert set(CATCHERS[fault]) <= {r.id for r in caught}, shown
    if fault in CHAOS_LEVEL:  # the catching case says which rule broke
        named = {v.clause for r in caught if r.id in CATCHERS[fault] for v in r.violations}
        assert named & set(fault.clauses), shown
    skipped = [c for c in cases if c.id in {r.id for r in report.results if r.outcome == "skip"}]
    if skipped:  # a skip is for a target that cannot offer the condition, never for a wrong answer
        clean = run_suite(FaultSet(), skipped)
        passing = [r.id for r in clean.results if r.outcome == "pass"]
        assert not passing, f"fault {fault.value} makes {passing} skip, which pass on the conforming server"


@pytest.mark.waits
@pytest.mark.parametrize("fault", sorted(OVER_LINKS, key=lambda f: f.value), ids=lambda f: f.value)
def test_link_fault_is_caught_over_its_link(fault: Fault) -> None:
    """A fault of the CHUDP or chaosd framing, run over that link (a reference server in real time in this
    process, on a loopback port or behind a chaosd hub): its case fails on one of its clauses.  Its frames
    refused, the connections wait out a short connect timeout: the test mostly waits."""
    cases = [c for c in suite() if c.id in fault.caught_by]
    report = run_over_link(cases, OVER_LINKS[fault], ServerConfig(faults=FaultSet.of(fault)), seed=SEED)
    shown = [(r.id, r.outcome, [v.clause for v in r.violations]) for r in report.results]
    print(f"fault {fault.value} over {OVER_LINKS[fault]}: {shown}")
    assert {r.id for r in report.results} == set(fault.caught_by), shown
    for result in report.results:
        assert result.outcome in CAUGHT, shown
        assert {v.clause for v in result.violations} & set(fault.clauses), shown


@pytest.mark.parametrize("scheme", sorted(set(LINK_CASES.values())))
def test_the_clean_server_passes_the_link_cases_over_each_link(scheme: str) -> None:
    """The cases the link faults' matrix runs over CHUDP and chaosd pass against the clean server there."""
    wanted = {c for c, link in LINK_CASES.items() if link == scheme} | {"server.link.packet-numbers"}
    report = run_over_link([c for c in suite() if c.id in wanted], scheme, seed=SEED)
    assert {r.id: r.outcome for r in report.results} == dict.fromkeys(wanted, "pass"), report.results


def test_the_arranged_paths_run_against_the_clean_server() -> None:
    """The cases whose paths the world arranges pass (not skip, not not-judged) against the clean
    embedded server."""
    catchers = {case for fault in PATHS for case in fault.caught_by}
    report = run_suite(FaultSet(), [c for c in suite() if c.id in catchers])
    assert {r.id: r.outcome for r in report.results} == dict.fromkeys(catchers, "pass")


GUIDE_ROUTES = {
    Fault.SPEED_IGNORED: "server.speed.scales",
    Fault.QUEUE_REVERSED: "server.motion.queued-segments",
    Fault.ABORT_KEEPS_QUEUE: "server.motion.abort-drops-queue",
}
"""The motion faults a server written from the 1985 guide alone can have, and the case that must catch
each through the guide's own requests (no request notifications to tell when a segment ends)."""
GUIDE_ROUTE_CASES = (*GUIDE_ROUTES.values(), "server.motion.awa-reset-abort", "server.connect.fresh-state")
"""The cases with a guide-only route for what they used an extension opcode for."""


def guide_route_taken(notes: Sequence[str]) -> bool:
    """The case said it went the guide's way (the extension it would use was refused)."""
    return any("a Puma extension" in note and "refused" in note for note in notes)


@pytest.mark.parametrize("fault", sorted(GUIDE_ROUTES, key=lambda f: f.value), ids=lambda f: f.value)
def test_motion_fault_is_caught_through_the_guide_profile(fault: Fault) -> None:
    """Against a server written from the 1985 guide alone (manip-server --profile guide: no Puma extensions,
    inches, the guide's asynchronous layout) the speed factor's effect, the queue's order and an abort
    dropping the queue are judged by polling the joint angles, so each fault still fails its case."""
    faults = FaultSet.of(fault)
    cases = [c for c in suite() if c.id == GUIDE_ROUTES[fault]]
    report = run_suite(faults, cases, ServerConfig.guide_profile(faults=faults))
    (result,) = report.results
    shown = [v.message for v in result.violations]
    print(f"fault {fault.value} without extensions: {result.outcome} {shown}")
    assert result.outcome in CAUGHT, (result.outcome, result.reason)
    assert guide_route_taken(result.notes), result.notes
    assert {v.clause for v in result.violations} & set(fault.clauses), result.violations


def test_the_guide_routes_pass_against_the_clean_guide_profile() -> None:
    """The same cases pass, through the guide's own requests, against a conforming guide-only server."""
    cases = [c for c in suite() if c.id in GUIDE_ROUTE_CASES]
    report = run_suite(FaultSet(), cases, ServerConfig.guide_profile())
    outcomes = {r.id: r.outcome for r in report.results}
    assert outcomes == dict.fromkeys(GUIDE_ROUTE_CASES, "pass"), [(r.id, r.reason) for r in report.results]
    assert all(guide_route_taken(r.notes) for r in report.results)


def test_packed_error_args_conform() -> None:
    """Erratum error-arg-layout: a server writing the numbers straight after the NUL, as the 1985 guide's
    NZI example does (manip-server --error-args packed), passes every case that judges error strings."""
    cases = [c for c in suite() if any(cl.startswith(("error-string.", "request.")) for cl in c.clauses)]
    report = run_suite(FaultSet(), cases, ServerConfig(error_args="packed"))
    bad = [
        (r.id, r.outcome, [v.message for v in r.violations]) for r in report.results if r.outcome in CAUGHT
    ]
    passed = {r.id for r in report.results if r.outcome == "pass"}
    assert {"server.error.arg-alignment", "server.error.string-format"} <= passed and not bad, bad


def test_the_guides_async_layout_conforms() -> None:
    """Erratum async-request-number: a server writing asynchronous responses as E.3 lays them out (the
    condition code first, 6 bytes; manip-server --async-layout guide) passes every case that reads them."""
    cases = [c for c in suite() if "async.layout" in c.clauses or c.id in GENERIC]
    report = run_suite(FaultSet(), cases, ServerConfig(async_layout="guide"))
    bad = [
        (r.id, r.outcome, r.reason, [v.message for v in r.violations])
        for r in report.results
        if r.outcome != "pass"
    ]
    assert {"server.async.segment-completed", "server.async.guard-hit"} <= {r.id for r in report.results}
    assert not bad, bad


def test_only_requests_pipelined_behind_describe_self_see_its_terminator_overtaken() -> None:
    """describe-terminator-overtaken is the re-entering request loop: a case that waits for each answer
    never sees it (the terminator comes two servo ticks late), the pipelined case does."""
    fault = FaultSet.parse([Fault.DESCRIBE_TERMINATOR_OVERTAKEN.value])
    cases = [c for c in suite() if c.id.startswith("server.describe.")]
    report = run_suite(fault, cases)
    outcomes = {r.id: r.outcome for r in report.results}
    assert outcomes.pop("server.describe.pipelined") == "fail"
    # the held terminator lets a segment report in between the reply's packets: a split (a SHOULD)
    assert outcomes.pop("server.describe.not-split") in ("pass", "warn")
    assert set(outcomes.values()) == {"pass"}, outcomes
    clean = run_suite(FaultSet(), [c for c in cases if c.id == "server.describe.pipelined"])
    assert [r.outcome for r in clean.results] == ["pass"]


REAL_TIME_VERDICTS = {"segments-stop": ("fail", "warn"), "": ("pass",)}
"""What queued-segments must say of a manip-server process, with and without the fault, when its timing
can be judged; otherwise it says not-judged with the delays it measured, never the other verdict."""


@pytest.mark.waits
@pytest.mark.parametrize("fault", sorted(REAL_TIME_VERDICTS), ids=lambda f: f or "clean")
def test_segments_stop_of_a_server_process_in_real_time(fault: str, manip_server: StartServer) -> None:
    """Against a real-time target (a manip-server process, at its own pace) the case catches the
    segments-stop fault and passes the clean server, or, when the host's delays were larger than what it
    measures (a loaded machine), says not-judged naming the delays it measured: a busy machine never
    turns either verdict into the other."""
    process = manip_server("--log-level", "WARNING", *(("--fault", fault) if fault else ()))
    selected = [c for c in suite() if c.id == "server.motion.queued-segments"]
    config = RunConfig(options=RunOptions(address=process.url, reply_timeout=2.0), seed=SEED)
    (result,) = asyncio.run(Runner(config, selected).run()).results
    print(f"{fault or 'clean'} manip-server in real time: {result.outcome} {result.reason} {result.notes}")
    if result.outcome == "not-judged":
        assert re.search(r"timers up to \d+\.\d ms late", result.reason), result.reason
    else:
        assert result.outcome in REAL_TIME_VERDICTS[fault], (result.outcome, result.reason, result.violations)
    if fault and result.outcome in CAUGHT:
        assert "motion.smooth-transitions" in {v.clause for v in result.violations}, result.violations
