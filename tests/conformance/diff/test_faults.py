"""The diff against the fault registry: every protocol fault of the reference server, run as side B
against a clean side A, shows as a class (a) difference naming one of the clauses the fault matrix
names for it (side B the violator), or is on :data:`NOT_SHOWN` with the reason the diff cannot show it.

Each fault runs the scenarios (the directed cases' request sequences, with the conditions of the world
they need arranged on both sides) and two generated streams, the scenario made for it first
(:data:`OWN_SCENARIO`), then those with the least pause, stopping at the first that names one of its
clauses (a fault on NOT_SHOWN runs them all).  A fault of a link's framing runs with both sides reached
over that link (:data:`LINKS`), one shown by waiting out the broken-connection timer with both sides
told the reference server's (:data:`TIMERS`).  The clean side's
observations are the same for every fault, so each worker observes them once (``DiffConfig.seen_a``).
Everything runs in virtual time.
"""

from __future__ import annotations

import pytest

from manip.conformance.diff.classify import Finding
from manip.conformance.diff.driver import DiffConfig, run_diff
from manip.conformance.diff.scenarios import scenarios
from manip.conformance.diff.sides import Observation, input_link
from manip.conformance.diff.streams import Stream, make_streams
from manip.conformance.fuzz.generators import GenOptions
from manip.conformance.fuzz.steps import Pause
from manip.conformance.suite.embedded import SimulatedLink
from manip.ncp import NcpConfig
from manip.reference_server.faults import Fault
from tests.support.tools import load_tool

pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]

SEED = 7
SWEEP = load_tool("diff_faults")
"""``tools/diff_faults.py``, which runs every fault through every stream: the sides of a fault and what
side B is named for are the sweep's and this test's alike."""
PROTOCOL_FAULTS: list[Fault] = SWEEP.protocol_faults()
"""The server's protocol faults (the wrist side's are the Puma cases' to catch: they need the suite
playing Cougar)."""

NOT_SHOWN: dict[Fault, str] = {}
"""Faults the diff does not show as a violation of one of their clauses, each with the reason the diff
cannot show it (the directed case that catches each is the fault matrix's, tests/conformance/test_faults.py).
Empty: every protocol fault shows.  A new fault goes here only with a reason a reader can check."""

NOT_RUN: frozenset[Fault] = frozenset()
"""Faults on :data:`NOT_SHOWN` that a run shows nothing of at all (side B answers every stream as side A
does, measured by ``tools/diff_faults.py``, which runs every fault through every stream), so they are
not run here."""

LINKS: dict[Fault, SimulatedLink] = {
    Fault.CHUDP_NO_HEADER: "chudp",
    Fault.CHUDP_ODD_BYTE_UNPADDED: "chudp",
    Fault.CHUDP_LSB_FIRST: "chudp",
    Fault.TRAILER_SOURCE_DESTINATION: "chudp",
    Fault.CHAOSD_MSB_FIRST: "chaosd",
}
"""Faults of a framing the Unix socket does not carry, run with both sides reached over their link (the
others: over the Unix socket)."""
OWN_SCENARIO = {
    Fault.LOS_UNKNOWN_IGNORED: "stray-packets",
    Fault.ILLEGAL_OPCODE_IGNORED: "stray-packets",
    Fault.OVERSIZE_SERVED: "oversize",
    Fault.DUPLICATE_RFC_NEW: "duplicate-rfc",
    Fault.NO_RETRANSMISSION: "lost-answer",
    Fault.PACKET_NUMBERS_SKIP: "frames",
    Fault.HEADER_SOURCE_FIRST: "frames",
    Fault.DATA_BYTES_SWAPPED: "frames",
    **dict.fromkeys(LINKS, "frames"),
    Fault.SILENT_PEER_KEPT: "silent-peer",
    # the directed cases' sequences that show a fault of the arm's motion or state (found by trying every
    # stream, tools/diff_faults.py): tried first, they spare the test running the scenarios before them
    Fault.POWER_KEEPS_ABORT: "abort-reset",
    Fault.CLOSE_KEEPS_MOVING: "close-moving",
    Fault.ABORT_KEEPS_QUEUE: "collision",
    Fault.ASYNC_NUMBER_PREVIOUS: "collision",
    Fault.AWA_IGNORED: "collision",
    Fault.AWA_REFUSES_ALL: "collision",
    Fault.COLLISION_UNCHECKED: "collision",
    Fault.KEEPS_ABORT: "fresh-connection",
    Fault.KEEPS_CONFIGURATION: "fresh-connection",
    Fault.KEEPS_SPEED: "fresh-connection",
    Fault.INCREMENT_ANGLES_FIRST: "increment-data",
    Fault.INCREMENT_FROM_ACTUAL: "increments",
    Fault.INCREMENT_O_T_SWAPPED: "increments",
    Fault.JOINTS_REVERSED: "joint-order",
    Fault.QUEUE_REVERSED: "notified-motion",
    Fault.SEGMENT_REPORT_PREVIOUS: "notified-motion",
    Fault.JOINT_MOVES_STRAIGHT: "paths",
    Fault.STRAIGHT_AS_JOINT: "paths",
    Fault.STRAIGHT_TURN_FIRST: "paths",
    Fault.COMMAND_LEAD: "queued-timing",
    Fault.SEGMENTS_STOP: "queued-timing",
    Fault.SERVO_DOUBLE_RATE: "queued-timing",
    Fault.SWAPPED_FLOAT_WORDS: "read-back",
    Fault.DESCRIBE_READY_OFF: "ready",
    Fault.READY_LEAVES_WRIST: "ready",
    Fault.MOTION_REPLY_AT_REST: "reply-timing",
    Fault.SPEED_IGNORED: "speed-scales",
    Fault.WARNING_INTERRUPTS: "warning",
}
"""The scenario made to show a fault, tried before the others: the Chaos level's faults make side B
answer little or nothing on every other stream, each request then waiting out the reply timeout, and a
fault of the arm's motion shows only in the scenario that moves the arm as its directed case does (a
hint, not the verdict: a fault its scenario no longer shows goes on through every other stream)."""

