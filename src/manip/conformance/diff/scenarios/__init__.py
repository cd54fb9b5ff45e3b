"""The diff's scenarios: the directed cases' request sequences as streams, each with the judge that
knows what its answers must be.

The fuzzer's generated inputs seldom reach a condition a directed case arranges on purpose: a motion
read back after it ends, describe self followed by a probe of every opcode it lists, a fatal error.
A scenario is such a request sequence (:class:`~manip.conformance.diff.streams.Stream` with a
``scenario`` name), sent to both sides from the same start like every stream, and judged by the
fuzzer's judges plus its own :data:`~manip.conformance.diff.streams.ScenarioCheck`: a check that
knows what the requests it sent demand of the answers (the joint angles a set joint angles put the
arm at, the ready position describe self stated, the joints a calibration failure names).  A breach
its check finds is a :class:`~manip.conformance.fuzz.judge.Sighting` like any judge's, so a
difference on that input is a violation (class a) naming the clause.  A scenario about what a
connection leaves behind closes its connection and goes on on the next
(:class:`~manip.conformance.fuzz.steps.Reconnect`); one about how the arm moves reads the joints or the
hand midway through a move, a fixed time after it was answered (the same time on both sides, in virtual
time on an embedded one).

Some scenarios need a condition of the arm's world (``conditions``: the world contract's
:class:`~manip.conformance.suite.world.Condition`, as the directed cases arrange them): an embedded
side's world arranges them at once; an addressed side's through its ``--world-a/-b`` (contract 2).  A
side whose world cannot arrange one, or that has none, is not sent the scenario (the report says
so).  One waits out the server's broken-connection timer, each server's own choice (erratum
``ncp-timers``): it is sent only when the diff is told the sides' timers (``--broken-after``), and
the report says otherwise that it was not.  Sans-I/O.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Final

from manip.conformance.diff.scenarios import (
    asyncs,
    chaos,
    forces,
    kinematics,
    motion,
    requests,
    silence,
    state,
    timing,
    values,
)
from manip.conformance.diff.scenarios.kit import ANGLE_TOLERANCE
from manip.conformance.diff.streams import Stream

__all__ = ["ANGLE_TOLERANCE", "SCENARIOS", "scenario", "scenarios"]


SCENARIOS: Final[dict[str, Callable[[], Stream]]] = {
    **state.SCENARIOS,
    **asyncs.SCENARIOS,
    **values.SCENARIOS,
    **motion.SCENARIOS,
    **requests.SCENARIOS,
    **timing.SCENARIOS,
    **kinematics.SCENARIOS,
    **forces.SCENARIOS,
    **chaos.SCENARIOS,
    **silence.SCENARIOS,
}
"""Every scenario by name, in the order a diff sends them."""


def scenario(name: str) -> Stream:
    """The scenario ``name`` (KeyError for an unknown one)."""
    return SCENARIOS[name]()


def scenarios(*, world: bool = True) -> list[Stream]:
    """Every scenario; without ``world``, only those that need no condition of the arm's world."""
    out = [make() for make in SCENARIOS.values()]
    return [s for s in out if world or not s.needs]
