"""The diff's scenarios of how the arm moves: a fresh connection, closing while moving, speed scaling,
unsplit replies, paths."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Final

from manip.arm.kinematics import PUMA600, forward
from manip.arm.oat import rotation_from_oat, xyzoat_from_transform
from manip.codecs.pdp11float import pack_f
from manip.conformance.cases.server.motion import SPEED_MATCH
from manip.conformance.cases.server.trajectory import (
    FRACTION_TOL,
    LINE_TOL_MM,
    MOVING_DEG,
    TURN_WAY_TOL_DEG,
    along_line,
    turn_at,
)
from manip.conformance.diff.pairing import SideEvent
from manip.conformance.diff.scenarios.kit import (
    MIDWAY,
    POSE,
    READY_POSE,
    REST,
    SEED_ANGLES,
    SLOW,
    SWING_DEG,
    Events,
    answer_at,
    close_to,
    error_in,
    floats_at,
    floats_data,
    is_op,
    midway_at,
    opcode_of,
    req,
    scenario_inputs,
    scenario_stream,
    segment_at,
    shown_angles,
    sighting,
    solution_at,
    solve_seed,
    timed_move,
    word,
)
from manip.conformance.diff.streams import Stream
from manip.conformance.fuzz.judge import Sighting
from manip.conformance.fuzz.steps import Pause, Reconnect, Step
from manip.spec.constants import ServerOp


def _check_fresh(
    first: int, queued: int, solved: int, moved: int, timed: int
) -> Callable[[Events], list[Sighting]]:
    """The second connection (from input ``solved``) finds none of what the first set
    (``connect.per-connection-state``): solve forwards gives the solution the first gave before set
    configuration (input ``first``), its first move is never refused AWA (input ``moved``) and has the
    segment number the first connection's first move had (input ``queued``), no asynchronous response
    comes unasked, and a move gets as far midway as one at an explicit factor 1 (input ``timed``)."""

    def check(events: Events) -> list[Sighting]:
        out: list[Sighting] = []
        fresh, again = solution_at(events, first), solution_at(events, solved)
        if fresh is not None and again is not None and not close_to(fresh[1], again[1]):
            anew, first_text = shown_angles(again[1]), shown_angles(fresh[1])
            message = f"solve forwards gave {anew} anew, {first_text} on the first connection"
            out.append(sighting(solved, _FRESH, message, "the fresh connection's solution", again[0]))
        out += _first_move(events, queued, moved, timed)
        out += _unasked(events, moved, timed)
        out += _fresh_speed(events, timed)
        return out

    return check


_FRESH: Final = "connect.per-connection-state"


def _first_move(events: Events, queued: int, moved: int, timed: int) -> list[Sighting]:
    out: list[Sighting] = []
    answer = answer_at(events, moved, "set-joint-angles")
    error = error_in(answer, ServerOp.NON_FATAL_ERROR)
    if answer is not None and error is not None and error.code == "AWA":
        message = "the new connection's first move was refused AWA: the last connection's abort"
        out.append(sighting(moved, _FRESH, message, "done, or NAP without power", answer))
    at = moved if segment_at(events, moved) is not None else timed  # NAP: the first move is later
    old, new = segment_at(events, queued), segment_at(events, at)
    if old is not None and new is not None and new[1] != old[1]:
        message = f"the new connection's first segment is {new[1]}, the first connection's was {old[1]}"
        out.append(sighting(at, _FRESH, message, "the segment counter afresh", new[0]))
    return out


def _unasked(events: Events, moved: int, timed: int) -> list[Sighting]:
    for number in range(moved, timed + 1):
        for event in events.get(number, []):
            if is_op(event, ServerOp.ASYNCHRONOUS_RESPONSE):
                message = "an asynchronous response on a connection that asked for none"
                expected = "none: the last connection's notifications are not in force"
                return [sighting(number, _FRESH, message, expected, event)]
    return []


def _fresh_speed(events: Events, timed: int) -> list[Sighting]:
    """A swing at the fresh connection's speed gets as far midway as the one back at factor 1."""
    got = midway_at(events, timed)
    if got is None or got[0] * SPEED_MATCH >= got[1]:
        return []
    default, explicit, event = got
    message = f"midway a move got {default:.0%} of its way at the fresh speed, {explicit:.0%} at factor 1"
    return [sighting(timed, _FRESH, message, "the fresh connection moving at factor 1", event)]


