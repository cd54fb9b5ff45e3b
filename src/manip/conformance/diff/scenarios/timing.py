"""The diff's scenarios of when the arm moves and when the answers come: queued moves sampled every few
milliseconds, a move's reply against where the arm stands when it comes, the codes of the reports of
segments completed, and the byte order of the angles read back.

Their checks read each event's times (:attr:`~manip.conformance.diff.pairing.SideEvent.time`, when it
came, and ``asked``, when its request went out: the side's clock, virtual time on an embedded side), as
the directed case ``server.motion.queued-segments`` reads its samples' times, and judge them with that
case's own judges (:mod:`manip.conformance.cases.server.trajectory`).  On an addressed side, in real
time, a timing clause whose breach the samples' round trips or the host's delays could hide, or
explain, is not judged: no sighting is made of it, and the diff reports it not judged with the delays
measured (:attr:`~manip.conformance.diff.streams.Stream.judge`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from itertools import pairwise
from typing import Final

from manip.conformance.cases._support import SEGMENT_MASK
from manip.conformance.cases.server.trajectory import (
    QUEUED_STEPS,
    SAMPLE_S,
    SERVO_S,
    Sample,
    Timing,
    smooth_rest_checks,
)
from manip.conformance.diff.pairing import SideEvent
from manip.conformance.diff.scenarios import kit
from manip.conformance.diff.scenarios.kit import (
    READY_POSE,
    REST,
    SWING_DEG,
    Events,
    floats_at,
    floats_data,
    req,
    scenario_stream,
    segments_at,
    sighting,
    word,
)
from manip.conformance.diff.streams import Stream
from manip.conformance.fuzz.judge import Sighting
from manip.conformance.fuzz.steps import Pause, Step
from manip.spec.constants import AsyncCondition, ServerOp

SAMPLES: Final = 480
"""Joint angles read every :data:`~manip.conformance.cases.server.trajectory.SAMPLE_S` after the
queued moves: 2.88 s of samples, the three moves (2.6 s at speed factor 1) and the arm at rest after
them."""
REPLY_SWING_DEG: Final = 10.0
"""How far joint 1 turns in the move whose reply is timed: short enough that a reply held until the arm
comes to rest still comes within the reply timeout (the diff would otherwise see it missing)."""
READ_EVERY: Final = 0.05
READS: Final = 20
"""Joint angles read every READ_EVERY seconds after the timed move, READS times: through most of the
move, and over before its report comes (a pause ends early when an asynchronous packet comes, so a
report among the readings would shift the later readings' times on a side that sends it)."""
PROMPT_S: Final = 0.1
"""The longest an answer that needs no arm may take for the move's reply to be judged on its times."""


def _ready_then(steps: Sequence[Step]) -> list[Step]:
    """Enable power, to the ready position, a rest, the joint angles, then ``steps``."""
    return [
        req("enable-power"),
        req("set-joint-angles", floats_data(READY_POSE)),
        Pause(REST),
        req("joint-angles"),
        *steps,
    ]


def _swung(by: float) -> tuple[float, ...]:
    return (READY_POSE[0] + by, *READY_POSE[1:])


# Queued moves sampled ---------------------------------------------------------------------------------


def _samples(reads: Sequence[tuple[SideEvent, list[float]]]) -> list[Sample] | None:
    """The readings as the directed case's samples (asked, answered, angles); None when one has no time
    of its request."""
    out = []
    for event, values in reads:
        if event.asked is None:
            return None
        out.append(Sample(event.asked, event.time, tuple(values)))
    return out


def _lateness(samples: Sequence[Sample]) -> float:
    """How late the side's sampler sent a reading at most, after the pause before it: the host's delay
    while it sampled (0 in virtual time)."""
    return max((max(0.0, b.sent - a.sent - SAMPLE_S) for a, b in pairwise(samples)), default=0.0)


def _came_to_rest(timing: Timing) -> bool:
    """Whether joint 1 was seen standing still for three servo cycles after it last changed."""
    samples, moved = timing.samples, timing.changed
    return bool(moved) and samples[-1].sent - samples[moved[-1]].received >= 3 * SERVO_S


Judgement = tuple[list[Sighting], list[str]]
"""What a timing judge found on a side: its sightings, and what it could not judge (and why)."""
NOTHING: Final[Judgement] = ([], [])


def _judge_queued(at: int) -> Callable[[Events], Judgement]:
    """Three moves of joint 1 queued at input ``at``, from the ready position, sampled every 6 ms: the
    arm comes to rest on the last goal without passing it (``motion.ends-at-rest``), what it reports
    changes at most once per 16 ms servo cycle (``motion.servo-period``), and it never stands still
    between its first change and its last (``motion.smooth-transitions``): the directed case
    ``server.motion.queued-segments``'s judges, on the side's times (each not judged, saying why,
    where the samples' round trips or the host's delays could hide a breach)."""

    def judge(events: Events) -> Judgement:
        reads = floats_at(events, at, "joint-angles")
        moves = segments_at(events, at)
        if len(reads) < 2 or len(moves) != 1 + len(QUEUED_STEPS) or not kit.close_to(reads[0][1], READY_POSE):
            return NOTHING  # refused, or not at the ready position when the moves were queued
        samples = _samples(reads[1:])
        if samples is None:
            return NOTHING
        timing = Timing(samples, 1.0, _lateness(samples))
        last = READY_POSE[0] + QUEUED_STEPS[-1]
        judged = dict(smooth_rest_checks(timing, 1.0, last))
        rest = judged.pop("motion.ends-at-rest")
        unjudged = []
        if _came_to_rest(timing):  # sampled until it stood still: where it came to rest is judged
            judged["motion.ends-at-rest"] = rest
        else:
            unjudged.append(
                f"motion.ends-at-rest: joint 1 was not seen standing still on {last:g} within the "
                f"{len(samples)} samples ({timing.delays()})"
            )
        out = []
        for clause, verdict in judged.items():
            if not verdict.held:
                out.append(sighting(at, clause, verdict.seen, verdict.expected, reads[-1][0]))
            elif verdict.unjudged:
                unjudged.append(verdict.unjudged)
        return out, unjudged

    return judge


def _queued() -> Stream:
    steps: list[Step] = [req("set-joint-angles", floats_data(_swung(step))) for step in QUEUED_STEPS]
    for _ in range(SAMPLES):
        steps += [req("joint-angles"), Pause(SAMPLE_S)]
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            f"enable power, to ready, joint angles, three moves of joint 1 queued, joint angles every "
            f"{SAMPLE_S * 1000:g} ms",
            _ready_then(steps),
        )
    ]
    return scenario_stream("queued-timing", groups, judge=_judge_queued(0))


