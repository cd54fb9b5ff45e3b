"""Running the client cases: one harness process, a judging server per case, outcomes, the verdict.

Theory of operation
===================

1. **Start the harness** (``CMD ARGS...``) and read its hello.  A harness that does not start or says
   no valid hello is *unreachable*: no case runs, exit code 3.
2. **Each case**, in id order, runs its function with a :class:`ClientContext`.  The function calls
   :meth:`ClientContext.play` once or more: a fresh judging server listens with the scenario's script,
   the harness gets the case's operations and its results are read until ``done``.  The case then judges
   the results and the wire with ``ctx.expect``.  After the body the ``client-wire`` invariant judges
   every play's wire (request layouts, initial RESPONSE, numbering, acknowledgements, window).
3. **Outcomes** are the server suite's, plus ``unsupported``: the harness's hello does not declare an
   operation, link or feature the case needs (never a pass; the run's verdict ignores it).  A harness that
   crashes, hangs, writes a line the contract does not allow or omits ``done`` fails the case (no
   clause: the harness broke the contract) and is started again for the next case.
"""

from __future__ import annotations

import asyncio
import contextlib
import shlex
import time
import traceback
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from typing import Any, Final

from manip.conformance.client.contract import HarnessHello, Instruction, Op, Result
from manip.conformance.client.process import HarnessError, HarnessProblem, HarnessProcess, Limits
from manip.conformance.client.server import Mangle, Script, ServerSide, WireRecord, serve_scenario
from manip.conformance.client.wire import (
    ack_violations,
    client_requests,
    initial_response_violations,
    numbering_violations,
    request_violations,
    window_violations,
    wire_packet,
)
from manip.conformance.judge.verdict import Outcome
from manip.conformance.judge.violation import FailureKind, showing
from manip.conformance.suite.case import Case, CaseFailure, CaseSkipped
from manip.conformance.suite.context import CaseContext, RunOptions
from manip.conformance.suite.invariants import CLIENT_WIRE
from manip.conformance.suite.results import CaseResult, LivenessCheck, RunReport, conclude
from manip.conformance.suite.runner import blank_result
from manip.conformance.suite.selection import PatternSet
from manip.links import NcpConfig

__all__ = [
    "DEFAULT_CLIENT_TIMEOUT",
    "CaseUnsupported",
    "ClientContext",
    "ClientRunConfig",
    "Play",
    "client_context",
    "run_client_suite",
]

DEFAULT_CLIENT_TIMEOUT: Final = 2.0
"""Seconds the harness is told to wait for each reply (``--reply-timeout``)."""
SCRIPT_GRACE: Final = 2.0
HARNESS_SLACK: Final = 10.0
"""Seconds a harness has beyond its ops' timeouts and waits to write ``done`` (docs/client-harness.md)."""
OUTER_SLACK: Final = 30.0
_PROBLEM_KIND: Final[dict[str, FailureKind]] = {
    "hung": "deadline",
    "crashed": "closed",
    "garbage": "malformed",
    "no-hello": "missing",
}


class CaseUnsupported(Exception):  # noqa: N818 - an outcome
    """The harness does not declare what the case needs."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


@dataclass
class Play:
    """One scenario played: the instruction, what the harness said, what went over the wire."""

    instruction: Instruction
    results: list[Result]
    wire: list[WireRecord]
    sides: list[ServerSide]
    stderr: list[str] = field(default_factory=list)
    times: list[float] = field(default_factory=list)
    """When each result was read, in seconds on the wire's clock (``WireRecord.t``)."""
    window: int = 15
    """The receive window the judging server offered."""

    def time_of(self, result: Result) -> float | None:
        for r, t in zip(self.results, self.times, strict=False):
            if r is result:
                return t
        return None

    def of(self, kind: str, op: int | None = None, *, any_op: bool = False) -> list[Result]:
        """Results of ``kind`` for op ``op`` (``any_op``: whatever op)."""
        return [r for r in self.results if r.type == kind and (any_op or r.op == op)]

    def one(self, kind: str, op: int | None) -> Result | None:
        found = self.of(kind, op)
        return found[0] if found else None

    def answer(self, op: int) -> Result | None:
        """The op's reply or error, whichever came first."""
        for r in self.results:
            if r.op == op and r.type in ("reply", "error"):
                return r
        return None

    def states(self) -> list[str]:
        return [str(r.get("state")) for r in self.results if r.type == "state"]

    @property
    def side(self) -> ServerSide | None:
        return self.sides[0] if self.sides else None

    def requests(self) -> list[WireRecord]:
        return client_requests(self.wire)

    def describe(self) -> str:
        lines = [r.line for r in self.results]
        return "\n".join(lines[-20:])