def _fresh_connection() -> Stream:
    swung = (READY_POSE[0] + SWING_DEG, *READY_POSE[1:])
    groups: list[tuple[str, Sequence[Step]]] = [
        ("solve forwards (no configuration set)", [solve_seed()]),
        (
            "enable power, a move to ready, set configuration 0, a slow speed, notifications 3",
            [
                req("enable-power"),
                req("set-joint-angles", floats_data(READY_POSE)),
                req("set-configuration", word(0)),
                req("set-speed", pack_f(SLOW)),
                req("request-notifications", word(3)),
            ],
        ),
        (
            "a move cut short by kill power (an abort stands), a new connection",
            [req("set-joint-angles", floats_data(swung)), req("kill-power"), Pause(1.0), Reconnect()],
        ),
        ("solve forwards", [solve_seed()]),
        ("set joint angles to ready", [req("set-joint-angles", floats_data(READY_POSE))]),
        (
            "to ready, a timed swing, one back at factor 1",
            _timed_pair([]),
        ),
    ]
    check = _check_fresh(0, 1, 3, 4, 5)
    return scenario_stream("fresh-connection", groups, check)


def _check_still(at: int) -> Callable[[Events], list[Sighting]]:
    """Joint angles read twice, seconds apart, on the connection after one closed under a move: the
    same (``connect.close-stops-arm``)."""

    def check(events: Events) -> list[Sighting]:
        reads = floats_at(events, at, "joint-angles")
        if len(reads) != 2 or close_to(reads[0][1], reads[1][1]):
            return []
        before, after = shown_angles(reads[0][1]), shown_angles(reads[1][1])
        message = f"the arm moved from {before} to {after} after the connection closed"
        return [sighting(at, "connect.close-stops-arm", message, "the arm standing still", reads[1][0])]

    return check


def _close_moving() -> Stream:
    far = (READY_POSE[0] + 90.0, *READY_POSE[1:])
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "enable power, to ready, rest, a long move, a new connection at once",
            [
                req("enable-power"),
                req("set-joint-angles", floats_data(READY_POSE)),
                Pause(REST),
                req("set-joint-angles", floats_data(far)),
                Reconnect(),
            ],
        ),
        ("joint angles twice, seconds apart", [req("joint-angles"), Pause(2.0), req("joint-angles")]),
    ]
    return Stream(
        None, scenario_inputs("close-moving", groups), scenario="close-moving", check=_check_still(1)
    )


def _check_speed_scales(timed: int) -> Callable[[Events], list[Sighting]]:
    """A swing at factor :data:`SLOW` gets at most 1 / :data:`SPEED_MATCH` as far midway as the one back at
    factor 1 (``motion.speed-scales``)."""

    def check(events: Events) -> list[Sighting]:
        got = midway_at(events, timed)
        if got is None or got[0] * SPEED_MATCH <= got[1]:
            return []
        slow, full, event = got
        message = f"midway a move got {slow:.0%} of its way at factor {SLOW:g}, {full:.0%} at factor 1"
        return [sighting(timed, "motion.speed-scales", message, f"the move {1 / SLOW:g} times slower", event)]

    return check


def _timed_pair(first: Sequence[Step]) -> list[Step]:
    """To ready, the joints read, ``first`` (a speed), a timed swing, the joints read, factor 1, a timed
    swing back."""
    swung = (READY_POSE[0] + SWING_DEG, *READY_POSE[1:])
    return [
        req("enable-power"),
        req("set-joint-angles", floats_data(READY_POSE)),
        Pause(REST),
        req("joint-angles"),
        *first,
        *timed_move(swung),
        req("joint-angles"),
        req("set-speed", pack_f(1.0)),
        *timed_move(READY_POSE),
    ]


