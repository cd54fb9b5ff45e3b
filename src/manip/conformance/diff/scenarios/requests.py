"""The diff's scenarios of what a request's data means and what its answer must be: calibrate's done,
free joint's joint number, the hand's amount, set configuration's one byte, an abort reset by enable
power, an incremental move's six floats, and a second client while the first is connected."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Final

from manip.codecs.packet import Packet
from manip.conformance.cases.server.motion import HAND_TOL_MM
from manip.conformance.cases.server.trajectory import OAT_DELTA, OAT_DELTA_BACK
from manip.conformance.diff.pairing import SideEvent
from manip.conformance.diff.scenarios.kit import (
    READY_POSE,
    REST,
    SEED_ANGLES,
    STILL,
    Events,
    answer_at,
    at_rest,
    error_in,
    floats_data,
    opcode_of,
    read_here,
    req,
    rest_at,
    scenario_stream,
    sighting,
    word,
)
from manip.conformance.diff.streams import Stream
from manip.conformance.fuzz.generators import GenOptions, stray_index
from manip.conformance.fuzz.judge import Sighting
from manip.conformance.fuzz.steps import Pause, RequestStep, Step, Stray
from manip.spec.constants import ChaosOp, RequestName, ServerOp

HAND_AMOUNTS: Final = (2, 0o400, 0o177777)
"""Amounts of open or close hand other than 0 and 1: each opens a binary hand (``hand.data``), 0o400
with a low byte of zero, 0o177777 with every bit set."""
BAD_JOINTS: Final = (0, 7)
"""Joint numbers outside 1..6, which free joint refuses with a command error (``free-joint.data``)."""
CONFIGURATION_BYTES: Final = (b"\x01", b"\x00")
"""Set configuration's data as the one byte the 1985 guide allows: lefty, then righty."""
ABORTED_GOAL: Final = (60.0, *READY_POSE[1:])
"""The goal of the move that losing power aborts: joint 1 swung 60 degrees from the ready position."""
ABORT_AFTER: Final = 0.3
"""Seconds into that move when power is killed (well before it ends)."""
SETTLED: Final = 2.0
"""Seconds of pause after an incremental move of these scenarios (a few degrees: well within it)."""
SECOND_RFC: Final = 0.5
"""Seconds the first connection stays open after the second RFC: the fuzzer's judge takes the robot as
busy when the RFC's answer came before the first connection ended, and in virtual time an answer and
an end with no pause between them come at the same instant."""


# The checks ----------------------------------------------------------------------------------------


def _code(event: SideEvent) -> tuple[str, str] | None:
    """A non-fatal error's severity and code (None: another answer, or a string that does not parse)."""
    error = error_in(event, ServerOp.NON_FATAL_ERROR)
    return (error.severity, error.code) if error is not None else None


def _check_done(name: RequestName, clause: str, asked: dict[int, str]) -> Callable[[Events], list[Sighting]]:
    """Each request ``name`` at the inputs of ``asked`` (what each sent, in words) is answered with an
    empty done: the 1985 guide's answer to that data (``clause``)."""

    def check(events: Events) -> list[Sighting]:
        out: list[Sighting] = []
        for number, what in asked.items():
            answer = answer_at(events, number, name)
            if answer is None or (answer.opcode == ServerOp.RESPONSE and len(answer.data) == 2):
                continue
            message = f"{what} was answered 0{answer.opcode:o}, not done"
            out.append(sighting(number, clause, message, f"an empty done for {what}", answer))
        return out

    return check


def _check_bad_joints(asked: dict[int, int]) -> Callable[[Events], list[Sighting]]:
    """Free joint of a joint outside 1..6, the PUMA's joints (input -> joint), is a command error: a
    non-fatal error of severity C (``free-joint.data``: the joints are numbered from 1)."""

    def check(events: Events) -> list[Sighting]:
        out: list[Sighting] = []
        for number, joint in asked.items():
            answer = answer_at(events, number, "free-joint")
            code = _code(answer) if answer is not None else ("C", "")
            if answer is None or (code is not None and code[0] == "C"):
                continue
            message = f"free joint {joint} was answered 0{answer.opcode:o}, not refused as a command error"
            expected = f"a non-fatal error (0202) of severity C: joint {joint} is outside 1..6"
            out.append(sighting(number, "free-joint.data", message, expected, answer))
        return out

    return check


