"""The kinematics scenario's judges on one side's own answers: a guide-only server (lengths in inches)
is judged and named by none of them, and each names the answer it judges once that answer is bent the
way a fault bends it (row by row, moved, an underflow not flushed)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import pytest

from manip.codecs.pdp11float import pack_f
from manip.conformance.diff.scenarios import scenario
from manip.conformance.diff.scenarios.kit import Events, angles_of, opcode_of
from manip.conformance.diff.sides import Side, observe
from manip.conformance.fuzz.session import Allowance
from manip.reference_server import ServerConfig

pytestmark = pytest.mark.timeout(120)

_SEEN: dict[str, Events] = {}


def _guide_events() -> Events:
    """The guide profile's events of the kinematics scenario (observed once per worker)."""
    if "guide" not in _SEEN:
        side = Side("B", "guide", config=ServerConfig.guide_profile())
        seen = observe(side, scenario("kinematics"), Allowance(), 7)
        assert not seen.sightings, [s.violation.message for s in seen.sightings]
        _SEEN["guide"] = seen.events
    return _SEEN["guide"]


def _floats(values: object) -> bytes:
    assert isinstance(values, (list, tuple))
    return b"".join(pack_f(v) for v in values)


def _bent(events: Events, name: str, bend: Callable[[list[float]], list[float]], which: int = -1) -> Events:
    """``events`` with the ``which``-th answer of ``name`` (a response of floats) bent by ``bend``."""
    out = {n: list(seen) for n, seen in events.items()}
    places = [
        (n, i)
        for n, seen in out.items()
        for i, e in enumerate(seen)
        if e.kind == "packet" and e.request == opcode_of(name) and angles_of(e) is not None
    ]
    n, i = places[which]
    event = out[n][i]
    values = angles_of(event)
    assert values is not None
    out[n][i] = dataclasses.replace(event, data=event.data[:2] + _floats(bend(values)))
    return out


def _named(events: Events) -> set[str]:
    check = scenario("kinematics").check
    assert check is not None
    return {s.violation.clause or "" for s in check(events)}


@pytest.mark.slow
def test_a_guide_only_server_in_inches_is_judged_and_named_by_none() -> None:
    events = _guide_events()
    assert _named(events) == set()
    # the inch variant of solve forwards is the one judged: its answer in radians is named
    assert _named(_bent(events, "solve-forwards", lambda q: [math.radians(a) for a in q])) == {
        "solve-forwards.data"
    }


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "bend", "which", "clause"),
    [
        ("here", lambda t: [t[c * 3 + r] for r in range(3) for c in range(4)], -1, "here.transform"),
        ("solve-backwards", lambda t: [*t[:9], t[9] + 5.0, *t[10:]], 0, "solve-backwards.data"),
        ("solve-backwards", lambda t: [t[0], 2.0**-128, *t[2:]], -1, "float.range"),
    ],
    ids=["row-major", "backwards", "underflow"],
)
def test_each_judge_names_the_answer_it_judges(
    name: str, bend: Callable[[list[float]], list[float]], which: int, clause: str
) -> None:
    assert _named(_bent(_guide_events(), name, bend, which)) == {clause}


@pytest.mark.slow
def test_a_dirty_zero_is_named_as_such() -> None:
    events = _bent(_guide_events(), "solve-backwards", lambda t: t)
    number = max(events)
    out = {n: list(seen) for n, seen in events.items()}
    event = out[number][-1]
    out[number][-1] = dataclasses.replace(event, data=event.data[:6] + b"\x0f\x00\x36\x34" + event.data[10:])
    assert _named(out) == {"float.dirty-zero"}