def _speed_scales() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            f"a timed swing at factor {SLOW:g}, one back at factor 1",
            _timed_pair([req("set-speed", pack_f(SLOW))]),
        )
    ]
    return Stream(
        None, scenario_inputs("speed-scales", groups), scenario="speed-scales", check=_check_speed_scales(0)
    )


def _check_not_split(at: int) -> Callable[[Events], list[Sighting]]:
    """No other packet comes between the first packet of describe self's reply at input ``at`` and its
    terminator (``multi.not-split``)."""

    def check(events: Events) -> list[Sighting]:
        seen = events.get(at, [])
        mine = [
            i for i, e in enumerate(seen) if e.kind == "packet" and e.request == opcode_of("describe-self")
        ]
        if not mine:
            return []
        inside = [e for e in seen[mine[0] : mine[-1]] if e.kind == "packet" and e.request is None]
        if not inside:
            return []
        message = f"0{inside[0].opcode:o} came inside describe self's reply"
        return [
            sighting(at, "multi.not-split", message, "the reply whole, then the other packets", inside[0])
        ]

    return check


def _split() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "enable power, notifications 3, a move, rest",
            [
                req("enable-power"),
                req("request-notifications", word(3)),
                req("set-joint-angles", floats_data(POSE)),
                Pause(REST),
            ],
        ),
        ("describe self", [req("describe-self")]),
    ]
    return scenario_stream("not-split", groups, _check_not_split(1))


LINE_SHIFT: Final = (80.0, 40.0, -60.0)
"""How far (mm) the paths scenario's straight-line move takes the hand from the seed's pose."""
LINE_TURN: Final = (15.0, -12.0, 20.0)
"""dO dA dT (deg) by which the paths scenario's straight-line move turns the hand on the way."""
LINE_MIDWAY: Final = 0.55
"""Seconds from the straight-line move to the Here read midway: about half its way on the reference
server, whose 36-degree turn at 60 degrees a second takes about 1.1 s (a check judges the turn only where
that Here is within a quarter of the line of half its way)."""
JOINT_SHIFT: Final = (30.0, 20.0, -25.0, 15.0, 20.0, -30.0)
"""How far (deg) each joint goes in the paths scenario's joint-interpolated move to a transform."""


def _shifted(
    angles: Sequence[float], shift: Sequence[float], turn: Sequence[float] = (0.0, 0.0, 0.0)
) -> bytes:
    """The transform of ``angles`` with its position moved by ``shift`` (mm) and, given ``turn``, its
    rotation turned by that dO dA dT (deg) of VAL's angles."""
    pose = forward(angles, PUMA600.geometry)
    floats = list(pose.to_floats())
    floats[9:] = [p + d for p, d in zip(floats[9:], shift, strict=True)]
    if any(turn):
        _, _, _, o, a, t = xyzoat_from_transform(pose)
        floats[:9] = rotation_from_oat(o + turn[0], a + turn[1], t + turn[2]).T.ravel().tolist()
    return floats_data(floats)


def _off_line(p: Sequence[float], a: Sequence[float], b: Sequence[float]) -> tuple[float, float]:
    """The distance of ``p`` from the line through ``a`` and ``b``, and how far along it p lies (0 to 1)."""
    along = along_line(p, a, b)
    return math.dist(p, [x + along * (y - x) for x, y in zip(a, b, strict=True)]), along


