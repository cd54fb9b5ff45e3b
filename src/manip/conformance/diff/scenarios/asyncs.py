"""The diff's scenarios of asynchronous responses and errors: unrequested and notified reports, fatal
errors, warnings, a silent wrist, a collision."""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from typing import Final

from manip.conformance.diff.pairing import SideEvent
from manip.conformance.diff.scenarios.kit import (
    NZI_JOINTS,
    POSE,
    SETTLE,
    Events,
    all_of,
    answer_at,
    answers_to,
    close_to,
    error_in,
    floats_at,
    floats_data,
    is_op,
    opcode_of,
    req,
    scenario_inputs,
    scenario_stream,
    shown_angles,
    sighting,
    wire_of,
)
from manip.conformance.diff.streams import Stream
from manip.conformance.fuzz.judge import Sighting
from manip.conformance.fuzz.steps import Pause, Step
from manip.conformance.judge.checks import completed_segment
from manip.conformance.suite.world import CalibrationFailure, Obstacle, SilentWrist, SluggishJoint
from manip.spec.constants import ASYNC_ERROR_OPS, ServerOp


def _check_nzi(at: int) -> Callable[[Events], list[Sighting]]:
    """Calibration's F NZI names joints 2 and 3 (the condition's): the mask 6."""

    def check(events: Events) -> list[Sighting]:
        fatal = [e for e in events.get(at, []) if e.kind == "packet" and e.opcode == ServerOp.FATAL_ERROR]
        if not fatal:
            return []
        error = error_in(fatal[0], ServerOp.FATAL_ERROR)
        if error is None:
            return []
        want = sum(1 << (j - 1) for j in NZI_JOINTS)
        if error.code != "NZI" or error.args == (want,):
            return []
        message = (
            f"F NZI carries {list(error.args)}, not the mask of joints {NZI_JOINTS} whose index was hidden"
        )
        return [sighting(at, "calibrate.nzi-mask", message, f"the mask {want}", fatal[0])]

    return check


def _check_collision(at: int, after: Sequence[int]) -> Callable[[Events], list[Sighting]]:
    """A move into the obstacle the condition placed (input ``at``, the segment after it queued too)
    ends with an asynchronous error; from then on motion is refused AWA until a reset, and the segment
    queued behind the aborted one never completes, not even after the reset (``motion.abort``; the
    inputs ``after``)."""

    def check(events: Events) -> list[Sighting]:
        seen = [(n, e) for n in (at, *after) for e in events.get(n, [])]
        first = next(iter(events.get(at, [])), None)
        if first is None:
            return []
        aborted = next((i for i, (_, e) in enumerate(seen) if is_op(e, ServerOp.ASYNCHRONOUS_ERROR)), None)
        if aborted is None:
            message = "a move into the obstacle ended without an asynchronous error"
            return [sighting(at, "motion.collision", message, "an asynchronous collision error", first)]
        queued = {
            int.from_bytes(e.data[2:4], "little")
            for e in answers_to(events.get(at, []), opcode_of("set-joint-angles"))
            if e.opcode == ServerOp.RESPONSE and len(e.data) >= 4
        }
        late = [(n, e) for n, e in seen[aborted:] if completed_segment(wire_of(e)) in queued]
        if late:
            message = "a segment queued before the abort completed after it"
            return [sighting(late[0][0], "motion.abort", message, "the queued segments dropped", late[0][1])]
        out: list[Sighting] = []
        for number in [n for n in after[:1] if n > seen[aborted][0]]:  # only once the abort was seen
            for answer in answers_to(events.get(number, []), opcode_of("set-joint-angles")):
                if answer.opcode == ServerOp.RESPONSE:
                    message = "a motion request after the abort was accepted before any reset"
                    out.append(sighting(number, "motion.abort", message, "E AWA", answer))
            for answer in answers_to(events.get(number, []), opcode_of("here")):
                if answer.opcode != ServerOp.RESPONSE:
                    message = "here, which moves nothing, was refused while motion was aborted"
                    clause = "motion.abort-serves-others"
                    out.append(sighting(number, clause, message, "the transform, as usual", answer))
        return out

    return check