# A move's reply, and the angles read back -------------------------------------------------------------


def _judge_reply(at: int) -> Callable[[Events], Judgement]:
    """A move of joint 1 by :data:`REPLY_SWING_DEG` from the ready position (input ``at``: the joint angles
    before it, its reply, the joint angles every :data:`READ_EVERY` seconds after it): the reply comes
    before the arm reaches the goal (``motion.reply-before-motion``).  The readings asked before the
    reply came show where the arm was when it came: past half its way, the reply waited for the motion.

    Not judged (saying why) unless the side answered promptly what needs no arm: the reading before
    the move, and those asked after the reply came, each within :data:`PROMPT_S` (on an addressed side
    a host whose answers lag could hold every reply as long)."""

    def judge(events: Events) -> Judgement:
        reads, moves = floats_at(events, at, "joint-angles"), segments_at(events, at)
        if len(reads) < 3 or len(moves) != 1 or not kit.close_to(reads[0][1], READY_POSE):
            return NOTHING
        reply = moves[0][0]
        if reply.asked is None or any(e.asked is None for e, _ in reads):
            return NOTHING
        before = [v[0] for e, v in reads[1:] if (e.asked or 0.0) < reply.time]
        after = [e for e, _ in reads[1:] if (e.asked or 0.0) >= reply.time]
        way = (max(before, default=READY_POSE[0]) - READY_POSE[0]) / REPLY_SWING_DEG
        if way <= 0.5:
            return NOTHING
        took = reply.time - reply.asked
        slowest = max(e.time - (e.asked or 0.0) for e in [reads[0][0], *after])
        if slowest > PROMPT_S:
            return [], [
                f"motion.reply-before-motion: the move's reply came after {took:.3f} s, but an answer that "
                f"needs no arm took {slowest:.3f} s (more than {PROMPT_S:g} s): the host's delays could "
                "explain it"
            ]
        message = (
            f"the move's reply came after {took:.3f} s, when joint 1 had gone {way:.0%} of its way "
            f"(read at {max(before):.2f}, goal {READY_POSE[0] + REPLY_SWING_DEG:.2f})"
        )
        expected = "the reply as soon as the segment is queued, before the arm reaches the goal"
        return [sighting(at, "motion.reply-before-motion", message, expected, reply)], []

    return judge


