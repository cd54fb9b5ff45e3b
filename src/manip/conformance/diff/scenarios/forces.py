"""The diff's scenarios of the wrist's forces: read forces before, while and after the world pushes the
hand, and a guard that trips on the push.

The push is the world contract's ``wrist-force`` condition, held for the middle input only (a
:class:`~manip.conformance.diff.streams.WorldPhase`), as the directed case server.wrist.force-push
arranges it for part of its connection; its judges are that case's (what the reading must change by, in
ounces and ounce-inches, and that each reading is the current one).  Each reading is judged once the
wrist's filter has followed the change: two readings a quarter second apart that agree.  A
stop-the-move guard armed across the push trips; its guard-hit report says so (1 = stop) and names the
guard (the 1985 guide, E.3 Opcode 203).  The wrist opcodes are manip's Puma extensions: a side that
refuses them (a server written from the 1985 guide alone) answers nothing a check judges.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Final

from manip.codecs.messages import encode_request
from manip.conformance.cases.server.guards import GUARD_BIT, HIT_WAIT, STOP_BIT
from manip.conformance.cases.server.wrist import (
    PUSH_CONDITION,
    PUSH_OZ,
    PUSH_WRENCH,
    STEADY_TOL,
    let_go,
    push_shown,
    push_sized,
)
from manip.conformance.diff.pairing import SideEvent
from manip.conformance.diff.scenarios.kit import (
    Events,
    all_of,
    async_in,
    floats_at,
    req,
    scenario_inputs,
    shown_angles,
    sighting,
)
from manip.conformance.diff.streams import Stream, WorldPhase
from manip.conformance.fuzz.judge import Sighting
from manip.conformance.fuzz.steps import Pause, RequestStep, Step
from manip.spec.constants import AsyncCondition, RequestName

FILTER_S: Final = 1.0
"""Seconds after a change that the wrist's reading is read (its filter follows within a few ticks)."""
APART_S: Final = 0.25
"""Seconds between the two readings that show it steady."""
GUARD: Final = 5
"""The index of the stop-the-move guard armed across the push."""
GUARD_STOPPED: Final = 1
"""Word 2 of a guard-hit report of a guard that stopped the move."""


def _ask(name: RequestName, **values: object) -> RequestStep:
    return req(name, encode_request(name, **values))


def _steady_reading() -> list[Step]:
    return [Pause(FILTER_S), req("read-forces"), Pause(APART_S), req("read-forces")]


def reading_at(events: Events, number: int) -> tuple[SideEvent, tuple[float, ...]] | None:
    """The wrist's steady reading at input ``number``: its last two read forces answers, six floats each,
    within :data:`STEADY_TOL` of each other (None: refused, or not yet steady)."""
    reads = [r for r in floats_at(events, number, "read-forces") if len(r[1]) == 6]
    if (
        len(reads) < 2
        or max(abs(a - b) for a, b in zip(reads[-2][1], reads[-1][1], strict=True)) >= STEADY_TOL
    ):
        return None
    return reads[-1][0], tuple(reads[-1][1])


_WHEN: Final = ("at rest", "pushed", "let go")


def _check_push(rest_at: int, push_at: int, free_at: int) -> Callable[[Events], list[Sighting]]:
    """The readings at rest (input ``rest_at``), while the world pushes the hand (``push_at``) and once
    it let go (``free_at``): the one while pushed differs from the others and back at rest after
    (``read-forces.current``), and it changed by the push, in ounces and ounce-inches
    (``read-forces.units``) (the directed case server.wrist.force-push's judges)."""

    def check(events: Events) -> list[Sighting]:
        rest, pushed, free = (reading_at(events, n) for n in (rest_at, push_at, free_at))
        if rest is None or pushed is None or free is None:
            return []
        out: list[Sighting] = []
        shown = ", ".join(
            f"{w} {shown_angles(r[1])}" for w, r in zip(_WHEN, (rest, pushed, free), strict=True)
        )
        if not push_shown(rest[1], pushed[1], free[1]):
            expected = "the reading while the world pushed the hand differing from those before and after"
            out.append(
                sighting(push_at, "read-forces.current", f"read forces answered {shown}", expected, pushed[0])
            )
        change = tuple(b - a for a, b in zip(rest[1], pushed[1], strict=True))
        if not push_sized(change):
            message = f"the reading changed by {shown_angles(change)} when the world pushed the hand"
            expected = f"a change of {shown_angles(PUSH_WRENCH)}: the push in ounces and ounce-inches"
            out.append(sighting(push_at, "read-forces.units", message, expected, pushed[0]))
        if not let_go(rest[1], free[1]):
            expected = f"the reading back at rest, {shown_angles(rest[1])}, once the world let go"
            out.append(
                sighting(free_at, "read-forces.current", f"read forces answered {shown}", expected, free[0])
            )
        return out

    return check


def _check_guard(events: Events) -> list[Sighting]:
    """A guard-hit report of the stop-the-move guard :data:`GUARD` says it stopped the move: word 2 = 1,
    word 3 = the guard (``async.layout``)."""
    for number, seen in events.items():
        for event in seen:
            message = async_in(event)
            if message is None or message.condition != AsyncCondition.GUARD_HIT or message.word3 != GUARD:
                continue
            if message.word2 != GUARD_STOPPED:
                said = f"the guard-hit report of stop-the-move guard {GUARD} has word 2 = {message.word2}"
                expected = f"word 2 = {GUARD_STOPPED} (trajectory stopped), word 3 = {GUARD}"
                return [sighting(number, "async.layout", said, expected, event)]
    return []


def _push() -> Stream:
    across = [0.0, 0.0, 1.0, 0.0, 0.0, 0.0]  # along the push, the hand's z axis
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "no gauge offsets, frame vector or weight, guard hits asked for, read forces at rest",
            [
                req("wrist-version"),
                _ask("set-gauge-offsets", offsets=[0] * 8),
                _ask("set-frame-vector", offset=[0.0] * 3),
                _ask("set-weight", weight=0.0, cg=[0.0] * 3),
                _ask("request-notifications", mask=GUARD_BIT),
                *_steady_reading(),
            ],
        ),
        (
            "the world pushes the hand: read forces, then a stop-the-move guard across the push",
            [
                *_steady_reading(),
                _ask("set-guard", type_index=STOP_BIT | GUARD, dvec=across, tol=PUSH_OZ / 2),
                Pause(HIT_WAIT),
            ],
        ),
        ("the world lets go: read forces", _steady_reading()),
    ]
    return Stream(
        None,
        scenario_inputs("force-push", groups),
        scenario="force-push",
        check=all_of(_check_push(0, 1, 2), _check_guard),
        phases=(WorldPhase(PUSH_CONDITION, (1,)),),
    )


SCENARIOS: Final[dict[str, Callable[[], Stream]]] = {
    "force-push": _push,
}
"""This module's scenarios by name, in the order a diff sends them."""
