"""Running cases against a target: selection, deadlines, liveness probes, outcomes, the verdict.

Theory of operation
===================

:class:`Runner` takes the registered cases and a :class:`RunConfig` and produces a
:class:`~manip.conformance.suite.results.RunReport`:

1. **Select**: cases matching ``--select`` (all when none given) and not ``--skip``, in id order.
   ``--known-failing`` entries are matched against every registered case; one that matches none is
   a problem of the run (a stale entry).
2. **Liveness before**: connect, send a read-only request, wait for any answer, and again on the same
   connection.  A target that
   fails it without having sent a single manip packet is *unreachable*: no case runs, exit code 3.  A
   target that sent something (the initial RESPONSE, a partial reply) and then broke the exchange was
   reached: the cases run, and the first one's failure says what it did.  So was a target whose frames
   the link refused for a rule of Chaos (a checksum, a header, the word order): the link cases say
   which.
3. **Each case**, one at a time, gets a :class:`~manip.conformance.suite.context.CaseContext` with its own
   seed (derived from the run seed and the case id, so a case's seed does not depend on what else
   runs) and its deadline (``case.deadline * deadline_scale``, plus any wait on a target's timer).  Its
   connections are closed after it, whatever happened.  After the body, unless the case turned it off
   (``ctx.auto_check = False``), every probe's recording goes through
   :func:`~manip.conformance.judge.checks.check_transcript`, so each case also checks the invariants of the
   whole exchange (one reply per request, echoes, error formats, asynchronous responses only when
   asked for...).  A case goes on after a violation its ``ctx.expect`` recorded, and its result lists
   them all (:func:`~manip.conformance.suite.results.conclude`).  An exception of the case never stops the
   run: it becomes an ``error`` outcome with its traceback (unless it came after a violation, which
   it then merely follows), and so does a violation of a clause the
   case does not declare that no suite invariant reported (:mod:`manip.conformance.suite.invariants`).
4. **Liveness after** every failure or error and after every negative case (unless the target was
   never alive, only reached: then every case runs and says what it saw); if the target is dead
   (after one retry), or a case failed for want of the initial RESPONSE and the liveness check got none
   either, or a case failed under a flood of :data:`RUNAWAY_PACKETS` packets or more (a runaway target),
   the run notices it once: the remaining cases end at once ``not-judged`` (a live target would judge
   them), the run records which case it died after, and the run is non-conformant (or
   unreachable, exit 3, when nothing the target sent reached any case).  So a run against any target
   ends within the sum of its cases' deadlines plus :data:`CASE_MARGIN` per case and the liveness
   checks (:func:`liveness_bound` each).
5. **Liveness at the end**; then the verdict (:attr:`RunReport.exit_code`).

Hazards: with ``robot="hardware"`` (``--target hardware``) cases whose hazard is above ``config`` are
skipped unless ``allow_motion``.  Interruption (Ctrl-C, cancellation) stops the run; the report so far
is returned with ``interrupted`` set (exit code 4).
"""

from __future__ import annotations

import asyncio
import hashlib
import shlex
import time
import traceback
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime

from manip.conformance.judge.checks import check_server_opcode, check_transcript
from manip.conformance.suite.busy import open_retrying_busy
from manip.conformance.suite.case import Case, CaseFailure, CaseSkipped
from manip.conformance.suite.context import CaseContext, Probe, RunOptions
from manip.conformance.suite.invariants import attribution_problem
from manip.conformance.suite.results import CaseResult, LivenessCheck, Outcome, RunReport, conclude
from manip.conformance.suite.selection import PatternSet
from manip.conformance.suite.units import learn_length_unit
from manip.conformance.suite.world import CaseNotJudged, ConditionUnsupported, World, WorldError
from manip.links import ChaosConnection, open_connection
from manip.links.api import LinkWrapper
from manip.links.base import Link, LinkStats
from manip.spec.constants import ANSWER_OPS, ServerOp
from manip.spec.notation import octal