def _check_byte_order(at: int) -> Callable[[Events], list[Sighting]]:
    """The joint angles read at the ready position (input ``at``) read as the ready position only with
    the two bytes of every word swapped: the data's first byte is not the word's low one
    (``chaos.data.byte-order``)."""

    def check(events: Events) -> list[Sighting]:
        answers = kit.answers_to(events.get(at, []), kit.opcode_of("joint-angles"))
        read = next((e for e in reversed(answers) if kit.is_op(e, ServerOp.RESPONSE)), None)
        if read is None:
            return []
        as_sent = kit.angles_of(read)
        if as_sent is not None and kit.close_to(as_sent, READY_POSE):
            return []  # the ready position: the byte order is right
        if not kit.close_to(kit.byte_swapped(read), READY_POSE):
            return []  # wrong, but not for its byte order: not this check's to name
        message = (
            f"the joint angles read {kit.shown_angles(READY_POSE)} at the ready position only with the two "
            "bytes of every word swapped"
        )
        return [
            sighting(at, "chaos.data.byte-order", message, "the first data byte of a word its low one", read)
        ]

    return check


def _reply() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        ("enable power, to ready, rest, joint angles", _ready_then([])),
        (
            f"notifications of segments completed, joint angles, a move of joint 1, joint angles every "
            f"{READ_EVERY * 1000:g} ms",
            [
                # Where the segment's report comes among the answers shows when the reply came (the
                # times are never compared): after the readings, or, held until the arm rests, first.
                req("request-notifications", word(SEGMENT_MASK)),
                req("joint-angles"),
                req("set-joint-angles", floats_data(_swung(REPLY_SWING_DEG))),
                *[step for _ in range(READS) for step in (Pause(READ_EVERY), req("joint-angles"))],
            ],
        ),
    ]
    byte_order, reply = _check_byte_order(0), _judge_reply(1)

    def judge(events: Events) -> Judgement:
        sightings, unjudged = reply(events)
        return byte_order(events) + sightings, unjudged

    return scenario_stream("reply-timing", groups, judge=judge)


# The reports of segments completed --------------------------------------------------------------------


def _check_codes(at: int) -> Callable[[Events], list[Sighting]]:
    """On a connection that asked for segment completions alone and set no guard, the report that
    carries the number of the segment queued at input ``at`` has condition code 2 (move segment
    completed), never 1 (guard hit): ``async.codes``."""

    def check(events: Events) -> list[Sighting]:
        moves = segments_at(events, at)
        if len(moves) != 2:
            return []
        move = moves[-1]
        for event in events.get(at, []):
            report = kit.async_in(event)
            if (
                report is None
                or report.word3 != move[1]
                or report.condition == AsyncCondition.SEGMENT_COMPLETED
            ):
                continue
            message = f"the report of segment {move[1]} carries condition code {report.condition}"
            expected = (
                "condition code 2 (move segment completed): segment completions alone were asked for, and no "
                "guard was set"
            )
            return [sighting(at, "async.codes", message, expected, event)]
        return []

    return check


def _codes() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "notifications of segments completed, a move of joint 1, a wait for its report",
            _ready_then(
                [
                    req("request-notifications", word(SEGMENT_MASK)),
                    req("set-joint-angles", floats_data(_swung(-SWING_DEG / 6))),
                    Pause(REST),  # ends when the report comes
                ]
            ),
        )
    ]
    return scenario_stream("segment-codes", groups, _check_codes(0))


SCENARIOS: Final[dict[str, Callable[[], Stream]]] = {
    "reply-timing": _reply,
    "segment-codes": _codes,
    "queued-timing": _queued,
}
"""This module's scenarios by name, in the order a diff sends them."""