@dataclass
class ClientRun:
    """The run's harness and settings, shared by the cases."""

    harness: HarnessProcess
    hello: HarnessHello
    link: str
    timeout: float
    deadline_scale: float = 1.0
    slack: float = HARNESS_SLACK


class ClientContext(CaseContext):
    """A :class:`CaseContext` that can play scenarios against the harness (see the module docstring)."""

    def __init__(self, session: ClientRun, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.session = session
        self.plays: list[Play] = []

    @property
    def link(self) -> str:
        return self.session.link

    @property
    def timeout(self) -> float:
        return self.session.timeout

    async def play(
        self,
        operations: Sequence[Op],
        script: Script,
        *,
        ncp: NcpConfig | None = None,
        refuse: str | None = None,
        mangle: Mangle | None = None,
        initial: bool = True,
        timeout: float | None = None,
        offer: int | None = None,
    ) -> Play:
        """Play one scenario: the judging server runs ``script``, the harness ``operations``; ``offer``
        is the window offered from the start when it is not the NCP's (``ncp.window``)."""
        session = self.session
        listener = await serve_scenario(
            session.link,
            script,
            rng=self.random,
            ncp=ncp,
            refuse=refuse,
            mangle=mangle,
            initial=initial,
            offer=offer,
        )
        try:
            instruction = Instruction(
                self.case_id,
                self.seed,
                session.link,
                listener.address,
                "PUMA",
                self.timeout if timeout is None else timeout,
                tuple(operations),
            )
            missing = session.hello.missing(instruction, session.link)
            if missing:
                raise CaseUnsupported(f"the harness does not declare {', '.join(missing)}")
            deadline = instruction.deadline(session.slack) * session.deadline_scale
            run = await session.harness.run_case(instruction, deadline)
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(SCRIPT_GRACE):
                    await listener.done.wait()
        finally:
            await listener.aclose()
        play = Play(
            instruction,
            run.results,
            list(listener.wire.records),
            listener.sides,
            run.stderr,
            [listener.wire.since_start(t) for t in run.times],
            (ncp or NcpConfig()).window if offer is None else offer,
        )
        self.plays.append(play)
        self.transcript += [wire_packet(r) for r in play.wire]
        for side in listener.sides:
            self.notes += side.notes
        if listener.script_error:
            raise listener.script_error[0]
        if run.problem is not None:
            self._harness_failed(run.problem, play)
        unsupported = play.of("unsupported", any_op=True)
        if unsupported:
            names = ", ".join(str(r.get("operation")) for r in unsupported)
            raise CaseUnsupported(f"the harness reported {names} unsupported")
        return play

    def _harness_failed(self, problem: HarnessProblem, play: Play) -> None:
        tail = "\n".join(play.stderr[-10:])
        actual = f"{problem.detail}" + (f"\nits stderr ends:\n{tail}" if tail else "")
        raise CaseFailure(
            f"the harness {problem.what}: {problem.detail}",
            expected="result lines of the contract, ending with 'done'",
            actual=actual,
            kind=_PROBLEM_KIND.get(problem.what, "missing"),
        )

    def expect_result(
        self,
        answer: Result | None,
        kind: str = "reply",
        *,
        clause: str,
        expected: str,
        values: Mapping[str, object] | None = None,
        seen: object = None,
    ) -> bool:
        """The harness reported ``answer`` (an op's result) as a reply, with ``values`` among its values
        when given, or (``kind`` other than "reply") as an error of that kind (``not-connected``,
        ``timeout``, ``bad-data``...).  The evidence is the result (``seen`` when given)."""
        got = (answer.get("values") or {}) if answer is not None else {}
        met = answer is not None and (
            answer.type == "reply" and all(got.get(k) == v for k, v in (values or {}).items())
            if kind == "reply"
            else answer.type == "error" and answer.get("kind") == kind
        )
        return self.expect(met, clause=clause, expected=expected, seen=str(answer) if seen is None else seen)

    def judge_wire(self) -> None:
        """The ``client-wire`` invariant over every play of the case."""
        for play in self.plays:
            violations = (
                request_violations(play.wire)
                + initial_response_violations(play.wire)
                + numbering_violations(play.wire)
                + ack_violations(play.wire, settle=1.0)
            )
            violations += window_violations(play.wire, play.window)
            for violation in violations:
                self.expect(
                    False,
                    clause=violation.clause,
                    expected=violation.expected,
                    seen=showing(violation.packets or violation.data, violation.actual),
                    message=violation.message,
                    invariant=CLIENT_WIRE.name,
                )


def client_context(ctx: CaseContext) -> ClientContext:
    """The client context of a client case (a client case runs only under ``manip-conform client``)."""
    if not isinstance(ctx, ClientContext):
        raise CaseSkipped("a client case runs under manip-conform client")
    return ctx


@dataclass
class ClientRunConfig:
    argv: Sequence[str]
    link: str
    seed: int
    options: RunOptions
    select: PatternSet = field(default_factory=PatternSet)
    skip: PatternSet = field(default_factory=PatternSet)
    known_failing: PatternSet = field(default_factory=PatternSet)
    command: str = ""
    env: dict[str, str] | None = None
    slack: float = HARNESS_SLACK
    limits: Limits = field(default_factory=Limits)
    """The time limits on the harness (hello, exit, kill, writing a case)."""


@dataclass
class ClientEvents:
    started: Callable[[list[Case]], None] | None = None
    case_started: Callable[[Case], None] | None = None
    case_finished: Callable[[CaseResult], None] | None = None
    liveness: Callable[[LivenessCheck], None] | None = None


def selected(config: ClientRunConfig, cases: Sequence[Case]) -> list[Case]:
    return [
        c
        for c in sorted(cases, key=lambda c: c.id)
        if (not config.select or config.select.matches(c.id)) and not config.skip.matches(c.id)
    ]


async def run_client_suite(
    config: ClientRunConfig, cases: Sequence[Case], events: ClientEvents | None = None
) -> RunReport:
    """Run the client cases against the harness ``config.argv``; never raises but on interruption."""
    events = events or ClientEvents()
    report = RunReport(
        target=shlex.join(config.argv),
        embedded=False,
        seed=config.seed,
        strict=config.options.strict,
        options={
            "link": config.link,
            "reply_timeout": config.options.reply_timeout,
            "deadline_scale": config.options.deadline_scale,
            "select": [p.text for p in config.select.patterns],
            "skip": [p.text for p in config.skip.patterns],
            "known_failing": [p.text for p in config.known_failing.patterns],
        },
        command=config.command,
    )
    report.started = datetime.now(UTC).isoformat(timespec="seconds")
    t0 = time.monotonic()
    chosen = selected(config, cases)
    for item in cases:
        config.known_failing.matches(item.id)
    for stale in config.known_failing.unmatched():
        report.problems.append(
            f"known-failing entry {stale.text!r} ({stale.source}) matches no case: remove it"
        )
    if events.started:
        events.started(chosen)
    harness = HarnessProcess(config.argv, env=config.env, limits=config.limits)
    try:
        hello = await _start(harness, report, events)
        if hello is None:
            for item in chosen:
                report.results.append(_blank(config, item, "skip", "the harness could not be started"))
            return report
        session = ClientRun(
            harness,
            hello,
            config.link,
            config.options.reply_timeout,
            config.options.deadline_scale,
            config.slack,
        )
        await _run_cases(config, session, chosen, report, events)
    except (asyncio.CancelledError, KeyboardInterrupt):
        report.interrupted = True
        report.problems.append("the run was interrupted; this report is partial")
    finally:
        await harness.stop()
        report.duration = time.monotonic() - t0
    return report


async def _run_cases(
    config: ClientRunConfig,
    session: ClientRun,
    chosen: Sequence[Case],
    report: RunReport,
    events: ClientEvents,
) -> None:
    """Each case in turn; once the harness cannot be started again, the rest are skipped."""
    harness = session.harness
    for item in chosen:
        if harness.unusable is not None:
            result = _blank(config, item, "skip", "the harness could not be started again")
        else:
            result = await run_client_case(config, session, item)
        report.results.append(result)
        if events.case_finished:
            events.case_finished(result)
    if harness.unusable is not None:
        report.problems.append(f"the harness could not be started again: {harness.unusable}")
    for result in report.results:
        if result.outcome == "fixed":
            report.problems.append(
                f"case {result.id} is listed as known failing but passed: remove its entry"
            )


async def _start(harness: HarnessProcess, report: RunReport, events: ClientEvents) -> HarnessHello | None:
    t = time.monotonic()
    try:
        hello = await harness.start()
    except HarnessError as exc:
        check = LivenessCheck("before", False, str(exc), time.monotonic() - t)
        report.liveness.append(check)
        report.unreachable = True
        report.problems.append(f"the harness could not be used: {exc}")
        if events.liveness:
            events.liveness(check)
        return None
    detail = f"hello from {hello.name} {hello.version}: links {', '.join(sorted(hello.links))}"
    report.liveness.append(LivenessCheck("before", True, detail, time.monotonic() - t))
    return hello


def _blank(config: ClientRunConfig, item: Case, outcome: Any, reason: str) -> CaseResult:
    selected = ["--link", config.link, "--select", item.id, "--seed", str(config.seed)]
    reproduce = shlex.join(["manip-conform", "client", *selected, "--", *config.argv])
    known = config.known_failing.matches(item.id)
    return blank_result(item, outcome, reason, config.seed, config.options, reproduce, known)


async def run_client_case(config: ClientRunConfig, session: ClientRun, item: Case) -> CaseResult:
    """Run one client case to its outcome (never raises, but on interruption)."""
    result = _blank(config, item, "pass", "")
    ctx = ClientContext(
        session,
        case_id=item.id,
        level=item.level,
        seed=result.seed,
        options=config.options,
        connector=_no_connector,
        clauses=item.clauses,
    )
    failure: CaseFailure | None = None
    start = time.monotonic()
    try:
        # Each play is bounded by its harness deadline (the ops' timeouts and waits); this outer bound
        # only keeps a scenario's own bug from hanging the run.
        async with asyncio.timeout(result.deadline * 4 + OUTER_SLACK):
            await item.function(ctx)
            if ctx.auto_check:
                ctx.judge_wire()
    except CaseFailure as exc:
        failure = exc
    except CaseUnsupported as exc:
        result.outcome = Outcome.UNSUPPORTED
        result.reason = exc.reason
    except CaseSkipped as exc:
        result.outcome = Outcome.SKIP
        result.reason = exc.reason
    except TimeoutError:
        failure = CaseFailure(
            "the case did not finish within its deadline",
            expected=f"the case to finish within {result.deadline * 4 + OUTER_SLACK:g} s",
            actual=f"still running after {time.monotonic() - start:.2f} s",
            kind="deadline",
        )
        await session.harness.kill()
    except (asyncio.CancelledError, KeyboardInterrupt):
        raise
    except Exception as exc:
        result.outcome = Outcome.ERROR
        result.reason = f"{type(exc).__name__}: {exc}"
        result.traceback = traceback.format_exc()
    result.duration = time.monotonic() - start
    if ctx.plays:
        result.harness_deadline = round(
            sum(p.instruction.deadline(session.slack) for p in ctx.plays) * session.deadline_scale, 3
        )
    result.notes = list(ctx.notes)
    result.packets = list(ctx.transcript)
    _judge(config, result, ctx, failure)
    return result


def _judge(
    config: ClientRunConfig, result: CaseResult, ctx: ClientContext, failure: CaseFailure | None
) -> None:
    stopped = None if failure is None else replace(failure.violation, level=failure.level or result.level)
    result.reached = tuple(sorted(ctx.reached))
    conclude(result, stopped, ctx.recorded, config.options.strict)


async def _no_connector(_retry_busy: bool, _watch: object = None) -> Any:
    raise RuntimeError("a client case plays scenarios (ctx.play); it opens no connection itself")
