"""The diff's scenarios of values a judge can compute: float extremes, the configuration bit, increments,
joint order."""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Sequence
from typing import Final

from manip.arm.kinematics import PUMA600, configuration
from manip.conformance.cases.server.motion import HAND_TOL_MM, TURN_TOL_DEG
from manip.conformance.cases.server.trajectory import (
    OAT_TOL,
    val_angles,
    val_rotation,
    wrap180,
)
from manip.conformance.diff.scenarios.kit import (
    INCREMENT,
    OAT_TURN,
    READY_POSE,
    REST,
    SEED_ANGLES,
    STILL,
    SWING_DEG,
    Events,
    all_done,
    at_rest,
    close_to,
    floats_data,
    is_op,
    payload,
    read_here,
    req,
    scenario_inputs,
    shown_angles,
    sighting,
    solution_at,
    solve_seed,
    word,
)
from manip.conformance.diff.streams import Stream
from manip.conformance.fuzz.judge import Sighting
from manip.conformance.fuzz.steps import Pause, Step
from manip.spec import SPEC
from manip.spec.constants import ServerOp

TINY: Final = 1e-38
HUGE: Final = 1.0e38


def _extremes() -> Stream:
    """The float extremes case's requests: solve backwards and forwards at the ends of the F range."""
    asks = [
        req("solve-backwards", floats_data((0.0, 0.0, 0.0, TINY, TINY, TINY))),
        req("solve-backwards", floats_data((TINY,) * 6)),
        req("solve-backwards", floats_data((HUGE, -HUGE, 1e20, 3e37, -HUGE, TINY))),
    ]
    for position in ((HUGE, HUGE, HUGE), (-HUGE, 0.0, TINY), (TINY, TINY, TINY)):
        transform = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, *position)
        asks.append(req("solve-forwards", floats_data(transform) + floats_data(READY_POSE)))
    groups: list[tuple[str, Sequence[Step]]] = [(f"request {i}", [a]) for i, a in enumerate(asks)]
    groups.append(("here, joint angles", [req("here"), req("joint-angles")]))
    return Stream(
        None, scenario_inputs("float-extremes", groups), scenario="float-extremes", check=_check_floats
    )


def _check_floats(events: Events) -> list[Sighting]:
    """Every float of every reply is an F value: never the reserved operand (a NaN or an infinity,
    ``float.not-finite``), and below 2^-128 a clean zero (``float.dirty-zero``)."""
    out: list[Sighting] = []
    for number, seen in events.items():
        for event in seen:
            if not is_op(event, ServerOp.RESPONSE) or event.request not in _FLOAT_REPLIES:
                continue
            body = payload(event)
            for i in range(0, len(body) - 3, 4):
                w0, w1 = struct.unpack_from("<HH", body, i)
                if (w0 >> 7) & 0xFF or not (w0 or w1):
                    continue
                clause = "float.not-finite" if w0 & 0x8000 else "float.dirty-zero"
                message = f"float words {w0:04x} {w1:04x} at byte {i} of the reply"
                out.append(sighting(number, clause, message, "an F value, zero all bits clear", event))
                break
    return out


_FLOAT_REPLIES: Final = frozenset(
    SPEC.request(n).opcode for n in ("here", "joint-angles", "solve-forwards", "solve-backwards")
)


def _check_configuration(lefty: int, righty: int) -> Callable[[Events], list[Sighting]]:
    """Solve forwards of the seed's transform after set configuration 1 (input ``lefty``) and 0
    (``righty``): two different solutions (``set-configuration.effect``), the first lefty and the second
    righty by the arm's geometry (raising joint 2 alone lowers the wrist in a lefty one,
    ``set-configuration.lefty-side``).  Judged where the first answer is (what follows it differs for it)."""

    def check(events: Events) -> list[Sighting]:
        got_l, got_r = solution_at(events, lefty), solution_at(events, righty)
        if got_l is None or got_r is None:
            return []
        (answer, left), (_, right) = got_l, got_r
        if close_to(left, right):
            message = f"set configuration 1 and 0 gave one solution, {shown_angles(left)}"
            expected = "a lefty and a righty solution (the transform has both in range)"
            return [sighting(lefty, "set-configuration.effect", message, expected, answer)]
        sides = [configuration(q, PUMA600.geometry)[0] for q in (left, right)]
        if sides == [True, False]:
            return []
        shown = ", ".join("lefty" if s else "righty" for s in sides)
        message = f"the solutions after set configuration 1 and 0 are {shown}"
        return [sighting(lefty, "set-configuration.lefty-side", message, "lefty, then righty", answer)]

    return check


def _configuration() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        ("set configuration 1, solve forwards", [req("set-configuration", word(1)), solve_seed()]),
        ("set configuration 0, solve forwards", [req("set-configuration", word(0)), solve_seed()]),
    ]
    return Stream(
        None,
        scenario_inputs("configuration", groups),
        scenario="configuration",
        check=_check_configuration(0, 1),
    )