def _check_fifo(at: int) -> Callable[[Events], list[Sighting]]:
    """The segments queued at input ``at`` complete in the order they were queued: the segment-completed
    reports name the numbers their requests were answered with, in that order."""

    def check(events: Events) -> list[Sighting]:
        here = events.get(at, [])
        queued = [
            int.from_bytes(e.data[2:4], "little")
            for e in answers_to(here, opcode_of("set-joint-angles"))
            if e.opcode == ServerOp.RESPONSE and len(e.data) >= 4
        ]
        reports = [(e, completed_segment(wire_of(e))) for e in here if e.kind == "packet"]
        done = [(e, n) for e, n in reports if n is not None]
        if not done or [n for _, n in done] == queued[: len(done)]:
            return []
        shown = [n for _, n in done]
        message = f"segments queued as {queued} were reported completed as {shown}"
        return [sighting(at, "segment.fifo-completion", message, f"completions {queued}", done[0][0])]

    return check


def _unrequested() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "enable power, ready, rest (no notifications asked for)",
            [req("enable-power"), req("ready"), Pause(SETTLE)],
        ),
        ("here", [req("here")]),
    ]
    return scenario_stream("unrequested-async", groups)


def _notified() -> Stream:
    moves = [(0.0, -90.0, 90.0, 0.0, 0.0, 0.0), POSE, (0.0, -60.0, 60.0, 0.0, 10.0, 0.0)]
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "enable power, notifications 3",
            [req("enable-power"), req("request-notifications", struct.pack("<H", 3))],
        ),
        (
            "three segments queued, rest",
            [
                *(req("set-joint-angles", floats_data(m)) for m in moves),
                Pause(SETTLE),
                Pause(SETTLE),
                Pause(SETTLE),
            ],
        ),
        ("here", [req("here")]),
        (
            "describe self, twice pipelined, here",
            [req("describe-self", lazy=True), req("describe-self", lazy=True), req("here")],
        ),
    ]
    return Stream(
        None, scenario_inputs("notified-motion", groups), scenario="notified-motion", check=_check_fifo(1)
    )


def _fatal() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        ("enable power", [req("enable-power")]),
        ("calibrate (no zero index on joints 2 and 3)", [req("calibrate")]),
        ("here (on the connection the fatal error left)", [req("here")]),
    ]
    return Stream(
        None,
        scenario_inputs("fatal-error", groups),
        scenario="fatal-error",
        conditions=(CalibrationFailure(NZI_JOINTS),),
        check=_check_nzi(1),
    )


WARNED_GOAL: Final = (0.0, -20.0, 90.0, 0.0, 0.0, 0.0)
"""The goal of the warning scenario's long move of joint 2 (the sluggish joint lags on its way)."""
WARNED_READS: Final = 2.0
"""Seconds between the warning scenario's two reads of the joints after the warning."""


def _stream_order(events: Events) -> list[tuple[int, SideEvent]]:
    return [(n, e) for n in sorted(events) for e in events[n]]


def _check_async_number(events: Events) -> list[Sighting]:
    """An asynchronous error or warning carries the number of the last request processed: the one whose
    answer came last before it (``async-error.request-number``, erratum async-last-processed)."""
    last: int | None = None
    for number, event in _stream_order(events):
        if event.kind != "packet" or len(event.data) < 2:
            continue
        said = int.from_bytes(event.data[:2], "little")
        if event.request is not None:
            last = said
        elif event.opcode in ASYNC_ERROR_OPS and last is not None and said != last:
            what = "error" if event.opcode == ServerOp.ASYNCHRONOUS_ERROR else "warning"
            message = (
                f"an asynchronous {what} carries request number {said}; the last request answered was {last}"
            )
            return [sighting(number, "async-error.request-number", message, f"request number {last}", event)]
    return []