def _check_reset(moved: int) -> Callable[[Events], list[Sighting]]:
    """After an abort, enable high power resets it: the move at input ``moved`` (after enable power) is
    not refused AWA (``motion.reset``)."""

    def check(events: Events) -> list[Sighting]:
        answer = answer_at(events, moved, "set-joint-angles")
        code = _code(answer) if answer is not None else None
        if answer is None or code is None or code[1] != "AWA":
            return []
        message = "a move after enable high power was refused AWA: the abort outlived enable power"
        return [sighting(moved, "motion.reset", message, "the move queued (a segment number)", answer)]

    return check


TURNS: Final[tuple[tuple[RequestName, tuple[float, float, float]], ...]] = (
    ("incremental-move", OAT_DELTA),
    ("incremental-straight-move", OAT_DELTA_BACK),
)
"""The incremental moves of the increment-data scenario, each turning the hand by dO dA dT alone (the
directed case's turns, distinct so that angles read as lengths show)."""


def _check_increment_data(start: int) -> Callable[[Events], list[Sighting]]:
    """From rest, an incremental move of dO dA dT alone keeps the hand's position, whatever the
    increment is added to: a position moved shows the six floats read in another order than dX dY dZ
    dO dA dT (``incremental-move.data``, ``incremental-straight-move.data``).  Here is read at input
    ``start``, then after each move of :data:`TURNS` (the inputs that follow), once the arm is at rest
    (two Here answers agree).  Turns carry no length, so a side's length unit changes nothing."""

    def check(events: Events) -> list[Sighting]:
        out: list[Sighting] = []
        for after, (name, delta) in enumerate(TURNS, start=start + 1):
            pair = _rested(events, after - 1, after, name)
            if pair is None or (off := math.dist(pair[0][9:], pair[1][1][9:])) <= HAND_TOL_MM:
                continue
            message = f"{name} of dO dA dT {delta} alone moved the hand's position by {off:.3g}"
            expected = "the position kept: dX dY dZ are 0, the six floats being dX dY dZ dO dA dT"
            out.append(sighting(after, f"{name}.data", message, expected, pair[1][0]))
        return out

    return check


Rested = tuple[list[float], tuple[SideEvent, list[float]]]
"""Where the hand stood before an incremental move, and its last Here answer at rest after it."""


def _rested(events: Events, before: int, after: int, name: RequestName) -> Rested | None:
    """Where the hand stood at input ``before`` and where the move ``name`` at input ``after`` left it at
    rest (None: a Here missing, the move refused, out of reach say, or the arm still moving)."""
    first, last = read_here(events, before), read_here(events, after)
    moved = answer_at(events, after, name)
    if first is None or last is None or moved is None or moved.opcode != ServerOp.RESPONSE:
        return None
    return (first[1], last) if at_rest(events, after) else None


# The scenarios -------------------------------------------------------------------------------------


def _calibrate() -> Stream:
    """A calibrate that succeeds (no condition arranged): its done is empty (``calibrate.done``, judged
    by the transcript checks as ``response.done-empty``)."""
    groups: list[tuple[str, Sequence[Step]]] = [
        ("enable power, calibrate", [req("enable-power"), req("calibrate")]),
        ("here", [req("here")]),
    ]
    return scenario_stream("calibrate-done", groups)


def _free_joint_range() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [("enable power", [req("enable-power")])]
    asked: dict[int, int] = {}
    for joint in BAD_JOINTS:
        asked[len(groups)] = joint
        groups += [(f"free joint {joint}", [req("free-joint", word(joint))]), ("here", [req("here")])]
    return scenario_stream("free-joint-range", groups, _check_bad_joints(asked))


