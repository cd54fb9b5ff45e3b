"""Driving a diff: each stream to both sides, its differences paired, checked for stability,
classified, and each gap shrunk.

1. Stream ``k`` goes to side A, then to side B (:func:`~.sides.observe`), each from the same start (a
   scenario that waits out the broken-connection timer is made for the sides' timers, and is not sent
   while one is unknown).
2. The two sides' events are paired (:func:`~.pairing.compare`).  No difference: the stream is done.
3. A stream that differs is sent to both sides again: if its differences are not the same the second
   time, the stream is *unstable* (reported as such, never as a finding).
4. Its differences are classified (:func:`~.classify.classify`).  A gap (class c) is shrunk
   (:func:`~manip.conformance.fuzz.shrink.ddmin` over the stream's inputs, the preamble always sent):
   the fewest inputs that still show a gap in the same parts, every trial both sides again.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Coroutine, Sequence
from dataclasses import dataclass, field, replace
from typing import Final

from manip.conformance.diff.classify import Finding, classify
from manip.conformance.diff.pairing import Difference, compare
from manip.conformance.diff.sides import Observation, Side, observe
from manip.conformance.diff.streams import PREAMBLE_NUMBER, Stream
from manip.conformance.fuzz.session import Allowance
from manip.conformance.fuzz.shrink import Budget, ddmin

__all__ = ["DiffConfig", "StreamResult", "diff_stream", "run_diff"]

SHRINK_TRIALS: Final = 24
SHRINK_SECONDS: Final = 60.0


@dataclass(frozen=True)
class DiffConfig:
    seed: int
    allowance: Allowance = field(default_factory=Allowance)
    shrink: bool = True
    shrink_trials: int = SHRINK_TRIALS
    shrink_seconds: float = SHRINK_SECONDS
    seen_a: dict[tuple[str, tuple[int, ...]], Observation] | None = field(default=None, compare=False)
    """Side A's observations by stream (label, inputs), kept for the next diff whose side A is the same
    (a caller diffing many sides B against one side A observes each stream on it once); None: none kept."""


@dataclass
class StreamResult:
    """What one stream showed: its findings (none if it did not differ), whether it was unstable."""

    stream: Stream
    findings: list[Finding] = field(default_factory=list)
    unstable: bool = False
    unstable_detail: str = ""
    runaway: list[str] = field(default_factory=list)
    seconds: float = 0.0
    unarranged: str = ""
    """Why the stream (a scenario) was not compared: a condition of the arm's world it needs could not
    be arranged on a side.  Not a finding: nothing was compared."""
    unjudged: list[str] = field(default_factory=list)
    """What the scenario's check could not judge, side by side, and why.  Not a finding."""


def _once(
    a: Side, b: Side, stream: Stream, config: DiffConfig
) -> tuple[Observation, Observation, list[Difference]]:
    oa = _observe_a(a, stream, config)
    ob = observe(b, stream, config.allowance, config.seed)
    numbers = (PREAMBLE_NUMBER, *stream.input_numbers)
    return oa, ob, compare(numbers, oa.events, ob.events)


def _observe_a(a: Side, stream: Stream, config: DiffConfig) -> Observation:
    seen = config.seen_a
    key = (stream.label, stream.input_numbers)
    if seen is None:
        return observe(a, stream, config.allowance, config.seed)
    if key not in seen:
        seen[key] = observe(a, stream, config.allowance, config.seed)
    return seen[key]


def _findings(
    stream: Stream,
    oa: Observation,
    ob: Observation,
    diffs: Sequence[Difference],
    *,
    units_differ: bool = False,
) -> list[Finding]:
    inputs = {i.number: i for i in stream.all_inputs}
    return classify(stream.label, diffs, oa.sightings, ob.sightings, inputs, units_differ=units_differ)