def _check_warning(moved: int, read: int, goal: Sequence[float]) -> Callable[[Events], list[Sighting]]:
    """A warning does not interrupt work: after an asynchronous warning during the move (input
    ``moved``), no asynchronous error follows, and the arm, read twice at input ``read``, is still on
    its way (or at the goal) (``async-warning.format``)."""

    def check(events: Events) -> list[Sighting]:
        order = _stream_order(events)
        warned = next((i for i, (_, e) in enumerate(order) if is_op(e, ServerOp.ASYNCHRONOUS_WARNING)), None)
        if warned is None:
            return []
        for _, event in order[warned:]:
            if is_op(event, ServerOp.ASYNCHRONOUS_ERROR):
                message = "an asynchronous error followed the warning: the warning interrupted the motion"
                return [sighting(moved, "async-warning.format", message, "the motion going on", event)]
        reads = floats_at(events, read, "joint-angles")
        if len(reads) != 2 or not close_to(reads[0][1], reads[1][1]) or close_to(reads[1][1], goal):
            return []
        still, goal_text = shown_angles(reads[1][1]), shown_angles(goal)
        message = f"after the warning the arm stood still at {still}, short of {goal_text}"
        return [sighting(moved, "async-warning.format", message, "the motion going on", reads[1][0])]

    return check


def _sluggish() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "enable power, notifications 3",
            [req("enable-power"), req("request-notifications", struct.pack("<H", 3))],
        ),
        (
            "a long move of joint 2, rest",
            [req("set-joint-angles", floats_data(WARNED_GOAL)), Pause(SETTLE)],
        ),
        (
            "joint angles twice, seconds apart, here",
            [req("joint-angles"), Pause(WARNED_READS), req("joint-angles"), req("here")],
        ),
    ]
    return Stream(
        None,
        scenario_inputs("warning", groups),
        scenario="warning",
        conditions=(SluggishJoint(),),
        check=_check_warning(1, 2, WARNED_GOAL),
    )


def _check_wrist(at: int) -> Callable[[Events], list[Sighting]]:
    """While the wrist is silent, read forces (input ``at``) is answered with a non-fatal error, never
    left unanswered nor answered with a fatal one (``wrist.no-answer``)."""

    def check(events: Events) -> list[Sighting]:
        answer = answer_at(events, at, "read-forces")
        if answer is not None and answer.opcode == ServerOp.NON_FATAL_ERROR:
            return []
        if answer is None:
            message = "read forces got no answer while the wrist was silent"
            seen = SideEvent("stream", text="no answer to read forces")
        else:
            message = f"read forces was answered 0{answer.opcode:o} while the wrist was silent"
            seen = answer
        return [sighting(at, "wrist.no-answer", message, "a non-fatal error (202)", seen)]

    return check


def _wrist_silent() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        ("read forces (the wrist does not answer)", [req("read-forces")]),
        ("here", [req("here")]),
    ]
    return Stream(
        None,
        scenario_inputs("wrist-silent", groups),
        scenario="wrist-silent",
        conditions=(SilentWrist(),),
        check=_check_wrist(0),
    )


def _collision() -> Stream:
    into = floats_data((0.0, -20.0, 90.0, 0.0, 0.0, 0.0))
    back = floats_data((0.0, -80.0, 90.0, 0.0, 0.0, 0.0))
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "enable power, notifications 3",
            [req("enable-power"), req("request-notifications", struct.pack("<H", 3))],
        ),
        (
            "move joint 2 into the obstacle at -60 degrees, a segment queued behind it, rest",
            [req("set-joint-angles", into), req("set-joint-angles", back), Pause(SETTLE)],
        ),
        ("a motion request before any reset (AWA), here", [req("set-joint-angles", back), req("here")]),
        ("enable power (the reset), rest, here", [req("enable-power"), Pause(SETTLE), req("here")]),
    ]
    check = all_of(_check_collision(1, (2, 3)), _check_async_number)
    return Stream(
        None,
        scenario_inputs("collision", groups),
        scenario="collision",
        conditions=(Obstacle(2, upper=-60.0),),
        check=check,
    )


SCENARIOS: Final[dict[str, Callable[[], Stream]]] = {
    "unrequested-async": _unrequested,
    "notified-motion": _notified,
    "fatal-error": _fatal,
    "warning": _sluggish,
    "wrist-silent": _wrist_silent,
    "collision": _collision,
}
"""This module's scenarios by name, in the order a diff sends them."""
