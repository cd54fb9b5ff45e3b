"""The request streams of a diff: the fuzzer's generated inputs, cut into streams, from one seed.

Stream ``k`` of seed ``S`` with ``length`` inputs is the fuzzer's inputs ``k*length`` to
``k*length + length - 1`` of campaign ``S`` (:func:`manip.conformance.fuzz.generators.generate`), after
a fixed preamble that sets the state both sides start from on their fresh connection (arm power off,
speed 1.0).
The same seed gives the same streams; ``manip-conform diff ... --seed S --stream K`` sends stream ``K``
again, ``--inputs N,M`` a stream of exactly those inputs (a shrunk one).  Sans-I/O.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Final

from manip.codecs.pdp11float import pack_f
from manip.conformance.fuzz.generators import GenOptions, generate
from manip.conformance.fuzz.steps import FuzzInput, RequestStep
from manip.spec import SPEC

if TYPE_CHECKING:
    from manip.conformance.diff.pairing import SideEvent
    from manip.conformance.fuzz.judge import Sighting
    from manip.conformance.suite.world import Condition

__all__ = [
    "PREAMBLE_NUMBER",
    "ScenarioCheck",
    "ScenarioJudge",
    "Stream",
    "WorldPhase",
    "make_stream",
    "make_streams",
    "preamble",
    "stream_of",
]

PREAMBLE_NUMBER: Final = -1
"""The input number of the preamble (the fuzzer numbers its inputs from 0)."""


def preamble() -> FuzzInput:
    """The requests that put both sides in the same state on a fresh connection: arm power off, speed
    1.0 (a fresh connection has no configuration on every conforming server).  The arm's pose is not
    set (that would move it): an embedded side is a fresh server for every stream, at its rest pose."""
    power = RequestStep(SPEC.request("kill-power").opcode, b"")
    speed = RequestStep(SPEC.request("set-speed").opcode, pack_f(1.0))
    return FuzzInput(
        PREAMBLE_NUMBER, "diff.preamble", (power, speed), "the preamble: kill power, set speed 1.0"
    )


ScenarioCheck = Callable[["dict[int, list[SideEvent]]"], "list[Sighting]"]
"""A scenario's own judge: a side's events of the stream in, the clauses they break out
(:mod:`manip.conformance.diff.scenarios`)."""
ScenarioJudge = Callable[["dict[int, list[SideEvent]]"], "tuple[list[Sighting], list[str]]"]
"""A scenario's own judge that may leave clauses unjudged: a side's events in, the clauses they break out,
with what it could not judge on that side, and why (a timing clause whose breach an addressed side's
round trips or host delays could hide or explain), one text per clause."""


@dataclass(frozen=True)
class WorldPhase:
    """A condition of the arm's world that holds for some inputs of a stream only: arranged before the
    first of ``inputs`` is sent, once every request sent before it is answered, and cleared so before
    the next input not among them (a change the answers before and after it show: a force put on the
    hand and taken off again)."""

    condition: Condition
    inputs: tuple[int, ...]


@dataclass(frozen=True)
class Stream:
    """Stream ``number`` (None: one made of chosen inputs, or a scenario): the preamble, then ``inputs``.

    A scenario (:mod:`manip.conformance.diff.scenarios`) has its ``scenario`` name, the environment
    conditions of the arm's world each side's world arranges for it (``conditions``, for the whole
    stream; ``phases``, for some of its inputs) and its own ``check`` of each side's answers, or its own
    ``judge`` of them that also says what it could not judge on a side; one that waits out the sides'
    broken-connection timer is made for the timer (``timed``)."""

    number: int | None
    inputs: tuple[FuzzInput, ...]
    scenario: str = ""
    conditions: tuple[Condition, ...] = ()
    check: ScenarioCheck | None = None
    judge: ScenarioJudge | None = None
    phases: tuple[WorldPhase, ...] = ()
    timed: Callable[[float], Stream] | None = field(default=None, compare=False)
    """A scenario that waits out the sides' broken-connection timer (erratum ncp-timers): the stream it
    is for a timer of so many seconds.  The diff sends ``timed(timer)`` only when told both sides'
    timers (``--broken-after``), and says otherwise that it was not sent."""

    @property
    def needs(self) -> tuple[Condition, ...]:
        """Every condition of the arm's world the stream needs arranged, for all of it or a phase."""
        return (*self.conditions, *(p.condition for p in self.phases))

    @property
    def all_inputs(self) -> list[FuzzInput]:
        return [preamble(), *self.inputs]

    @property
    def input_numbers(self) -> tuple[int, ...]:
        return tuple(i.number for i in self.inputs)

    def only(self, numbers: Sequence[int]) -> Stream:
        """The same stream with only the inputs numbered ``numbers`` (shrinking)."""
        keep = set(numbers)
        return replace(self, inputs=tuple(i for i in self.inputs if i.number in keep))

    @property
    def label(self) -> str:
        if self.scenario:
            return f"scenario {self.scenario}"
        if self.number is not None:
            return f"stream {self.number}"
        return "inputs " + ",".join(str(n) for n in self.input_numbers)


def make_stream(seed: int, number: int, length: int, gen: GenOptions) -> Stream:
    first = number * length
    return Stream(number, tuple(generate(seed, n, gen) for n in range(first, first + length)))


def make_streams(seed: int, count: int, length: int, gen: GenOptions) -> list[Stream]:
    """Streams 0 to ``count - 1``."""
    return [make_stream(seed, k, length, gen) for k in range(count)]


def stream_of(seed: int, numbers: Sequence[int], gen: GenOptions) -> Stream:
    """A stream of exactly the inputs ``numbers`` of campaign ``seed`` (``--inputs``)."""
    return Stream(None, tuple(generate(seed, n, gen) for n in numbers))