TIMERS: dict[Fault, float] = {Fault.SILENT_PEER_KEPT: NcpConfig().broken_after}
"""Faults shown by a scenario that waits out the broken-connection timer: both sides are told the
reference server's own (as the diff's --broken-after tells them), which the scenario is sent for."""

_CLEAN_SEEN: dict[tuple[str, float | None], dict[tuple[str, tuple[int, ...]], Observation]] = {}
"""The clean side's observations, by link, timer and stream: the same for every fault, so each worker
observes them once."""


def streams(first: str = "", link: SimulatedLink = "unix") -> list[Stream]:
    """The scenarios and two generated streams (of the link's inputs), the scenario ``first`` first, then
    those that let the arm's clock run least (a fault stops at the first stream that shows it, so the
    cheap ones are tried first)."""
    generated = make_streams(SEED, 2, 8, GenOptions(link=input_link(link)))
    return sorted([*scenarios(), *generated], key=lambda s: (s.scenario != first, _paused(s)))


def _paused(stream: Stream) -> float:
    """The seconds of pause a stream's inputs ask for (the simulated time its sides run, at the most)."""
    return sum(s.seconds for i in stream.all_inputs for s in i.steps if isinstance(s, Pause))


def findings(fault: Fault, wanted: set[str] | None = None) -> list[Finding]:
    """What the diff shows of ``fault`` on side B, stream by stream; with ``wanted``, it stops at the
    first stream where side B is named violating one of those clauses (the rest cannot undo that)."""
    link, timer = LINKS.get(fault, "unix"), TIMERS.get(fault)
    clean, faulty = SWEEP.side_pair(fault, link, timer)
    seen = _CLEAN_SEEN.setdefault((link, timer), {})
    found: list[Finding] = []
    for stream in streams(OWN_SCENARIO.get(fault, ""), link):
        (result,) = run_diff(clean, faulty, [stream], DiffConfig(SEED, shrink=False, seen_a=seen))
        found += result.findings
        if wanted is not None and wanted & SWEEP.named_by_b(result.findings):
            break
    return found


@pytest.mark.parametrize("fault", [f for f in PROTOCOL_FAULTS if f not in NOT_RUN], ids=lambda f: f.value)
def test_a_protocol_fault_is_a_violation_of_its_clause(fault: Fault) -> None:
    wanted = set(fault.clauses)
    found = findings(fault, None if fault in NOT_SHOWN else wanted)
    assert not [f for f in found if f.cls == "violation" and f.violator in ("A", "both")], "the clean side"
    named: set[str] = SWEEP.named_by_b(found)
    shown = sorted({(f.cls, f.names) for f in found})
    print(f"{fault.value}: wanted {sorted(wanted)}; named {sorted(named)}; {len(found)} difference(s)")
    if fault in NOT_SHOWN:
        assert not named & wanted, f"{fault.value} now shows: take it off NOT_SHOWN"
        return
    assert named & wanted, shown


def test_the_allow_list_names_protocol_faults_with_reasons() -> None:
    assert set(NOT_SHOWN) <= set(PROTOCOL_FAULTS)
    assert set(NOT_SHOWN) >= NOT_RUN
    assert {s.scenario for s in scenarios()} >= set(OWN_SCENARIO.values())
    assert all(len(why) > 40 for why in NOT_SHOWN.values())