def _timed(a: Side, b: Side, stream: Stream) -> Stream | str:
    """``stream``, made for the sides' broken-connection timer if it waits one out (the longer of the
    two); why it is not sent if a side's is unknown."""
    if stream.timed is None:
        return stream
    timers = [side.broken_after for side in (a, b) if side.broken_after is not None]
    if len(timers) < 2:
        unknown = [side.name for side in (a, b) if side.broken_after is None]
        whose = f"side {unknown[0]}" if len(unknown) == 1 else "sides A and B"
        return (
            f"it waits out the sides' broken-connection timer, not known for {whose}: "
            "give it with --broken-after SECONDS"
        )
    return stream.timed(max(timers))


def diff_stream(a: Side, b: Side, stream: Stream, config: DiffConfig) -> StreamResult:
    """One stream through steps 1 to 4 of the module docstring."""
    started = time.monotonic()
    result = StreamResult(stream)
    timed = _timed(a, b, stream)
    if isinstance(timed, str):
        result.unarranged = timed
        return result
    stream = result.stream = timed
    oa, ob, diffs = _once(a, b, stream, config)
    result.runaway = [f"{s.name}: {o.runaway}" for s, o in ((a, oa), (b, ob)) if o.runaway]
    unarranged = [f"side {s.name}: {o.unarranged}" for s, o in ((a, oa), (b, ob)) if o.unarranged]
    result.unjudged = [f"side {s.name}: {note}" for s, o in ((a, oa), (b, ob)) for note in o.unjudged]
    if unarranged:
        result.unarranged = "; ".join(unarranged)
    elif diffs:
        _, _, again = _once(a, b, stream, config)
        if [d.signature for d in again] != [d.signature for d in diffs]:
            result.unstable = True
            first = {d.signature for d in diffs} ^ {d.signature for d in again}
            result.unstable_detail = (
                f"{len(diffs)} difference(s) the first time, {len(again)} the second; "
                f"{len(first)} came or went"
            )
        else:
            result.findings = _findings(stream, oa, ob, diffs, units_differ=a.length_unit != b.length_unit)
            if config.shrink and not stream.scenario:
                result.findings = _shrink_gaps(a, b, stream, result.findings, config)
    result.seconds = time.monotonic() - started
    return result


def _gap_parts(findings: Sequence[Finding]) -> set[tuple[str, ...]]:
    return {f.difference.parts for f in findings if f.cls == "unexplained"}


def _shrink_gaps(
    a: Side, b: Side, stream: Stream, findings: list[Finding], config: DiffConfig
) -> list[Finding]:
    """Each gap with the fewest inputs found that still show a gap in the same parts."""
    out: list[Finding] = []
    shrunk: dict[tuple[str, ...], tuple[int, ...]] = {}
    for finding in findings:
        parts = finding.difference.parts
        if finding.cls == "unexplained" and parts not in shrunk:
            shrunk[parts] = _shrink(a, b, stream, parts, config)
        out.append(replace(finding, shrunk=shrunk[parts]) if finding.cls == "unexplained" else finding)
    return out


def _shrink(a: Side, b: Side, stream: Stream, parts: tuple[str, ...], config: DiffConfig) -> tuple[int, ...]:
    async def still(candidate: list[int]) -> bool:
        sub = stream.only(candidate)
        oa, ob, diffs = _once(a, b, sub, config)
        found = _findings(sub, oa, ob, diffs, units_differ=a.length_unit != b.length_unit)
        return parts in _gap_parts(found)

    budget = Budget(config.shrink_trials, config.shrink_seconds)

    async def main() -> list[int]:
        return (await ddmin(list(stream.input_numbers), still, budget))[0]

    return tuple(_complete(main()))


def _complete(coro: Coroutine[None, None, list[int]]) -> list[int]:
    """Run a coroutine that never suspends (every trial of the shrinking runs its own event loop, so
    the shrinking itself must not run on one)."""
    try:
        coro.send(None)
    except StopIteration as stop:
        return list(stop.value)
    coro.close()
    raise RuntimeError("the shrinking suspended")


def run_diff(
    a: Side,
    b: Side,
    streams: Sequence[Stream],
    config: DiffConfig,
    done: Callable[[StreamResult], None] = lambda result: None,
) -> list[StreamResult]:
    """Every stream in order; ``done`` after each."""
    out = []
    for stream in streams:
        result = diff_stream(a, b, stream, config)
        done(result)
        out.append(result)
    return out