def _turn_midway(line: int, heres: Sequence[tuple[SideEvent, list[float]]], along: float) -> list[Sighting]:
    """On its line (``along`` of the way), the hand is on its way from the orientation it started at to
    the one it ended at, and not done turning before half way nor yet to begin after it
    (``straight-move.orientation``)."""
    start, mid, end = (h[1] for h in heres)
    turn = turn_at(start, mid, end)
    if not 0.0 < along < 1.0 or turn.whole < 1.0:
        return []
    if turn.off_way <= TURN_WAY_TOL_DEG and not turn.off_pace(along):
        return []
    message = (
        f"{along:.0%} along the line the hand had turned {turn.turned:.3g} deg of a {turn.whole:.3g}-degree "
        f"turn, {turn.left:.3g} deg left ({turn.off_way:.3g} deg off the way)"
    )
    expected = "the hand on its way from the start's orientation to the end's, still turning half way"
    return [sighting(line, "straight-move.orientation", message, expected, heres[1][0])]


def _check_paths(line: int, joint: int) -> Callable[[Events], list[Sighting]]:
    """Midway through a straight-line move (input ``line``: Here before, midway, at the end) the hand is
    on the line from where it started to where it ended (``straight-move.line``) and on its turn from the
    orientation it started at to the one it ended at, still turning (``straight-move.orientation``);
    midway through a move (input ``joint``: joint angles before, midway, at the end) the joints that move
    are at one fraction of their ways (``joint-move.interpolated``)."""

    def check(events: Events) -> list[Sighting]:
        out: list[Sighting] = []
        heres = floats_at(events, line, "here")
        if len(heres) == 3 and all(len(h[1]) == 12 for h in heres):
            start, mid, end = (h[1][9:] for h in heres)
            off, along = _off_line(mid, start, end)
            if 0.0 < along < 1.0 and off > LINE_TOL_MM:
                ends = f"{shown_angles(start)} to {shown_angles(end)}"
                message = f"midway the hand is {off:.3g} mm off the line from {ends}"
                out.append(sighting(line, "straight-move.line", message, "the hand on the line", heres[1][0]))
            out += _turn_midway(line, heres, along)
        reads = floats_at(events, joint, "joint-angles")
        if len(reads) == 3:
            first, mid, last = (r[1] for r in reads)
            moving = [i for i, (a, b) in enumerate(zip(first, last, strict=True)) if abs(b - a) >= MOVING_DEG]
            fractions = [(mid[i] - first[i]) / (last[i] - first[i]) for i in moving]
            spread = max(fractions) - min(fractions) if fractions else 0.0
            if spread > FRACTION_TOL:
                message = f"midway the moving joints were {spread:.3f} apart in the fractions of their ways"
                expected = "every moving joint at one fraction of its way"
                out.append(sighting(joint, "joint-move.interpolated", message, expected, reads[1][0]))
        return out

    return check


def _paths() -> Stream:
    start = floats_data(SEED_ANGLES)
    goal = tuple(a + d for a, d in zip(SEED_ANGLES, JOINT_SHIFT, strict=True))
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "enable power, to the seed's angles, rest",
            [req("enable-power"), req("set-joint-angles", start), Pause(REST)],
        ),
        (
            "here, a straight-line move, here midway and at the end",
            [
                req("here"),
                req("straight-move", _shifted(SEED_ANGLES, LINE_SHIFT, LINE_TURN)),
                Pause(LINE_MIDWAY),
                req("here"),
                Pause(REST),
                req("here"),
            ],
        ),
        ("back to the seed's angles, rest", [req("set-joint-angles", start), Pause(REST)]),
        (
            "joint angles, a move to a transform, joint angles midway and at the end",
            [
                req("joint-angles"),
                req("move", _shifted(goal, (0.0, 0.0, 0.0))),
                Pause(MIDWAY),
                req("joint-angles"),
                Pause(REST),
                req("joint-angles"),
            ],
        ),
    ]
    return scenario_stream("paths", groups, _check_paths(1, 3))


SCENARIOS: Final[dict[str, Callable[[], Stream]]] = {
    "fresh-connection": _fresh_connection,
    "close-moving": _close_moving,
    "speed-scales": _speed_scales,
    "not-split": _split,
    "paths": _paths,
}
"""This module's scenarios by name, in the order a diff sends them."""
