"""The force-push scenario: its world condition holds for its middle input only (a phase), on an
embedded side; a side with no world is not sent it; and its judges name a reading that stays, a
reading in pounds and a guard-hit report whose words are swapped."""

from __future__ import annotations

import dataclasses
import struct

import pytest

from manip.codecs.pdp11float import pack_f
from manip.conformance.diff.scenarios import scenario
from manip.conformance.diff.scenarios.forces import GUARD, reading_at
from manip.conformance.diff.scenarios.kit import Events, opcode_of
from manip.conformance.diff.sides import Side, observe
from manip.conformance.fuzz.session import Allowance
from manip.links import parse_address
from manip.reference_server import ServerConfig
from manip.spec.constants import ServerOp

pytestmark = pytest.mark.timeout(120)

_SEEN: dict[str, Events] = {}


def _clean_events() -> Events:
    if "clean" not in _SEEN:
        seen = observe(Side("B", "clean", config=ServerConfig()), scenario("force-push"), Allowance(), 7)
        assert seen.unarranged is None and not seen.sightings, [s.violation.message for s in seen.sightings]
        _SEEN["clean"] = seen.events
    return _SEEN["clean"]


def _named(events: Events) -> set[str]:
    check = scenario("force-push").check
    assert check is not None
    return {s.violation.clause or "" for s in check(events)}


def _forces_bent(events: Events, bend: dict[int, tuple[float, ...] | float]) -> Events:
    """``events`` with the read forces answers of each input of ``bend`` replaced by that reading
    (a tuple), or scaled by that factor (a float)."""
    out = {n: list(seen) for n, seen in events.items()}
    for number, how in bend.items():
        for i, event in enumerate(out[number]):
            if event.request != opcode_of("read-forces") or event.opcode != ServerOp.RESPONSE:
                continue
            reading = reading_at({number: [event, event]}, number)
            assert reading is not None
            values = how if isinstance(how, tuple) else tuple(v * how for v in reading[1])
            data = event.data[:2] + b"".join(pack_f(v) for v in values)
            out[number][i] = dataclasses.replace(event, data=data)
    return out


@pytest.mark.slow
def test_the_push_holds_for_its_phase_only() -> None:
    events = _clean_events()
    rest, pushed, free = (reading_at(events, n) for n in (0, 1, 2))
    assert rest is not None and pushed is not None and free is not None
    assert abs(rest[1][2]) < 2.0 and abs(free[1][2]) < 2.0
    assert abs(pushed[1][2] - 48.0) < 2.0 and abs(pushed[1][5] - 96.0) < 2.0
    assert _named(events) == set()


@pytest.mark.slow
def test_a_stale_reading_and_pounds_are_named() -> None:
    events = _clean_events()
    rest = reading_at(events, 0)
    assert rest is not None
    assert "read-forces.current" in _named(_forces_bent(events, {1: rest[1], 2: rest[1]}))
    assert _named(_forces_bent(events, {0: 1 / 16, 1: 1 / 16, 2: 1 / 16})) == {"read-forces.units"}


@pytest.mark.slow
def test_a_guard_hit_with_its_words_swapped_is_named() -> None:
    events = _clean_events()
    out = {n: list(seen) for n, seen in events.items()}
    (number, i, event), *_ = [
        (n, i, e)
        for n, seen in out.items()
        for i, e in enumerate(seen)
        if e.opcode == ServerOp.ASYNCHRONOUS_RESPONSE
    ]
    assert event.data[-4:] == struct.pack("<HH", 1, GUARD)
    out[number][i] = dataclasses.replace(event, data=event.data[:-4] + struct.pack("<HH", 2, GUARD))
    assert _named(out) == {"async.layout"}


def test_a_side_with_no_world_is_not_sent_it() -> None:
    side = Side("B", "addressed", address=parse_address("tcp://127.0.0.1:1"))
    seen = observe(side, scenario("force-push"), Allowance(), 7)
    assert seen.unarranged is not None and "--world-b" in seen.unarranged and not seen.events
