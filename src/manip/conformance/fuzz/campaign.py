"""The campaign: inputs in batches, a liveness check after each, violations shrunk as they are found.

Theory of operation:

1. The target is started (or found) and must pass a liveness check: else the campaign ends at once,
   unreachable (exit 3).
2. Inputs are numbered from 0 and sent ``batch`` at a time (:mod:`.batch`) until ``inputs`` were
   sent or ``seconds`` passed; with ``only`` exactly those inputs are sent, as one batch.  After each
   batch: the liveness check, the target's new tracebacks, its count of bad frames, and the judgement
   (:mod:`.judge`).
3. Each violation a batch shows (a :class:`~.judge.Sighting`) is new, or one more occurrence of a
   violation already seen (same kind and clause).  A new violation is shrunk (:mod:`.shrink`): first the
   input it is attributed to alone, then delta debugging over its batch, every trial a batch of its own
   on a fresh connection (and, for a crash or hang, a restarted target).  The shrunk inputs are what
   the report shows, with the reproduce line ``manip-conform fuzz ... --seed S --only N,M``.
4. A target found dead is restarted when the fuzzer runs it; a remote one is waited for
   (``restart_wait``); one that does not come back ends the campaign (a problem of the report).
"""

from __future__ import annotations

import asyncio
import contextlib
import datetime
import shlex
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Final

from manip.conformance.fuzz.batch import BatchRun, BatchRunner, Liveness, liveness
from manip.conformance.fuzz.generators import GenOptions, generate
from manip.conformance.fuzz.judge import Sighting, judge
from manip.conformance.fuzz.report import (
    HEALTH,
    CampaignFacts,
    CampaignViolation,
    ClassTally,
    MinimalInput,
    class_results,
)
from manip.conformance.fuzz.session import Allowance
from manip.conformance.fuzz.shrink import Budget, BudgetError, ddmin
from manip.conformance.fuzz.steps import (
    ConnPacket,
    FuzzInput,
    Pause,
    Raw,
    Reconnect,
    RequestStep,
    Silence,
    Step,
    Stray,
)
from manip.conformance.fuzz.target import FuzzedServer, UnreachableError
from manip.conformance.judge.verdict import counts
from manip.conformance.suite.context import RunOptions
from manip.conformance.suite.results import RunReport
from manip.spec import SPEC
from manip.spec.notation import octal

__all__ = ["Campaign", "CampaignConfig", "CampaignEvents", "describe_step"]

COUNT_RETRIES: Final = 3
COUNT_SETTLE: Final = 0.05
"""Seconds to let the target's links catch up before its bad-frame count is taken again."""


@dataclass
class CampaignConfig:
    """One campaign's configuration, built once by ``manip-conform fuzz`` and read everywhere: the
    judging settings the suite's run has too (``options``: strictness, how long answers may take, the
    robot kind), what shapes the inputs (``gen``), and what only a campaign has."""

    seed: int
    gen: GenOptions
    options: RunOptions = field(default_factory=RunOptions)
    inputs: int | None = 10_000
    seconds: float | None = None
    batch: int = 100
    only: Sequence[int] = ()
    shrink: bool = True
    shrink_trials: int = 200
    shrink_seconds: float = 60.0
    restart_wait: float = 0.0
    reproduce_prefix: Sequence[str] = ("manip-conform", "fuzz")
    reproduce_options: Sequence[str] = ()
    command: str = ""
    server: Mapping[str, object] = field(default_factory=dict)
    """How the server fuzzed was chosen (its link, faults, wrist), for the report's options."""

    def report_options(self) -> dict[str, object]:
        """The report's ``options``: the campaign's settings, each read from where it is kept."""
        return {
            "inputs": len(self.only) if self.only else self.inputs,
            "seconds": self.seconds,
            "batch": self.batch,
            "classes": list(self.gen.select),
            "target": self.options.robot,
            "allow_motion": self.options.allow_motion,
            "reply_timeout": self.options.reply_timeout,
            "deadline_scale": self.options.deadline_scale,
            **self.server,
            "only": list(self.only),
        }


