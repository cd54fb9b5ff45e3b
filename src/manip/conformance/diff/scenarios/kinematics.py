"""The diff's scenarios of the kinematic answers a judge of one side can check against that side's own
answers: Here's layout, solve backwards and forwards of a pose the arm stands at, underflow to zero.

What the 1985 guide fixes and what it leaves: Here's transform is column-major (E.1 Opcode 201, clause
``here.transform``); angles are degrees and lengths the server's own unit (erratum units: mm, cm or
inches, so a guide-only server in inches is judged in inches); which of several solutions solve forwards
picks is the solution code's (erratum pose-equivalence: joint angles are never compared, only the pose
they reach).  So no check trusts the reference server: the arm is set to a pose, and its own Here there is
the transform that pose produces, which solve backwards of those angles must give too; solve forwards of
that transform must answer angles that reach it.  The spec's kinematics (the PUMA 600, erratum
geometry) only say which transform to ask solve forwards of (one in reach, in each unit), and are
trusted only where the side's own Here agrees with them.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Final

from manip.arm.kinematics import PUMA600, forward
from manip.arm.units import LENGTH_UNITS, MM_PER_UNIT, LengthUnit, WireLengths
from manip.conformance.cases.server.floats import TINY_WRIST, bad_patterns, by_rows, sent_by_rows, unflushed
from manip.conformance.diff.scenarios.kit import (
    POSE,
    REST,
    Events,
    all_of,
    angles_of,
    answers_to,
    close_to,
    floats_at,
    floats_data,
    opcode_of,
    payload,
    read_back,
    read_here,
    req,
    scenario_stream,
    shown_angles,
    sighting,
)
from manip.conformance.diff.streams import Stream
from manip.conformance.fuzz.judge import Sighting
from manip.conformance.fuzz.steps import Pause, Step
from manip.spec.constants import ServerOp

SAME_POSE_TURN: Final = 0.01
"""How far two rotations of one pose may differ, entry by entry (a joint settled within a few hundredths
of a degree turns the hand by far less; angles read as radians, by tens of degrees)."""
SAME_POSE_MM: Final = 2.0
"""How far two positions of one pose may be apart (mm; in the side's unit, as many of its units)."""
POSE_TRANSFORM: Final = forward(POSE, PUMA600.geometry).to_floats()
"""The transform of :data:`POSE` by the spec's kinematics, in millimetres."""


def _pose_in(unit: LengthUnit) -> tuple[float, ...]:
    """:data:`POSE_TRANSFORM` with its position in ``unit``."""
    return WireLengths(unit).transform_out(POSE_TRANSFORM)


def same_pose(got: Sequence[float], want: Sequence[float], unit: LengthUnit) -> bool:
    """Whether two transforms in ``unit`` are one pose within :data:`SAME_POSE_TURN` and
    :data:`SAME_POSE_MM`."""
    if len(got) != 12 or len(want) != 12:
        return False
    turn = max(abs(g - w) for g, w in zip(got[:9], want[:9], strict=True))
    return turn <= SAME_POSE_TURN and math.dist(got[9:], want[9:]) <= SAME_POSE_MM / MM_PER_UNIT[unit]


def _unit_of(here: Sequence[float]) -> LengthUnit | None:
    """The unit in which the side's Here at :data:`POSE` is the spec's transform of it (None: in none;
    the side's arm is not the spec's, and nothing here judges its solutions)."""
    return next((u for u in LENGTH_UNITS if same_pose(here, _pose_in(u), u)), None)


def _check_here(at: int) -> Callable[[Events], list[Sighting]]:
    """Here's twelve floats are the transform column by column: floats that are a rotation only read row by
    row (Nx Ox Ax Px Ny ...) break its order (``here.transform``; the directed case
    server.float.here-consistent's judge)."""

    def check(events: Events) -> list[Sighting]:
        here = read_here(events, at)
        if here is None or not sent_by_rows(here[1]):
            return []
        message = "Here's floats are a rotation and a position only when read row by row (Nx Ox Ax Px Ny ...)"
        expected = "the transform column by column: Nx Ny Nz Ox Oy Oz Ax Ay Az Px Py Pz"
        return [sighting(at, "here.transform", message, expected, here[0])]

    return check


def _pose_here(events: Events, at: int) -> tuple[list[float], LengthUnit] | None:
    """The side's Here at input ``at`` (read column by column, or row by row where it was sent so) and
    the unit it agrees with the spec's transform of :data:`POSE` in, once the joint angles read there
    are :data:`POSE` (the arm stands at it)."""
    joints, here = read_back(events, at), read_here(events, at)
    if joints is None or here is None or not close_to(joints[1], POSE):
        return None
    pose = list(by_rows(here[1])) if sent_by_rows(here[1]) else here[1]
    unit = _unit_of(pose)
    return None if unit is None else (pose, unit)


def _check_backwards(at: int, solved: int) -> Callable[[Events], list[Sighting]]:
    """Solve backwards of :data:`POSE` (input ``solved``) gives the transform the arm's own Here shows
    while it stands at POSE (input ``at``), where that Here is the spec's transform of POSE too
    (``solve-backwards.data``: the transform the angles produce)."""

    def check(events: Events) -> list[Sighting]:
        seen = _pose_here(events, at)
        answers = floats_at(events, solved, "solve-backwards")
        if seen is None or not answers or same_pose(answers[0][1], seen[0], seen[1]):
            return []
        message = f"solve backwards of {shown_angles(POSE)} gave {shown_angles(answers[0][1])}"
        expected = f"the transform Here shows with the arm at those angles, {shown_angles(seen[0])}"
        return [sighting(solved, "solve-backwards.data", message, expected, answers[0][0])]

    return check


def _reaches(angles: Sequence[float], transform: Sequence[float], unit: LengthUnit) -> bool:
    """Whether ``angles`` reach ``transform`` (in ``unit``): they are :data:`POSE` (whose transform it
    is on the side's own arm), or the spec's kinematics take them to it (another solution)."""
    at_pose = len(angles) == 6 and all(
        close_to([math.remainder(a - p, 360.0)], [0.0]) for a, p in zip(angles, POSE, strict=True)
    )
    if at_pose or len(angles) != 6:
        return at_pose
    reached = WireLengths(unit).transform_out(forward(angles, PUMA600.geometry).to_floats())
    return same_pose(reached, transform, unit)


def _check_forwards(at: int, solved: int) -> Callable[[Events], list[Sighting]]:
    """Solve forwards of the spec's transform of :data:`POSE` in each unit (input ``solved``), in the
    unit the side's own Here at POSE agrees with it in (input ``at``): an answer of six angles reaches
    that transform (``solve-forwards.data``; erratum pose-equivalence: any solution, in degrees)."""

    def check(events: Events) -> list[Sighting]:
        seen = _pose_here(events, at)
        if seen is None:
            return []
        unit = seen[1]
        asked = answers_to(events.get(solved, []), opcode_of("solve-forwards"))
        answer = asked[LENGTH_UNITS.index(unit)] if len(asked) == len(LENGTH_UNITS) else None
        angles = angles_of(answer) if answer is not None and answer.opcode == ServerOp.RESPONSE else None
        if answer is None or angles is None or _reaches(angles, seen[0], unit):
            return []
        message = (
            f"solve forwards of the transform of {shown_angles(POSE)} ({unit}) gave {shown_angles(angles)}"
        )
        expected = "joint angles in degrees that reach the transform (the arm's own Here at those angles)"
        return [sighting(solved, "solve-forwards.data", message, expected, answer)]

    return check


def _check_underflow(at: int) -> Callable[[Events], list[Sighting]]:
    """Solve backwards of every joint at 0 and of :data:`TINY_WRIST` (input ``at``, in that order): where
    the first rotation has a zero the second has one too, its change there being below 2^-128
    (``float.range``), and no float of theirs is a dirty zero (``float.dirty-zero``) (the directed case
    server.float.extremes's judges)."""

    def check(events: Events) -> list[Sighting]:
        answers = floats_at(events, at, "solve-backwards")
        for event, _ in answers:
            dirty = bad_patterns(payload(event))[1]
            if dirty:
                message = f"solve backwards answered exponent 0 with fraction bits: {'; '.join(dirty)}"
                return [sighting(at, "float.dirty-zero", message, "a clean zero (all bits 0)", event)]
        if len(answers) != 2 or len(answers[0][1]) != 12 or len(answers[1][1]) != 12:
            return []
        wrong = unflushed(answers[0][1], answers[1][1])
        if not wrong:
            return []
        message = f"solve backwards of {shown_angles(TINY_WRIST)} has {'; '.join(wrong)}"
        expected = (
            "zero where the rotation of every joint at 0 has zero (a magnitude below 2^-128 is sent as zero)"
        )
        return [sighting(at, "float.range", message, expected, answers[1][0])]

    return check


def _kinematics() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "enable power, set joint angles, rest, joint angles, here",
            [
                req("enable-power"),
                req("set-joint-angles", floats_data(POSE)),
                Pause(REST),
                req("joint-angles"),
                req("here"),
            ],
        ),
        ("solve backwards of the angles set", [req("solve-backwards", floats_data(POSE))]),
        (
            "solve forwards of their transform, in mm, cm and inches",
            [req("solve-forwards", floats_data(_pose_in(u)) + floats_data(POSE)) for u in LENGTH_UNITS],
        ),
        (
            "solve backwards of every joint at 0 and of wrist angles whose sines underflow",
            [
                req("solve-backwards", floats_data((0.0,) * 6)),
                req("solve-backwards", floats_data(TINY_WRIST)),
            ],
        ),
    ]
    check = all_of(_check_here(0), _check_backwards(0, 1), _check_forwards(0, 2), _check_underflow(3))
    return scenario_stream("kinematics", groups, check)


SCENARIOS: Final[dict[str, Callable[[], Stream]]] = {
    "kinematics": _kinematics,
}
"""This module's scenarios by name, in the order a diff sends them."""