__all__ = [
    "CASE_MARGIN",
    "LIVENESS_RETRY_DELAY",
    "RUNAWAY_PACKETS",
    "RunConfig",
    "RunEvents",
    "Runner",
    "case_seed",
    "liveness_bound",
]

LIVENESS_RETRY_DELAY = 0.5
LIVENESS_REQUESTS = 2
"""Requests a liveness probe sends on its connection, one after the other, each to be answered."""
CLOSE_GRACE = 2.0
CASE_MARGIN = CLOSE_GRACE
RUNAWAY_PACKETS = 5_000
"""A case that fails having taken this many packets from the target (a case needs a few dozen, a property
case a few hundred) shows a runaway target: the run gives it up, as it does a dead one."""
"""How long a case may run past its deadline, whatever the target does: the closing of its connections."""


def _sent_chaos_frames(stats: LinkStats) -> bool:
    """Whether the target sent frames its link refused for a rule of Chaos (a checksum, a header, a whole
    frame in the other byte order...), not only a stream the link could find no frame in: a Chaos host,
    reached, whose frames the link cases judge (``server.link.*-frames``)."""
    return sum(stats.bad_clauses.values()) > stats.bad["framing"]


def _held_back(probe: Probe) -> bool:
    """Whether the probe's connection holds packets of the target beyond one that never came (its
    numbering has a gap): the target sent data, which ``server.link.packet-numbers`` judges."""
    info = probe.conn.info()
    return info is not None and info.buffered > 0


def liveness_bound(options: RunOptions) -> float:
    """The longest one liveness check takes (two probes, each bounded, and the pause between them)."""
    once = options.connect_timeout + LIVENESS_REQUESTS * options.reply_timeout + 1.0 + CLOSE_GRACE
    return 2 * once + LIVENESS_RETRY_DELAY


def case_seed(run_seed: int, case_id: str) -> int:
    """A case's seed: a 32-bit hash of the run seed and the case id."""
    digest = hashlib.sha256(f"{run_seed}:{case_id}".encode()).digest()
    return int.from_bytes(digest[:4], "big")


def blank_result(
    item: Case,
    outcome: Outcome,
    reason: str,
    run_seed: int,
    options: RunOptions,
    reproduce: str,
    known_failing: bool,
) -> CaseResult:
    """A case's result before it runs (or instead of running): what it is, its seed and deadline."""
    return CaseResult(
        id=item.id,
        clauses=item.clauses,
        level=item.level,
        kind=item.technique,
        target=item.target,
        hazard=item.hazard,
        extensions=item.extensions,
        summary=item.summary,
        outcome=outcome,
        seed=case_seed(run_seed, item.id),
        deadline=item.deadline_for(options),
        reason=reason,
        reproduce=reproduce,
        known_failing=known_failing,
    )


@dataclass
class RunConfig:
    """One run's configuration, built once by its command and read everywhere: the settings cases see
    (``options``, with the target's address and whether the suite started it), and what only the
    runner reads.  No setting is in both."""

    options: RunOptions
    seed: int
    select: PatternSet = field(default_factory=PatternSet)
    skip: PatternSet = field(default_factory=PatternSet)
    known_failing: PatternSet = field(default_factory=PatternSet)
    virtual_time: bool = False
    """The run's event loop is a :class:`~manip.links.virtual_clock.VirtualClockLoop` (the embedded
    server simulated on the same loop)."""
    reproduce_prefix: Sequence[str] = ("manip-conform", "run")
    """The command a failing case's reproduce line starts with (target and options are appended)."""
    reproduce_options: Sequence[str] = ()
    command: str = ""
    liveness_check: Callable[[RunOptions], Awaitable[tuple[bool, str]]] | None = None
    """Replaces the Chaos liveness probe: (alive, detail) for targets that are not manip servers
    (the Cougar target, :mod:`manip.conformance.cougar.target`)."""
    world: World | None = None
    """The target's world, for the cases that arrange a condition of it
    (:mod:`manip.conformance.suite.world`): the embedded server's, or ``--world``'s; None without one
    (those cases end not-judged)."""
    wrap_link: LinkWrapper | None = None
    """Given every link the run's connections make (``RecorderTap(recorder, "client").wrap`` records
    the run: ``manip-conform run --record``)."""