def _answered_done(
    name: str, request: RequestName, clause: str, sent: Sequence[tuple[str, RequestStep]], powered: bool
) -> Stream:
    """Scenario ``name``: each request of ``sent`` (what it sends, in words, and the request) in an input
    of its own, after enable power if ``powered``, each to be answered with an empty done (``clause``)."""
    groups: list[tuple[str, Sequence[Step]]] = [("enable power", [req("enable-power")])] if powered else []
    asked = {len(groups) + n: what for n, (what, _) in enumerate(sent)}
    groups += [(what, [step]) for what, step in sent]
    return scenario_stream(name, groups, _check_done(request, clause, asked))


def _hand_amounts() -> Stream:
    sent = [(f"open or close hand of amount {a}", req("hand", word(a))) for a in HAND_AMOUNTS]
    return _answered_done("hand-amounts", "hand", "hand.data", sent, powered=True)


def _configuration_byte() -> Stream:
    opcode = opcode_of("set-configuration")
    sent = [(f"set configuration of one byte {d.hex()}", RequestStep(opcode, d)) for d in CONFIGURATION_BYTES]
    return _answered_done(
        "configuration-byte", "set-configuration", "set-configuration.data", sent, powered=False
    )


def _abort_reset() -> Stream:
    swing, ready = (req("set-joint-angles", floats_data(goal)) for goal in (ABORTED_GOAL, READY_POSE))
    aborted: list[Step] = [req("enable-power"), swing, Pause(ABORT_AFTER), req("kill-power"), Pause(STILL)]
    groups: list[tuple[str, Sequence[Step]]] = [
        ("enable power, a move aborted by killing power midway", aborted),
        ("enable power, a move to the ready position", [req("enable-power"), ready, Pause(REST)]),
    ]
    return scenario_stream("abort-reset", groups, _check_reset(1))


def _increment_data() -> Stream:
    def turned(name: RequestName, delta: Sequence[float]) -> tuple[str, Sequence[Step]]:
        move = req(name, floats_data((0.0, 0.0, 0.0, *delta)))
        return f"{name} turning the hand, rest, here twice", [
            move,
            Pause(SETTLED),
            req("here"),
            Pause(STILL),
            req("here"),
        ]

    groups = [rest_at(SEED_ANGLES), *(turned(name, delta) for name, delta in TURNS)]
    return scenario_stream("increment-data", groups, _check_increment_data(0))


def _second_client() -> Stream:
    """A second client: an RFC for the contact, on a link of its own from another index, while the
    stream's connection is open (a :class:`~manip.conformance.fuzz.steps.Stray` RFC, as the fuzzer's
    RFC floods send).  It is refused (``connect.one-server-per-robot``): what it got, CLS or OPN, is
    paired as the stray's answer and judged by the fuzzer's judge of RFC answers; an OPN is closed at
    once.  The first connection then serves Here as before."""
    contact = GenOptions().contact.encode("ascii")
    rfc = Packet(ChaosOp.RFC, 0, 0, 0, stray_index(1, 0), 0, 0, contact)
    groups: list[tuple[str, Sequence[Step]]] = [
        ("here", [req("here")]),
        (
            "an RFC for the contact from another index, the first connection open",
            [Stray(rfc, "answer", "connect.one-server-per-robot"), Pause(SECOND_RFC)],
        ),
        ("here", [req("here")]),
    ]
    return scenario_stream("second-client", groups)


SCENARIOS: Final[dict[str, Callable[[], Stream]]] = {
    "calibrate-done": _calibrate,
    "free-joint-range": _free_joint_range,
    "hand-amounts": _hand_amounts,
    "configuration-byte": _configuration_byte,
    "abort-reset": _abort_reset,
    "increment-data": _increment_data,
    "second-client": _second_client,
}
"""This module's scenarios by name, in the order a diff sends them."""
