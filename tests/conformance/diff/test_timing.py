"""The diff's timing scenarios (:mod:`manip.conformance.diff.scenarios.timing`) judged from events made
by hand: the times an event carries are never compared, samples timed exactly (virtual time) judge the
servo period and a held reply, and the same samples with the round trips of a busy host are not judged,
saying why.  Sans-I/O: no server runs."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import pytest

from manip.conformance.diff.pairing import SideEvent, differing_parts
from manip.conformance.diff.scenarios import scenario
from manip.conformance.diff.scenarios.kit import READY_POSE, floats_data, opcode_of, word
from manip.conformance.diff.scenarios.timing import REPLY_SWING_DEG
from manip.spec.constants import ServerOp

Timed = Callable[[float], float]


def _answer(name: str, data: bytes, asked: float, came: float) -> SideEvent:
    request = opcode_of(name)  # type: ignore[arg-type]
    return SideEvent("packet", ServerOp.RESPONSE, b"\1\0" + data, request=request, time=came, asked=asked)


def _read(joint1: float, asked: float, came: float) -> SideEvent:
    return _answer("joint-angles", floats_data((joint1, *READY_POSE[1:])), asked, came)


def _queued(path: Timed, trip: float) -> dict[int, list[SideEvent]]:
    """The queued-timing scenario's answers: four moves answered, joint angles before them, then joint 1
    read every 6 ms for 0.8 s along ``path`` (read when asked; answered ``trip`` seconds later)."""
    events = [_answer("set-joint-angles", word(n), 0.0, trip) for n in range(1, 5)]
    events.insert(1, _read(READY_POSE[0], 0.0, trip))
    events += [_read(path(k * 0.006), k * 0.006, k * 0.006 + trip) for k in range(134)]
    return {0: events}


def _servo(period: float) -> Timed:
    """Joint 1 stepping every ``period`` seconds to 30 degrees in 0.48 s, standing there after."""
    return lambda t: min(30.0, math.floor(t / period) * 30.0 / (0.48 / period))


def _judged(name: str, events: dict[int, list[SideEvent]]) -> tuple[list[str], list[str]]:
    stream = scenario(name)
    assert stream.check is None and stream.judge is not None
    sightings, unjudged = stream.judge(events)
    return [s.violation.clause or "" for s in sightings], unjudged


def test_the_times_an_event_carries_are_never_compared() -> None:
    early, late = _read(1.0, 0.0, 0.001), _read(1.0, 5.0, 7.0)
    assert early == late and differing_parts(early, late) == ()


@pytest.mark.parametrize(
    ("period", "trip", "named", "unjudged"),
    [
        (0.016, 0.0, [], []),
        (0.008, 0.0, ["motion.servo-period"], []),
        (0.016, 0.03, [], ["motion.servo-period", "motion.smooth-transitions"]),
    ],
    ids=["a 16 ms servo", "an 8 ms servo", "round trips of 30 ms"],
)
def test_queued_moves_sampled_judge_the_servo_period_on_the_sides_times(
    period: float, trip: float, named: list[str], unjudged: list[str]
) -> None:
    sightings, notes = _judged("queued-timing", _queued(_servo(period), trip))
    assert sightings == named
    assert [n.split(":")[0] for n in notes] == unjudged


def _reply(held: float, first_trip: float) -> dict[int, list[SideEvent]]:
    """The reply-timing scenario's answers to its timed move: joint angles before it (answered
    ``first_trip`` s later), the move's reply ``held`` s after it was asked, and joint 1 read every 50 ms
    as it goes its way in 1 s (every answer in order: none before the reply)."""

    def way(t: float) -> float:
        return READY_POSE[0] + REPLY_SWING_DEG * min(1.0, t)

    reads: Sequence[SideEvent] = [_read(way(k * 0.05), k * 0.05, max(k * 0.05, held)) for k in range(1, 21)]
    before = _read(READY_POSE[0], 0.0, first_trip)
    move = _answer("set-joint-angles", word(1), 0.0, max(held, first_trip))
    return {1: [_answer("request-notifications", b"", 0.0, 0.0), before, move, *reads]}


@pytest.mark.parametrize(
    ("held", "first_trip", "named", "unjudged"),
    [
        (0.0, 0.0, [], []),
        (1.02, 0.0, ["motion.reply-before-motion"], []),
        (1.02, 0.5, [], ["motion.reply-before-motion"]),
    ],
    ids=["answered at once", "held until the arm rests", "a host that answers late"],
)
def test_a_moves_reply_is_judged_by_where_the_arm_was_when_it_came(
    held: float, first_trip: float, named: list[str], unjudged: list[str]
) -> None:
    sightings, notes = _judged("reply-timing", _reply(held, first_trip))
    assert sightings == named
    assert [n.split(":")[0] for n in notes] == unjudged