@dataclass
class RunEvents:
    """Callbacks for progress display (all optional)."""

    started: Callable[[list[Case]], None] | None = None
    case_started: Callable[[Case], None] | None = None
    case_finished: Callable[[CaseResult], None] | None = None
    liveness: Callable[[LivenessCheck], None] | None = None


class Runner:
    def __init__(self, config: RunConfig, cases: Sequence[Case], events: RunEvents | None = None) -> None:
        self.config = config
        self.all_cases = list(cases)
        self.events = events or RunEvents()
        self.report = RunReport(
            target=config.options.address,
            embedded=config.options.embedded,
            seed=config.seed,
            strict=config.options.strict,
            options={
                "target": config.options.robot,
                "allow_motion": config.options.allow_motion,
                "max_examples": config.options.max_examples,
                "reply_timeout": config.options.reply_timeout,
                "deadline_scale": config.options.deadline_scale,
                "time_scale": config.options.time_scale,
                "length_unit": config.options.length_unit,
                "select": [p.text for p in config.select.patterns],
                "skip": [p.text for p in config.skip.patterns],
                "known_failing": [p.text for p in config.known_failing.patterns],
            },
            command=config.command,
            time="virtual" if config.virtual_time else "real",
            length_unit=config.options.length_unit,
        )
        self._reached = False
        self._reached_by_frames_only = False
        # reached only through frames its link refused (or packets held back for a number it skipped)
        """Whether anything the target sent (a manip packet, not only the Chaos opening) reached the run."""
        self._initial_seen = True
        """Whether the last liveness probe got its initial RESPONSE."""
        self._runaway = ""
        """Set when a case could not finish under a flood from the target (:data:`RUNAWAY_PACKETS`)."""
        self._dead_reason = ""

    # --------------------------------------------------------------------------------- selection

    def selected(self) -> list[Case]:
        config = self.config
        out = []
        for item in sorted(self.all_cases, key=lambda c: c.id):
            if config.select and not config.select.matches(item.id):
                continue
            if config.skip.matches(item.id):
                continue
            out.append(item)
        return out

    # --------------------------------------------------------------------------------- connecting

    async def connect(self, retry_busy: bool = True, watch: LinkWrapper | None = None) -> ChaosConnection:
        """A fresh connection to the target; a refusal as busy is retried briefly (``retry_busy``).
        ``watch`` is given the link before the run's own wrapper (a capture's tap) is."""
        config = self.config
        wrap = config.wrap_link
        if watch is not None:
            outer = wrap
            wrap = watch if outer is None else (lambda link: outer(watch(link)))
        return await open_retrying_busy(
            lambda: open_connection(
                config.options.address, timeout=config.options.connect_timeout, wrap_link=wrap
            ),
            retry=retry_busy,
        )

    async def liveness(self, when: str) -> LivenessCheck:
        """Connect, send Here, wait for any answer; one retry after a short pause."""
        clock = asyncio.get_running_loop().time
        start = clock()
        alive, detail = await self._probe_once()
        if not alive:
            await asyncio.sleep(LIVENESS_RETRY_DELAY)
            alive, detail = await self._probe_once()
        check = LivenessCheck(when, alive, detail, clock() - start)
        self.report.liveness.append(check)
        if self.events.liveness:
            self.events.liveness(check)
        return check

    async def _learn_length_unit(self) -> None:
        """``--length-unit auto``: the unit the cases size their moves in, learned from the target."""
        unit, how = await learn_length_unit(self.config.options, self.connect)
        self.config.options = replace(self.config.options, length_unit=unit)
        self.report.length_unit = unit
        self.report.options["length_unit"] = unit
        self.report.options["length_unit_learned"] = how

    async def _probe_once(self) -> tuple[bool, str]:
        """One liveness probe: a fresh connection, Here answered, then Here again on it (a target that
        answers the first request of each connection and nothing after is not alive)."""
        options = self.config.options
        if self.config.liveness_check is not None:
            return await self.config.liveness_check(options)
        ctx = CaseContext(case_id="liveness", level="MUST", seed=0, options=options, connector=self.connect)
        links: list[Link] = []

        def watch(link: Link) -> Link:
            links.append(link)
            return link

        try:
            async with asyncio.timeout(
                options.connect_timeout + LIVENESS_REQUESTS * options.reply_timeout + 1.0
            ):
                probe = await ctx.connect(initial=False, watch=watch)
                detail = ""
                for _ in range(LIVENESS_REQUESTS):
                    answered, detail, fatal = await self._answer_to_here(probe)
                    if not answered or fatal:
                        return answered, detail
                return True, detail
        except CaseFailure as exc:
            return False, exc.actual or exc.message
        except TimeoutError:
            return False, "timed out"
        except OSError as exc:
            return False, f"{type(exc).__name__}: {exc}"
        finally:
            self._initial_seen = bool(ctx.probes) and ctx.probes[0].initial is not None
            self._note_reached(ctx)
            if not self._reached and (
                any(_sent_chaos_frames(link.stats) for link in links)
                or any(_held_back(p) for p in ctx.probes)
            ):
                self._reached = self._reached_by_frames_only = True
            # No wait for the target to read our EOF: a target that floods and never reads again
            # would cost a second per check, after every failed case.
            await _quietly(ctx.close_all(wait=0.0))

    async def _answer_to_here(self, probe: Probe) -> tuple[bool, str, bool]:
        """Send Here and wait for any answer: (answered, what happened, the answer was a fatal error)."""
        timeout = self.config.options.reply_timeout
        number = await probe.request("here")
        while True:
            packet = await probe.next_packet(timeout)
            if packet is None:
                reason = probe.end_reason or f"no answer within {timeout:g} s"
                return False, f"request #{number} sent, {reason}", False
            if packet.opcode in ANSWER_OPS:
                if (
                    probe.initial is None
                    and len(packet.data) == 2
                    and packet.packet_no
                    and not probe.unsolicited
                ):
                    probe.initial = packet  # the initial RESPONSE; the answer comes next
                    continue
                detail = f"answered request #{number} with opcode {octal(packet.opcode)}"
                return True, detail, packet.opcode == ServerOp.FATAL_ERROR
            if check_server_opcode(packet):  # an answer under an opcode no server sends: alive all the same
                return True, f"answered request #{number} with opcode {octal(packet.opcode)}", False

    def _note_reached(self, ctx: CaseContext) -> None:
        """Remember whether the target sent anything a manip session carries."""
        if not self._reached:
            self._reached = any(p.direction == "s2c" and not p.is_close for p in ctx.transcript)

    # --------------------------------------------------------------------------------- the run

    async def run(self) -> RunReport:
        report = self.report
        report.started = datetime.now(UTC).isoformat(timespec="seconds")
        t0 = time.monotonic()
        cases = self.selected()
        for item in self.all_cases:
            self.config.known_failing.matches(item.id)
        for stale in self.config.known_failing.unmatched():
            report.problems.append(
                f"known-failing entry {stale.text!r} ({stale.source}) matches no case: remove it"
            )
        if self.events.started:
            self.events.started(cases)
        try:
            before = await self.liveness("before")
            if not before.alive and not self._reached:
                report.unreachable = True
                for item in cases:
                    report.results.append(
                        self._blank(item, Outcome.SKIP, "target unreachable before the run")
                    )
                return report
            if self.config.options.learn_length_unit:
                await self._learn_length_unit()
            dead = False
            for item in cases:
                if dead:
                    result = self._blank(item, Outcome.NOT_JUDGED, self._dead_reason)
                else:
                    result = await self.run_case(item)
                report.results.append(result)
                if self.events.case_finished:
                    self.events.case_finished(result)
                if (
                    not (self._reached_by_frames_only and not before.alive)  # never alive: cannot die
                    and not dead
                    and (result.outcome in ("fail", "error", "known-fail") or item.technique == "negative")
                ):
                    dead = await self._dead_after(item, result)
                if not dead and self._runaway:
                    dead = self._given_up(item, self._runaway)
            if not dead:
                end = await self.liveness("end")
                if not end.alive:
                    report.problems.append(f"the target was dead at the end of the run: {end.detail}")
            if report.target_died_after is not None and not self._reached:
                report.unreachable = True
        except (asyncio.CancelledError, KeyboardInterrupt):
            report.interrupted = True
            report.problems.append("the run was interrupted; this report is partial")
        finally:
            self._stale_known_failing()
            report.duration = time.monotonic() - t0
        return report

    async def _dead_after(self, item: Case, result: CaseResult) -> bool:
        """The liveness check after a case; True (and recorded once) when the target is found dead: it
        does not answer, or it sends no initial RESPONSE, which the case failed for, on a fresh
        connection either."""
        check = await self.liveness(f"after:{item.id}")
        no_initial = (
            check.alive
            and not self._initial_seen
            and any(v.clause == "connect.initial-response" for v in result.violations)
        )
        if check.alive and not no_initial:
            return False
        detail = "it sends no initial RESPONSE on a fresh connection" if check.alive else check.detail
        return self._given_up(item, f"the target died during case {item.id}: {detail}")

    def _given_up(self, item: Case, problem: str) -> bool:
        """The target is found dead or runaway after ``item``: recorded once; the rest is not judged."""
        self.report.target_died_after = item.id
        self.report.problems.append(problem)
        self._dead_reason = f"{problem}; a target that answers as the protocol says would judge this case"
        return True

    def _stale_known_failing(self) -> None:
        for result in self.report.results:
            if result.outcome == "fixed":
                self.report.problems.append(
                    f"case {result.id} is listed as known failing but passed: remove its entry"
                )

    def _blank(self, item: Case, outcome: Outcome, reason: str) -> CaseResult:
        config = self.config
        known = config.known_failing.matches(item.id)
        return blank_result(item, outcome, reason, config.seed, config.options, self.reproduce(item), known)

    def reproduce(self, item: Case) -> str:
        config = self.config
        words = [*config.reproduce_prefix]
        if not config.options.embedded:
            words.append(config.options.address)
        words += ["--select", item.id, "--seed", str(config.seed), *config.reproduce_options]
        return shlex.join(words)

    async def run_case(self, item: Case) -> CaseResult:
        """Run one case to its outcome (never raises, except on interruption)."""
        options = self.config.options
        result = self._blank(item, Outcome.PASS, "")
        if self.events.case_started:
            self.events.case_started(item)
        if item.hazard not in options.allowed_hazards:
            result.outcome = Outcome.SKIP
            result.reason = f"{item.hazard} case on {options.robot} target without --allow-motion"
            return result
        ctx = CaseContext(
            case_id=item.id,
            level=item.level,
            seed=result.seed,
            options=options,
            connector=self.connect,
            clauses=item.clauses,
            world=self.config.world,
            reproduce=result.reproduce,
        )
        failure: CaseFailure | None = None
        clock = asyncio.get_running_loop().time  # the clock of every deadline (virtual when simulated)
        start = clock()
        scope: asyncio.Timeout | None = None
        try:
            async with asyncio.timeout(result.deadline) as scope:
                ctx.deadline_scope = scope
                await item.function(ctx)
                if ctx.auto_check:
                    for probe in ctx.probes:
                        ctx.check(
                            check_transcript(probe.packets, rfc_packet_no=probe.rfc_packet_no), clauses=()
                        )
        except CaseFailure as exc:
            failure = exc
        except CaseSkipped as exc:
            result.outcome = Outcome.SKIP
            result.reason = exc.reason
        except CaseNotJudged as exc:
            result.outcome = Outcome.NOT_JUDGED
            result.reason = exc.reason
        except ConditionUnsupported as exc:
            result.outcome = Outcome.NOT_JUDGED
            result.reason = f"{exc}; a world that can would judge it"
        except WorldError as exc:
            result.outcome = Outcome.ERROR
            result.reason = f"the world failed: {exc}"
        except TimeoutError as exc:
            if scope is None or not scope.expired():
                result.outcome = Outcome.ERROR
                result.reason = f"TimeoutError inside the case: {exc}"
                result.traceback = traceback.format_exc()
                failure = None
            else:
                failure = _found_by_then(ctx) or CaseFailure(
                    f"the case did not finish within its deadline of {result.deadline:g} s",
                    expected=f"the exchange to finish within {result.deadline:g} s",
                    actual=f"still running after {clock() - start:.2f} s",
                    kind="deadline",
                )
        except (asyncio.CancelledError, KeyboardInterrupt):
            await _quietly(ctx.close_all())
            raise
        except Exception as exc:
            result.outcome = Outcome.ERROR
            result.reason = f"{type(exc).__name__}: {exc}"
            result.traceback = traceback.format_exc()
        finally:
            result.duration = clock() - start
        await _quietly(ctx.close_all())
        self._note_reached(ctx)
        self._watch_runaway(item, ctx, result, failed=failure is not None)
        result.notes = list(ctx.notes)
        result.packets = list(ctx.transcript if ctx.shown_packets is None else ctx.shown_packets)
        self._judge(result, ctx, failure)
        self._check_attribution(result, ctx, failure)
        return result

    def _watch_runaway(self, item: Case, ctx: CaseContext, result: CaseResult, *, failed: bool) -> None:
        """Note a case that failed under a flood of :data:`RUNAWAY_PACKETS` or more (the run then gives
        the target up)."""
        if ctx.received >= RUNAWAY_PACKETS and (failed or result.outcome == "error"):
            ctx.note(f"the target sent {ctx.received:,} packets in this case")
            self._runaway = (
                f"the target ran away during case {item.id}: {ctx.received:,} packets "
                f"in {result.duration:.1f} s, and the case could not finish"
            )

    @staticmethod
    def _check_attribution(result: CaseResult, ctx: CaseContext, failure: CaseFailure | None) -> None:
        """A violation of a clause the case does not declare (and no invariant reported) is a bug of
        the suite, whichever way it was raised: the case ends as ``error`` naming case and clause."""
        reported = [(s.clause, s.invariant) for s in ctx.recorded]
        if failure is not None:
            reported.insert(0, (failure.clause, failure.invariant))
        for clause, invariant in reported:
            problem = attribution_problem(result.id, result.clauses, clause, invariant)
            if problem is not None:
                result.outcome = Outcome.ERROR
                result.reason = f"bug of the suite: {problem}"
                return

    def _judge(self, result: CaseResult, ctx: CaseContext, failure: CaseFailure | None) -> None:
        stopped = None if failure is None else replace(failure.violation, level=failure.level or result.level)
        result.reached = tuple(sorted(ctx.reached))
        conclude(result, stopped, ctx.recorded, self.config.options.strict)


def _found_by_then(ctx: CaseContext) -> CaseFailure | None:
    """At a case's deadline: the first MUST violation of what was recorded by then (a target that floods
    the case with extra replies broke a clause the transcript shows), else None."""
    if not ctx.auto_check:
        return None
    try:
        for probe in ctx.probes:
            ctx.check(check_transcript(probe.packets, rfc_packet_no=probe.rfc_packet_no))
    except CaseFailure as exc:
        return exc
    return None


async def _quietly(awaitable: object) -> None:
    """Await cleanup with a bound, swallowing what the dying target throws at it."""
    try:
        async with asyncio.timeout(CLOSE_GRACE):
            await awaitable  # type: ignore[misc]
    except Exception:
        pass
