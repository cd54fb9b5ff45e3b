"""Mutation testing of the conformance suite: every protocol fault of the reference server is caught.

Each protocol fault of :data:`manip.reference_server.faults.FAULTS` is switched on alone, the embedded
reference server (``serve`` on port 0, in this process) runs with it, and the suite's server cases run
against it; at least one case must end ``fail`` (or ``warn``, for a fault that breaks a SHOULD clause).
The clean server must pass every case.

To stay within the CI budget each fault runs only the cases that cite one of the clauses the fault
breaks, plus the stateful case (which checks the whole protocol model), with a reduced number of
Hypothesis examples, a short shrinking budget (only *that* a case fails matters here), and the
simulated arm running :data:`TIME_SCALE` times faster than real time (moves end sooner; timing-based
cases compare durations, which scale alike).  A fault whose defect can only show under a condition of
the arm's world runs with the environment fault that creates the condition (:data:`CONDITIONS`): the
reference arm never sends a fatal error unless calibration fails.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterator, Sequence

import pytest

from manip.conformance.suite import bridge
from manip.conformance.suite.case import Case, all_cases
from manip.conformance.suite.context import RunOptions
from manip.conformance.suite.embedded import simulated_environment
from manip.conformance.suite.results import RunReport
from manip.conformance.suite.runner import RunConfig, Runner
from manip.links import virtual_clock
from manip.reference_server.faults import FAULTS, WRIST_SIDE, Fault, FaultSet
from manip.reference_server.session import ServerConfig
from tests.support.suite import run_on_reference_server

SEED = 20260
MAX_EXAMPLES = 10
TIME_SCALE = 8.0
SHRINK_BUDGET = 0.2
REPLY_TIMEOUT = 1.0
"""Seconds to wait for an answer: loopback answers take well under a millisecond; a fault that drops a
packet costs this much per wait."""
SUITE_PREFIXES = ("server.", "property.", "stateful.")
"""The cases that judge a server over the default link (the Cougar cases need --cougar)."""
GENERIC = ("stateful.arm-model",)
CONDITIONS: dict[Fault, tuple[str, ...]] = {}
PATHS = {
    Fault.FATAL_WITHOUT_CLOSE: "server.error.fatal-then-close",
    Fault.FATAL_NUMBER_PREVIOUS: "server.error.fatal-then-close",
    Fault.FATAL_SEVERITY_E: "server.error.fatal-then-close",
    Fault.FATAL_DROPS_LINK: "server.error.fatal-then-close",
    Fault.WARNING_INTERRUPTS: "server.async.warning-format",
    Fault.ASYNC_NUMBER_PREVIOUS: "server.async.warning-format",
    Fault.GUARD_HIT_WORD_SWAPPED: "server.async.guard-hit",
    Fault.WRIST_TIMEOUT_SILENT: "server.wrist.no-answer",
    Fault.WRIST_ERROR_FATAL: "server.wrist.no-answer",
    Fault.ABORT_KEEPS_QUEUE: "server.motion.abort-drops-queue",
}
"""The fault of each path the target's world arranges, and the case that must catch it."""
CATCHERS = {
    **PATHS,
    Fault.STRAIGHT_AS_JOINT: "server.motion.straight-line",
    Fault.INCREMENT_FROM_ACTUAL: "server.motion.incremental-reference",
    Fault.READY_LEAVES_WRIST: "server.motion.ready",
    Fault.SEGMENT_REPORT_PREVIOUS: "server.motion.queued-segments",
    Fault.SEGMENTS_STOP: "server.motion.queued-segments",
    Fault.SERVO_DOUBLE_RATE: "server.motion.queued-segments",
    Fault.COLLISION_UNCHECKED: "server.motion.collision",
    Fault.CLOSE_KEEPS_MOVING: "server.connect.close-stops-arm",
    Fault.UNDERFLOW_DIRTY_ZERO: "server.float.extremes",
    Fault.NOT_FINITE_RESERVED: "server.float.extremes",
    Fault.ERROR_PAD_MISPLACED: "server.error.arg-alignment",
    Fault.UOP_OPCODE_SWAPPED: "server.negative.unknown-opcodes",
    Fault.BDL_COUNTS_SWAPPED: "server.negative.data-length.safe",
    Fault.JOINT_MASK_SWAPPED: "server.motion.jor",
    Fault.DESCRIBE_LIMITS_SHORT: "server.describe.joint-limits",
    Fault.DESCRIBE_READY_OFF: "server.motion.ready-position",
    Fault.INCREMENT_O_T_SWAPPED: "server.motion.incremental-oat",
    Fault.CONFIGURATION_IGNORED: "server.motion.configuration",
    Fault.KEEPS_SPEED: "server.connect.fresh-state",
    Fault.KEEPS_CONFIGURATION: "server.connect.fresh-state",
    Fault.KEEPS_NOTIFICATIONS: "server.connect.fresh-state",
    Fault.SPEED_IGNORED: "server.speed.scales",
    Fault.QUEUE_REVERSED: "server.motion.queued-segments",
}
"""Faults and the case written to catch each: it must fail, or warn for a SHOULD clause (others may catch
the fault too)."""
WRIST_FAULTS = frozenset({Fault.GUARD_HIT_WORD_SWAPPED, Fault.WRIST_TIMEOUT_SILENT, Fault.WRIST_ERROR_FATAL})
"""Faults whose catching case needs the simulated Cougar wrist."""
VIRTUAL_FAULTS = WRIST_FAULTS | {Fault.SERVO_DOUBLE_RATE, Fault.SEGMENTS_STOP}
"""Faults caught in virtual time (:func:`run_with_wrist`): those needing the wrist, the 8 ms servo and the
rest between segments (12.5 ms of real time at 8 times real speed), which show only to samples closer
than a real round trip to a time-scaled server allows on a loaded machine."""
CAUGHT = ("fail", "warn")