@dataclass
class CampaignEvents:
    """Callbacks for a console: after each batch (inputs sent so far), at each new violation."""

    batch_done: Callable[[CampaignFacts], None] = lambda facts: None
    found: Callable[[CampaignViolation], None] = lambda violation: None
    note: Callable[[str], None] = lambda text: None


def describe_step(step: Step) -> str:
    """One line per step for a report: what it is and its bytes."""
    if isinstance(step, RequestStep):
        op = SPEC.requests.get(step.opcode)
        name = op.name if op is not None else "unknown opcode"
        how = f", written {step.chunk} byte(s) at a time" if step.chunk else ""
        how += ", not read" if step.lazy else ""
        return f"request 0{step.opcode:o} ({name}{how}), data: {step.data.hex(' ') or '(none)'}"
    if isinstance(step, ConnPacket):
        data = step.data.hex(" ") or "(none)"
        return f"on the connection: {step.what} opcode 0{step.opcode:o} offset {step.offset}, data: {data}"
    if isinstance(step, Stray):
        p = step.packet
        damage = f", damage: {step.damage}" if step.damage else ""
        return (
            f"stray opcode 0{p.opcode:o} to index {octal(p.dest_index)} from {octal(p.src_index)} "
            f"#{p.packet_no}{damage}, expect {step.expect}, data: {p.data.hex(' ') or '(none)'}"
        )
    if isinstance(step, Pause):
        return f"a pause of up to {step.seconds:g} s (ended by an asynchronous packet)"
    if isinstance(step, Reconnect):
        return f"the connection closed once answered, and a new one opened {step.after:g} s later"
    if isinstance(step, Silence):
        return f"the connection silent for {step.seconds:g} s once answered (no receipt, no answer to SNS)"
    assert isinstance(step, Raw)
    held = " (left open)" if step.hold else ""
    return f"raw bytes on a link of their own{held}: {step.data.hex(' ') or '(none)'}"


