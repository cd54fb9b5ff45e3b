"""The diff against the fault registry: every protocol fault of the reference server, run as side B
against a clean side A, shows as a class (a) difference naming one of the clauses the fault matrix
names for it (side B the violator), or is on :data:`NOT_SHOWN` with the reason the diff cannot show it.

Each fault runs the scenarios (the directed cases' request sequences, with the conditions of the world
they need arranged on both sides) and two generated streams, stopping at the first that names one of its
clauses (a fault on NOT_SHOWN runs them all).  The clean side's observations are the
same for every fault, so each worker observes them once (:func:`clean_once`).  Everything runs in
virtual time.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from manip.conformance.diff import driver
from manip.conformance.diff.classify import Finding
from manip.conformance.diff.driver import DiffConfig, run_diff
from manip.conformance.diff.scenarios import scenarios
from manip.conformance.diff.sides import Observation, Side, observe
from manip.conformance.diff.streams import Stream, make_streams
from manip.conformance.fuzz.generators import GenOptions
from manip.conformance.fuzz.session import Allowance
from manip.reference_server import FaultSet, ServerConfig
from manip.reference_server.faults import WRIST_SIDE, Fault

pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]

SEED = 7
CLEAN = Side("A", "clean", config=ServerConfig())
PROTOCOL_FAULTS = sorted(
    (f for f in Fault if f.kind == "protocol" and f not in WRIST_SIDE),
    key=lambda f: f.value,
)
"""The server's protocol faults (the wrist side's are the Puma cases' to catch: they need the suite
playing Cougar)."""

NOT_SHOWN: dict[Fault, str] = {
    Fault.ASYNC_NUMBER_PREVIOUS: (
        "the asynchronous error names an earlier request's number; the diff pairs it as the numbers of "
        "another message and no judge of one side knows which request it is about, so it is unexplained "
        "(c)"
    ),
    Fault.ASYNC_SPLITS_MULTI: (
        "no scenario has a motion end inside a multi-packet reply; the asynchronous packets it moves show"
        " as unexplained differences (c) of the replies around them"
    ),
    Fault.CLOSE_KEEPS_MOVING: (
        "a diff stream is one connection on each side, and the fault shows only on a second one (what a "
        "closed connection leaves behind)"
    ),
    Fault.CONFIGURATION_IGNORED: (
        "no scenario sets the configuration and then solves or moves: the generated streams reach set "
        "configuration but never a solution it changes on a reference arm"
    ),
    Fault.CONFIGURATION_SWAPPED: (
        "no scenario sets the configuration and then solves or moves: the generated streams reach set "
        "configuration but never a solution it changes on a reference arm"
    ),
    Fault.KEEPS_ABORT: (
        "a diff stream is one connection on each side, and the fault shows only on a second one (what a "
        "closed connection leaves behind)"
    ),
    Fault.KEEPS_CONFIGURATION: (
        "a diff stream is one connection on each side, and the fault shows only on a second one (what a "
        "closed connection leaves behind)"
    ),
    Fault.KEEPS_NOTIFICATIONS: (
        "a diff stream is one connection on each side, and the fault shows only on a second one (what a "
        "closed connection leaves behind)"
    ),
    Fault.KEEPS_SPEED: (
        "a diff stream is one connection on each side, and the fault shows only on a second one (what a "
        "closed connection leaves behind)"
    ),
    Fault.DESCRIBE_TERMINATOR_OVERTAKEN: (
        "shown as a violation of multi.terminated-by-empty and multi.same-request-number (side B): the "
        "reply that overtakes the terminator is judged by those clauses, not by request.one-reply"
    ),
    Fault.FATAL_EOF_WITHOUT_CLS: (
        "both sides end the connection after the fatal error; the diff pairs a connection end without "
        "telling an end of file from a CLS packet"
    ),
    Fault.FORCES_IN_POUNDS: (
        "no stream reads forces under a known load: the reference wrist reads zero ounces, which is zero "
        "pounds too"
    ),
    Fault.FORCES_STALE: (
        "no stream reads forces twice under a changing load: the reference wrist's reading does not change"
    ),
    Fault.GUARD_HIT_WORD_SWAPPED: (
        "no scenario arranges a guarded move that hits its guard, so no guard-hit report is sent"
    ),
    Fault.INCREMENT_FROM_ACTUAL: (
        "no scenario sends an incremental move while the arm lags its commanded pose; the generated ones "
        "are refused or land within tolerance"
    ),
    Fault.INCREMENT_O_T_SWAPPED: (
        "no scenario reads back an incremental move's result; the generated ones show as unexplained "
        "differences (c) of the answers that follow"
    ),
    Fault.JOINTS_REVERSED: (
        "the server reverses the joint order everywhere (requests, replies, describe self), so no answer "
        "of side B contradicts another; its differences from side A are unexplained (c)"
    ),
    Fault.NO_INITIAL_RESPONSE: (
        "shown as a violation of connect.initial-response-number (side B): the first answer is taken for "
        "the initial response and its number judged"
    ),
    Fault.SEGMENTS_STOP: (
        "the fault changes how the arm moves (its path or its timing), not what the server answers; the "
        "diff pairs answers, and the arm's motion is the directed cases' to judge"
    ),
    Fault.SERVO_DOUBLE_RATE: (
        "the fault changes how the arm moves (its path or its timing), not what the server answers; the "
        "diff pairs answers, and the arm's motion is the directed cases' to judge"
    ),
    Fault.SPEED_IGNORED: (
        "the fault changes how the arm moves (its path or its timing), not what the server answers; the "
        "diff pairs answers, and the arm's motion is the directed cases' to judge"
    ),
    Fault.STRAIGHT_AS_JOINT: (
        "the fault changes how the arm moves (its path or its timing), not what the server answers; the "
        "diff pairs answers, and the arm's motion is the directed cases' to judge"
    ),
    Fault.JOINT_MOVES_STRAIGHT: (
        "the fault changes how the arm moves (its path or its timing), not what the server answers; the "
        "diff pairs answers, and the arm's motion is the directed cases' to judge"
    ),
    Fault.WARNING_INTERRUPTS: (
        "the warning scenario's sluggish joint warns inside a reply on both sides; where it lands shows "
        "as an unexplained difference (c) of request.one-reply, no judge of one side reading the "
        "warning's format"
    ),
    Fault.WRIST_ERROR_FATAL: (
        "the silent wrist makes read forces fail on both sides; a fatal error against a non-fatal one is "
        "paired as the answer's opcode, and no judge of one side names wrist.no-answer"
    ),
    Fault.WRIST_TIMEOUT_SILENT: (
        "shown as a violation of request.one-reply (side B): read forces gets no answer at all, which the"
        " judge names as a request without its reply"
    ),
    Fault.WRONG_REQUEST_NUMBER: (
        "shown as a violation of request.one-reply (side B): an answer with another number is a reply to "
        "no request outstanding, and the request's own reply missing"
    ),
    Fault.LOS_UNKNOWN_IGNORED: (
        "the diff's clients only send packets for connections that exist, so the server's missing LOS for "
        "one that does not never shows; server.ncp.los-unknown-connection sends one by hand"
    ),
    Fault.ILLEGAL_OPCODE_IGNORED: (
        "the diff's clients send only legal Chaos opcodes, so the server's silence about an illegal one "
        "never shows; server.ncp.los-illegal-opcode forges one"
    ),
    Fault.OVERSIZE_SERVED: (
        "the diff's clients never send more than 488 data bytes in a packet (their codec refuses to), so "
        "the missing bound never shows; server.negative.oversize-frame forges such a frame"
    ),
    Fault.NO_RETRANSMISSION: (
        "the diff's link (a Unix socket in one process) loses nothing and its NCPs receipt promptly, so no "
        "packet ever waits to be sent again"
    ),
    Fault.DUPLICATE_RFC_NEW: (
        "the diff's connections open at the first RFC (a Unix socket loses none), so no RFC is ever sent "
        "twice"
    ),
    Fault.SILENT_PEER_KEPT: (
        "the diff's clients are never silent for the server's broken-connection timer (90 s), so no "
        "connection is ever given up on either side"
    ),
    Fault.PACKET_NUMBERS_SKIP: (
        "side B's replies are all held back by the diff's client NCP for the number skipped, so side B "
        "answers nothing: the differences are replies missing on side B (after the diff's reply timeout "
        "each), which no judge of one side names as ncp.packet-numbers"
    ),
    Fault.DATA_BYTES_SWAPPED: (
        "shown as violations of response.echoes-request-number, multi.same-request-number and the error "
        "strings' clauses (side B): every number and string of side B is byte-swapped, and no judge of one "
        "side reads the data's byte order as such"
    ),
    Fault.HEADER_SOURCE_FIRST: (
        "the diff's client links refuse every packet of side B (it names their own address as its source), "
        "so side B answers nothing: its differences are missing answers, named by no judge of one side as "
        "chaos.header.layout"
    ),
    Fault.CHUDP_NO_HEADER: (
        "the diff's sides are reached over a Unix socket with the TCP link framing: the CHUDP framing it "
        "breaks is never used"
    ),
    Fault.CHUDP_ODD_BYTE_UNPADDED: (
        "the diff's sides are reached over a Unix socket with the TCP link framing: the CHUDP framing it "
        "breaks is never used"
    ),
    Fault.CHUDP_LSB_FIRST: (
        "the diff's sides are reached over a Unix socket with the TCP link framing: the CHUDP framing it "
        "breaks is never used"
    ),
    Fault.TRAILER_SOURCE_DESTINATION: (
        "the diff's sides are reached over a Unix socket with the TCP link framing, whose receivers do not "
        "learn peers from the trailer: only a CHUDP link refuses the trailer"
    ),
    Fault.CHAOSD_MSB_FIRST: (
        "the diff's sides are reached over a Unix socket with the TCP link framing: the chaosd framing it "
        "breaks is never used"
    ),
}
"""Faults the diff does not show as a violation of one of their clauses, and why (the directed case
that catches each is the fault matrix's, tests/conformance/test_faults.py)."""

NOT_RUN = frozenset(
    {
        Fault.LOS_UNKNOWN_IGNORED,
        Fault.ILLEGAL_OPCODE_IGNORED,
        Fault.OVERSIZE_SERVED,
        Fault.NO_RETRANSMISSION,
        Fault.DUPLICATE_RFC_NEW,
        Fault.SILENT_PEER_KEPT,
        Fault.PACKET_NUMBERS_SKIP,
        Fault.DATA_BYTES_SWAPPED,
        Fault.HEADER_SOURCE_FIRST,
        Fault.CHUDP_NO_HEADER,
        Fault.CHUDP_ODD_BYTE_UNPADDED,
        Fault.CHUDP_LSB_FIRST,
        Fault.TRAILER_SOURCE_DESTINATION,
        Fault.CHAOSD_MSB_FIRST,
    }
)
"""Faults of the Chaos level on :data:`NOT_SHOWN` that are not run through the diff: their defect lies
where its connections never go (another link's framing, packets a well-behaved client never sends, losses
and silences that never happen), or shows only as side B's answers missing or garbled throughout; every
stream run against one costs some 30 s of CPU to show nothing of theirs (the fault matrix's cases catch
each, tests/conformance/test_faults.py)."""

_CLEAN_SEEN: dict[tuple[str, tuple[int, ...]], Observation] = {}


def streams() -> list[Stream]:
    return [*scenarios(), *make_streams(SEED, 2, 8, GenOptions())]


@pytest.fixture(autouse=True)
def clean_once(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """The clean side observed once per stream in this worker (it is the same for every fault)."""

    def observed(side: Side, stream: Stream, allowance: Allowance, seed: int) -> Observation:
        if side.config != CLEAN.config:
            return observe(side, stream, allowance, seed)
        key = (stream.label, stream.input_numbers)
        if key not in _CLEAN_SEEN:
            _CLEAN_SEEN[key] = observe(side, stream, allowance, seed)
        return _CLEAN_SEEN[key]

    monkeypatch.setattr(driver, "observe", observed)
    yield


def findings(fault: Fault, wanted: set[str] | None = None) -> list[Finding]:
    """What the diff shows of ``fault`` on side B, stream by stream; with ``wanted``, it stops at the
    first stream where side B is named violating one of those clauses (the rest cannot undo that)."""
    faulty = Side("B", fault.value, config=ServerConfig(faults=FaultSet.parse([fault.value])))
    found: list[Finding] = []
    for stream in streams():
        (result,) = run_diff(CLEAN, faulty, [stream], DiffConfig(SEED, shrink=False))
        found += result.findings
        if wanted is not None and wanted & _named_by_b(result.findings):
            break
    return found


def _named_by_b(found: list[Finding]) -> set[str]:
    return {n for f in found if f.cls == "violation" and f.violator == "B" for n in f.names}


@pytest.mark.parametrize("fault", [f for f in PROTOCOL_FAULTS if f not in NOT_RUN], ids=lambda f: f.value)
def test_a_protocol_fault_is_a_violation_of_its_clause(fault: Fault) -> None:
    wanted = set(fault.clauses)
    found = findings(fault, None if fault in NOT_SHOWN else wanted)
    assert not [f for f in found if f.cls == "violation" and f.violator in ("A", "both")], "the clean side"
    named = _named_by_b(found)
    shown = sorted({(f.cls, f.names) for f in found})
    print(f"{fault.value}: wanted {sorted(wanted)}; named {sorted(named)}; {len(found)} difference(s)")
    if fault in NOT_SHOWN:
        assert not named & wanted, f"{fault.value} now shows: take it off NOT_SHOWN"
        return
    assert named & wanted, shown


def test_the_allow_list_names_protocol_faults_with_reasons() -> None:
    assert set(NOT_SHOWN) <= set(PROTOCOL_FAULTS)
    assert set(NOT_SHOWN) >= NOT_RUN
    assert all(len(why) > 40 for why in NOT_SHOWN.values())