def _check_increments(start: int, end: int, turned: int) -> Callable[[Events], list[Sighting]]:
    """Here at input ``start``, after two incremental moves queued back to back (``end``) and after an
    incremental turn by :data:`OAT_TURN` (``turned``), each judged once the arm is at rest: the hand
    moved by both deltas, orientation kept, then turned by dO dA dT of VAL's angles, position kept
    (``incremental.relative``)."""

    def check(events: Events) -> list[Sighting]:
        first, moved, last = (read_here(events, n) for n in (start, end, turned))
        if not (all_done(events, end, 2) and at_rest(events, end)):
            return []  # refused (out of reach in the side's unit, say), or still moving: nothing to judge
        if not (all_done(events, turned, 1) and at_rest(events, turned)):
            last = None
        out: list[Sighting] = []
        if first is not None and moved is not None:
            want = [p + sum(d[i] for d in INCREMENT) for i, p in enumerate(first[1][9:])]
            off = math.dist(moved[1][9:], want)
            turn = max(abs(x - y) for x, y in zip(moved[1][:9], first[1][:9], strict=True))
            if off > HAND_TOL_MM or turn > OAT_TOL:
                message = (
                    f"after both incremental moves the hand is {off:.3g} mm from the start plus both deltas"
                )
                out.append(sighting(end, "incremental.relative", message, shown_angles(want), moved[0]))
        if moved is not None and last is not None:
            o, a, t = val_angles(moved[1])
            want_r = val_rotation(o + OAT_TURN[0], a + OAT_TURN[1], t + OAT_TURN[2])
            got = tuple(tuple(last[1][3 * j + i] for j in range(3)) for i in range(3))
            turn = max(abs(want_r[i][j] - got[i][j]) for i in range(3) for j in range(3))
            if turn > OAT_TOL or math.dist(last[1][9:], moved[1][9:]) > HAND_TOL_MM:
                message = f"after an incremental turn by dO dA dT {OAT_TURN} the rotation is {turn:.3g} off"
                expected = f"O A T {shown_angles((o, a, t))} plus {shown_angles(OAT_TURN)}, position kept"
                out.append(sighting(turned, "incremental.relative", message, expected, last[0]))
        return out

    return check


def _increments() -> Stream:
    def delta(values: Sequence[float]) -> bytes:
        return floats_data(values)

    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "enable power, set joint angles, rest, here",
            [
                req("enable-power"),
                req("set-joint-angles", floats_data(SEED_ANGLES)),
                Pause(REST),
                req("here"),
            ],
        ),
        (
            "two incremental moves queued back to back, rest, here twice",
            [
                req("incremental-move", delta((*INCREMENT[0], 0.0, 0.0, 0.0))),
                req("incremental-straight-move", delta((*INCREMENT[1], 0.0, 0.0, 0.0))),
                Pause(REST),
                req("here"),
                Pause(STILL),
                req("here"),
            ],
        ),
        (
            "an incremental turn, rest, here twice",
            [
                req("incremental-move", delta((0.0, 0.0, 0.0, *OAT_TURN))),
                Pause(REST),
                req("here"),
                Pause(STILL),
                req("here"),
            ],
        ),
    ]
    return Stream(
        None, scenario_inputs("increments", groups), scenario="increments", check=_check_increments(0, 1, 2)
    )


def _check_joint_order(before: int, after: int) -> Callable[[Events], list[Sighting]]:
    """Element 1 of a joint vector is the waist: set joint angles with element 1 alone changed by
    :data:`SWING_DEG` turns the hand about the base's z axis by as much, at the same height and distance
    from the axis (``joint-angles.reply``)."""

    def check(events: Events) -> list[Sighting]:
        first, last = read_here(events, before), read_here(events, after)
        if first is None or last is None:
            return []
        p0, p1 = first[1][9:], last[1][9:]
        turned = wrap180(math.degrees(math.atan2(p1[1], p1[0]) - math.atan2(p0[1], p0[0])))
        if (
            abs(p1[2] - p0[2]) <= HAND_TOL_MM
            and abs(math.hypot(p1[0], p1[1]) - math.hypot(p0[0], p0[1])) <= HAND_TOL_MM
            and abs(turned - SWING_DEG) <= TURN_TOL_DEG
        ):
            return []
        message = (
            f"element 1 turned by {SWING_DEG:g} deg moved the hand {shown_angles(p0)} -> {shown_angles(p1)}"
        )
        expected = f"the hand turned {SWING_DEG:g} deg about the base's z axis (element 1 the waist)"
        # Judged where the first Here is: the hand at the angles set already differs for it.
        return [sighting(before, "joint-angles.reply", message, expected, first[0])]

    return check


def _joint_order() -> Stream:
    swung = (READY_POSE[0] + SWING_DEG, *READY_POSE[1:])
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "enable power, set joint angles to ready, rest, here",
            [req("enable-power"), req("set-joint-angles", floats_data(READY_POSE)), Pause(REST), req("here")],
        ),
        (
            "element 1 alone turned, rest, here",
            [req("set-joint-angles", floats_data(swung)), Pause(REST), req("here")],
        ),
    ]
    return Stream(
        None, scenario_inputs("joint-order", groups), scenario="joint-order", check=_check_joint_order(0, 1)
    )


SCENARIOS: Final[dict[str, Callable[[], Stream]]] = {
    "float-extremes": _extremes,
    "configuration": _configuration,
    "increments": _increments,
    "joint-order": _joint_order,
}
"""This module's scenarios by name, in the order a diff sends them."""