class Campaign:
    """One campaign against ``target`` (module docstring)."""

    def __init__(
        self, config: CampaignConfig, target: FuzzedServer, events: CampaignEvents | None = None
    ) -> None:
        self.config = config
        self.target = target
        self.events = events or CampaignEvents()
        self.facts = CampaignFacts()
        self.report = RunReport(
            target="",
            embedded=config.options.embedded,
            seed=config.seed,
            strict=config.options.strict,
            options=config.report_options(),
            command=config.command,
            campaign=self.facts,
        )
        for c in config.gen.classes():
            self.facts.classes[c.id] = ClassTally(
                c.id, c.layer, c.sends, c.expected, c.clauses, c.level, c.hazard
            )
        self._allowance = Allowance.of(config.options)
        self._runner: BatchRunner | None = None
        self._known: dict[tuple[str, str], int] = {}
        self._bad_seen: int | None = None

    # ------------------------------------------------------------------------------------ running

    async def run(self) -> RunReport:
        """Run the campaign; its report (:meth:`finish`, also after an interruption)."""
        report = self.report
        report.started = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
        started = time.monotonic()
        try:
            await self._run()
        except (KeyboardInterrupt, asyncio.CancelledError):
            report.interrupted = True
            report.problems.append("the campaign was interrupted; this report is partial")
        finally:
            report.duration = time.monotonic() - started
            if self._runner is not None:
                self._runner.close()
            with contextlib.suppress(Exception):
                await self.target.stop()
            self.facts.tracebacks_seen = self.target.tracebacks_seen
            self.finish()
        return report

    def finish(self) -> RunReport:
        """The report with its cases: one per input class, graded from its violations."""
        self.report.results = class_results(self.report, self.facts)
        return self.report

    async def _run(self) -> None:
        report = self.report
        try:
            await self.target.start()
        except UnreachableError as exc:
            report.unreachable = True
            report.problems.append(str(exc))
            return
        report.target = self.target.label
        self._runner = self._new_runner()
        first = await self._await_alive(self._allowance.connect if not self.target.can_restart else 30.0)
        if not first.alive:
            report.unreachable = True
            report.problems.append(f"the target is not alive: {first.detail}")
            return
        self.target.tracebacks()  # what it logged while starting is not the campaign's
        self._bad_seen = await self.target.bad_frames()
        deadline = None if self.config.seconds is None else time.monotonic() + self.config.seconds
        for numbers in self._batches():
            if deadline is not None and time.monotonic() >= deadline:
                break
            inputs = [generate(self.config.seed, n, self.config.gen) for n in numbers]
            sightings, run, live = await self.trial(inputs)
            facts = self.facts
            facts.batches += 1
            facts.inputs += len(inputs)
            facts.requests += run.sent_requests
            facts.bad_frames_sent += run.counted
            for item in inputs:
                tally = facts.classes[item.kind]
                tally.inputs += 1
                tally.requests += item.requests
            for sighting in sightings:
                await self._record(sighting, inputs, facts.batches - 1)
            self.events.batch_done(facts)
            if not live.alive and not await self._revive():
                report.problems.append(
                    f"the target did not come back after batch {facts.batches - 1}: {live.detail}"
                )
                return

    def _batches(self) -> list[list[int]] | _Numbers:
        if self.config.only:
            return [list(self.config.only)]
        return _Numbers(self.config.inputs, self.config.batch)

    async def _await_alive(self, timeout: float) -> Liveness:
        assert self._runner is not None
        deadline = time.monotonic() + timeout
        while True:
            live = await liveness(self._runner)
            self._runner.finish()
            if live.alive or time.monotonic() >= deadline:
                return live
            gone = self.target.gone()
            if gone is not None:
                return Liveness(False, "crash", gone, live.duration)
            await asyncio.sleep(0.2)

    async def _revive(self) -> bool:
        """Bring a dead target back: restart it, or wait for it.  False if it stays dead."""
        if self.target.can_restart:
            try:
                await self.target.restart()
            except UnreachableError as exc:
                self.report.problems.append(f"restarting the target failed: {exc}")
                return False
            self.facts.restarts += 1
            self._runner = self._new_runner()
            live = await self._await_alive(30.0)
            self.target.tracebacks()
            self._bad_seen = await self.target.bad_frames()
            return live.alive
        if self.config.restart_wait <= 0:
            return False
        self.events.note(f"waiting up to {self.config.restart_wait:g} s for the target to come back")
        return (await self._await_alive(self.config.restart_wait)).alive

    def _new_runner(self) -> BatchRunner:
        if self._runner is not None:
            self._runner.close()
        return BatchRunner(self.target.address, self._allowance, seed=self.config.seed)

    async def trial(self, inputs: list[FuzzInput]) -> tuple[list[Sighting], BatchRun, Liveness]:
        """Send one batch, check liveness, collect what the target logged and counted; judge."""
        runner = self._runner
        assert runner is not None
        run = await runner.run(inputs)
        live = await liveness(runner)
        self.facts.liveness_checks += 1
        gone = self.target.gone()
        if gone is not None:
            live = Liveness(False, "crash", gone, live.duration)
        if not live.alive:
            self.facts.liveness_failures += 1
        uncounted = await self._count(run) if live.alive else None
        sightings = judge(run, runner.inbox, live, tracebacks=self.target.tracebacks(), uncounted=uncounted)
        runner.finish()
        return sightings, run, live

    async def _count(self, run: BatchRun) -> tuple[int, int] | None:
        """(bad frames sent, counted) for the batch, when the target counts them."""
        if self._bad_seen is None:
            return None
        before = self._bad_seen
        now = await self.target.bad_frames()
        for _ in range(COUNT_RETRIES):
            if now is None or now - before >= run.counted:
                break
            await asyncio.sleep(COUNT_SETTLE)
            now = await self.target.bad_frames()
        if now is None:
            return None
        self._bad_seen = now
        self.facts.bad_frames_counted = (self.facts.bad_frames_counted or 0) + (now - before)
        return run.counted, now - before

    # ------------------------------------------------------------------------------------ violations

    async def _record(self, o: Sighting, inputs: list[FuzzInput], batch: int) -> None:
        facts = self.facts
        known = self._known.get(o.signature)
        if known is not None:
            facts.violations[known].occurrences += 1
            facts.violations[known].followers += o.followers
            return
        kind = _class_of(o, inputs)
        violation = CampaignViolation(
            o.violation,
            kind,
            batch,
            counts=counts(o.violation, self.config.options.strict),
            followers=o.followers,
        )
        index = len(facts.violations)
        facts.violations.append(violation)
        self._known[o.signature] = index
        numbers = [i.number for i in inputs]
        if self.config.shrink and not self.config.only:
            self.events.note(f"shrinking: {violation.title()}")
            minimal, violation.shrunk, violation.shrink_note = await self._shrink(o, numbers)
        else:
            minimal = [o.number] if o.number is not None and not self.config.only else numbers
            violation.shrink_note = "not shrunk" if not self.config.only else "the inputs given with --only"
        by_number = {i.number: i for i in inputs}
        violation.minimal = [
            _minimal(by_number.get(n) or generate(self.config.seed, n, self.config.gen)) for n in minimal
        ]
        if violation.minimal and kind == HEALTH and violation.shrunk:
            violation.input_class = violation.minimal[-1].kind
        violation.reproduce = self._reproduce(minimal)
        tally = facts.classes.get(violation.input_class)
        if tally is not None:
            tally.violations.append(index)
        self.events.found(violation)

    async def _shrink(self, o: Sighting, numbers: list[int]) -> tuple[list[int], bool, str]:
        budget = Budget(self.config.shrink_trials, self.config.shrink_seconds)
        wanted = o.signature

        async def fails(candidate: list[int]) -> bool:
            return await self.reproduces(candidate, wanted)

        try:
            if o.number is not None:
                budget.spend()
                if await fails([o.number]):
                    return [o.number], True, "the input it was seen on, alone"
            budget.spend()
            if not await fails(numbers):
                return numbers, False, "the batch did not cause it again: not shrunk"
        except BudgetError:
            return numbers, False, "no trial left to shrink it"
        except UnreachableError as exc:
            return numbers, False, f"not shrunk: {exc}"
        try:
            minimal, complete = await ddmin(numbers, fails, budget)
        except UnreachableError as exc:
            return numbers, False, f"not shrunk: {exc}"
        finally:
            self.facts.shrink_trials += budget.used
        note = f"{budget.used} trials" + ("" if complete else ", the budget ran out before it was minimal")
        return minimal, complete, note

    async def reproduces(self, numbers: list[int], signature: tuple[str, str]) -> bool:
        """Send inputs ``numbers`` as a batch of their own: does ``signature`` show again?"""
        if not await self._alive_for_trial():
            raise UnreachableError("the target is not alive to try inputs on")
        inputs = [generate(self.config.seed, n, self.config.gen) for n in numbers]
        checks, failures = self.facts.liveness_checks, self.facts.liveness_failures
        sightings, _, live = await self.trial(inputs)
        self.facts.liveness_checks, self.facts.liveness_failures = checks, failures  # not the campaign's
        if not live.alive and not await self._revive():
            raise UnreachableError("the target did not come back")
        return any(x.signature == signature for x in sightings)

    async def _alive_for_trial(self) -> bool:
        assert self._runner is not None
        if self.target.gone() is not None:
            return await self._revive()
        live = await liveness(self._runner)
        self._runner.finish()
        return live.alive or await self._revive()

    def _reproduce(self, numbers: Sequence[int]) -> str:
        words = [
            *self.config.reproduce_prefix,
            "--seed",
            str(self.config.seed),
            "--only",
            ",".join(map(str, numbers)),
        ]
        return shlex.join([*words, *self.config.reproduce_options])


class _Numbers:
    """Batches of input numbers: ``batch`` at a time from 0, up to ``total`` (None: without end)."""

    def __init__(self, total: int | None, batch: int) -> None:
        self.total = total
        self.batch = batch

    def __iter__(self) -> _Numbers:
        self._next = 0
        return self

    def __next__(self) -> list[int]:
        start = self._next
        end = start + self.batch if self.total is None else min(start + self.batch, self.total)
        if end <= start:
            raise StopIteration
        self._next = end
        return list(range(start, end))


def _class_of(o: Sighting, inputs: list[FuzzInput]) -> str:
    if o.number is None:
        return HEALTH
    for item in inputs:
        if item.number == o.number:
            return item.kind
    return HEALTH


def _minimal(item: FuzzInput) -> MinimalInput:
    return MinimalInput(item.number, item.kind, item.note, [describe_step(s) for s in item.steps])