PROTOCOL_FAULTS = sorted(
    (f for f, info in FAULTS.items() if info.kind == "protocol" and f not in WRIST_SIDE),
    key=lambda f: f.value,
)
"""The wrist side's defects are caught by the puma cases (tests/conformance/puma/test_puma.py)."""


@pytest.fixture(autouse=True)
def short_shrinking(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    monkeypatch.setattr(bridge, "DEFAULT_SHRINK_BUDGET", SHRINK_BUDGET)
    yield


def suite() -> list[Case]:
    return [c for c in all_cases() if c.id.startswith(SUITE_PREFIXES)]


def cases_for(fault: Fault) -> list[Case]:
    """The cases citing a clause the fault breaks, and the generic ones."""
    broken = set(FAULTS[fault].clauses)
    return [c for c in suite() if broken & set(c.clauses) or c.id in GENERIC]


async def run_suite(faults: FaultSet, cases: Sequence[Case], config: ServerConfig | None = None) -> RunReport:
    config = ServerConfig(faults=faults) if config is None else config
    options = {"max_examples": MAX_EXAMPLES, "reply_timeout": REPLY_TIMEOUT, "time_scale": TIME_SCALE}
    return await run_on_reference_server(
        cases, config, seed=SEED, time_scale=TIME_SCALE, options=options, embedded=True, world=True
    )


def run_with_wrist(faults: FaultSet, cases: Sequence[Case], server: ServerConfig | None = None) -> RunReport:
    """The cases against a robot with the simulated Cougar wrist, as the embedded target's is, in virtual
    time: Cougar ticks with the servo, so its answers never depend on how loaded the machine is (in real
    time a busy machine delays its ticks past any reply timeout)."""

    async def main() -> RunReport:
        config = ServerConfig(faults=faults) if server is None else server
        async with simulated_environment(config, seed=SEED, wrist=True) as environment:
            address = environment.address
            options = RunOptions(max_examples=MAX_EXAMPLES, address=address, reply_timeout=REPLY_TIMEOUT)
            run = RunConfig(
                address=address,
                options=options,
                seed=SEED,
                embedded=True,
                world=environment.world,
                virtual_time=True,
            )
            return await Runner(run, cases).run()

    return virtual_clock.run(main(), virtual=True)


def test_every_protocol_fault_has_a_case_citing_its_clauses() -> None:
    """The selection is not empty beyond the generic cases: some case names each fault's clauses."""
    for fault in PROTOCOL_FAULTS:
        specific = [c.id for c in cases_for(fault) if c.id not in GENERIC]
        assert specific, f"no case cites a clause of fault {fault.value}: {FAULTS[fault].clauses}"


@pytest.mark.waits
def test_clean_server_passes_every_case() -> None:
    report = asyncio.run(run_suite(FaultSet(), suite()))
    # this server has no wrist: the cases that use the wrist's opcodes are not judged
    wrist = {c.id for c in suite() if set(c.extensions) - {"request-notifications", "reset-abort"}}
    bad = [
        (r.id, r.outcome, r.reason or [v.message for v in r.violations])
        for r in report.results
        if r.outcome not in ("pass", "skip")
        and not (r.outcome == "not-judged" and r.id in wrist)
        and r.id != "server.ncp.broken"  # it needs --broken-after
    ]
    print(f"clean server: {len(report.results)} cases in {report.duration:.1f} s")
    assert not bad, bad
    assert not report.problems, report.problems
    assert sum(r.outcome == "pass" for r in report.results) > len(report.results) // 2


@pytest.mark.parametrize("fault", PROTOCOL_FAULTS, ids=lambda f: f.value)
def test_protocol_fault_is_caught(fault: Fault) -> None:
    faults = FaultSet.parse([fault.value, *CONDITIONS.get(fault, ())])
    cases = cases_for(fault)
    virtual = fault in VIRTUAL_FAULTS
    report = run_with_wrist(faults, cases) if virtual else asyncio.run(run_suite(faults, cases))
    caught = [r for r in report.results if r.outcome in CAUGHT]
    errors = [(r.id, r.reason) for r in report.results if r.outcome == "error"]
    shown = ", ".join(
        f"{r.id} ({r.outcome}: {r.violations[0].clause if r.violations else r.reason})" for r in caught
    )
    print(f"fault {fault.value}: caught by {shown or 'NO CASE'} [{report.duration:.1f} s]")
    assert not errors, errors
    assert caught, f"no case caught fault {fault.value} ({FAULTS[fault].description})"
    if fault in CATCHERS:
        assert CATCHERS[fault] in {r.id for r in caught}, shown


def test_the_arranged_paths_run_against_the_clean_server() -> None:
    """The cases whose paths the world arranges pass (not skip, not not-judged) against the clean
    embedded server."""
    report = run_with_wrist(FaultSet(), [c for c in suite() if c.id in PATHS.values()])
    assert {r.id: r.outcome for r in report.results} == dict.fromkeys(PATHS.values(), "pass")


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
    report = asyncio.run(run_suite(faults, cases, ServerConfig.guide_profile(faults=faults)))
    (result,) = report.results
    shown = [v.message for v in result.violations]
    print(f"fault {fault.value} without extensions: {result.outcome} {shown}")
    assert result.outcome in CAUGHT, (result.outcome, result.reason)
    assert guide_route_taken(result.notes), result.notes
    assert {v.clause for v in result.violations} & set(FAULTS[fault].clauses), result.violations


def test_the_guide_routes_pass_against_the_clean_guide_profile() -> None:
    """The same cases pass, through the guide's own requests, against a conforming guide-only server."""
    cases = [c for c in suite() if c.id in GUIDE_ROUTE_CASES]
    report = asyncio.run(run_suite(FaultSet(), cases, ServerConfig.guide_profile()))
    outcomes = {r.id: r.outcome for r in report.results}
    assert outcomes == dict.fromkeys(GUIDE_ROUTE_CASES, "pass"), [(r.id, r.reason) for r in report.results]
    assert all(guide_route_taken(r.notes) for r in report.results)


def test_packed_error_args_conform() -> None:
    """Erratum error-arg-layout: a server writing the numbers straight after the NUL, as the 1985 guide's
    NZI example does (manip-server --error-args packed), passes every case that judges error strings."""
    cases = [c for c in suite() if any(cl.startswith(("error-string.", "request.")) for cl in c.clauses)]
    report = asyncio.run(run_suite(FaultSet(), cases, ServerConfig(error_args="packed")))
    bad = [
        (r.id, r.outcome, [v.message for v in r.violations]) for r in report.results if r.outcome in CAUGHT
    ]
    passed = {r.id for r in report.results if r.outcome == "pass"}
    assert {"server.error.arg-alignment", "server.error.string-format"} <= passed and not bad, bad


def test_the_guides_async_layout_conforms() -> None:
    """Erratum async-request-number: a server writing asynchronous responses as E.3 lays them out (the
    condition code first, 6 bytes; manip-server --async-layout guide) passes every case that reads them."""
    cases = [c for c in suite() if "async.layout" in c.clauses or c.id in GENERIC]
    report = run_with_wrist(FaultSet(), cases, ServerConfig(async_layout="guide"))
    bad = [
        (r.id, r.outcome, r.reason, [v.message for v in r.violations])
        for r in report.results
        if r.outcome != "pass"
    ]
    assert {"server.async.segment-completed", "server.async.guard-hit"} <= {r.id for r in report.results}
    assert not bad, bad
