"""Where ``manip-conform run`` sends its cases: the target dispatch.

:func:`execute` runs a configured run to its end and turns what can go wrong around it (a world or a
Puma that cannot be reached, an interruption, an internal error of the suite) into an exit status, the
report kept.  The target is one of: a server at HOST (with HOST's world, ``--world``); the embedded
reference server (in virtual time, or on a thread in real time), whose world is its own; a Cougar
(``--cougar``); or the Puma's wrist side (``--puma``), the suite playing Cougar.  :func:`repeat_run` is
``--repeat``: the same selection over several seeds, and what changed between them.
"""

from __future__ import annotations

import contextlib
import traceback
from collections.abc import AsyncIterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from rich.console import Console
from rich.markup import escape

from manip.conformance.cougar.target import CougarTarget
from manip.conformance.output.console import progress_bar
from manip.conformance.output.run_console import counts_text, headline, shown
from manip.conformance.puma.target import PumaTarget, PumaUnreachableError
from manip.conformance.replay.cli import recording
from manip.conformance.suite.case import Case
from manip.conformance.suite.embedded import EmbeddedServer, simulated_environment
from manip.conformance.suite.results import CaseResult, ExitCode, LivenessCheck, RunReport
from manip.conformance.suite.runner import RunConfig, RunEvents, Runner
from manip.conformance.suite.stability import instability, repeat_seeds
from manip.conformance.suite.world import WorldError
from manip.conformance.suite.world_link import DEFAULT_ANSWER_TIMEOUT, open_world
from manip.conformance.suite.world_prompt import PROMPT_TIMEOUT, PromptWorld
from manip.links import virtual_clock
from manip.reference_server import FaultSet
from manip.reference_server.session import server_config as profile_config

__all__ = ["Job", "WorldSpec", "execute", "repeat_run", "world_of"]


@dataclass(frozen=True)
class WorldSpec:
    """``--world`` and ``--world-timeout`` as given."""

    spec: str
    timeout: float


def world_of(world: str | None, timeout: float | None) -> WorldSpec | None:
    if world is None:
        return None
    default = PROMPT_TIMEOUT if world == "prompt" else DEFAULT_ANSWER_TIMEOUT
    return WorldSpec(world, default if timeout is None else timeout)


@dataclass
class Job:
    """One run as the dispatch carries it: its configuration and cases, the embedded server's faults,
    where it prints, the target it goes to (a Cougar, the Puma's wrist side, else the server), HOST's
    world, and its runner once it has one (whose report survives an interruption)."""

    config: RunConfig
    cases: Sequence[Case]
    console: Console
    quiet: bool = False
    faults: FaultSet | None = None
    target: CougarTarget | PumaTarget | None = None
    server_profile: str = "manip"
    """The embedded server's profile, ``manip`` or ``guide``
    (:func:`~manip.reference_server.session.server_config`)."""
    world: WorldSpec | None = None
    runner: Runner | None = None

    @property
    def report(self) -> RunReport | None:
        return self.runner.report if self.runner is not None else None


def execute(job: Job, record: Path | None = None) -> int | None:
    """Run ``job`` to its end (recorded to ``record``); an exit status when something around the run
    failed, None to use the report's."""
    console = job.console
    try:
        virtual_clock.run(_run_recorded(job, record), virtual=job.config.virtual_time)
    except WorldError as exc:
        console.print(f"[bold red]world unusable[/]: {escape(str(exc))}")
        return int(ExitCode.UNREACHABLE)
    except PumaUnreachableError as exc:
        console.print(f"[bold red]target unreachable[/]: {escape(str(exc))}")
        return int(ExitCode.UNREACHABLE)
    except KeyboardInterrupt:
        if job.report is not None:
            job.report.interrupted = True
            if not any("interrupted" in p for p in job.report.problems):
                job.report.problems.append("the run was interrupted; this report is partial")
        console.print("[bold]interrupted[/]: the report is partial")
        return int(ExitCode.INTERNAL)
    except Exception as exc:  # an internal error of the suite: keep what was done
        text = traceback.format_exc()
        console.print(f"[bold magenta]internal error[/]: {type(exc).__name__}: {escape(str(exc))}")
        if job.report is not None:
            job.report.internal_error = text
        else:
            console.print(text, markup=False)
        return int(ExitCode.INTERNAL)
    return None


def repeat_run(job: Job, runs: int) -> tuple[RunReport | None, int | None]:
    """``--repeat``: the selection with ``runs`` seeds, then the first seed again; the first run's report
    carries what changed between them (:mod:`manip.conformance.suite.stability`)."""
    config, console = job.config, job.console
    seeds = repeat_seeds(config.seed, runs)
    reports: list[RunReport] = []
    worst: int | None = None
    for number, seed in enumerate([*seeds, seeds[0]], start=1):
        run_config = replace(config, seed=seed, options=replace(config.options))
        one = replace(job, config=run_config, quiet=True, runner=None)
        code = execute(one)
        if one.report is None:
            return None, code
        report = one.report
        reports.append(report)
        if code is not None or report.interrupted:
            return reports[0], code
        again = " (its seed again)" if number == len(seeds) + 1 else ""
        console.print(
            f"run {number}/{len(seeds) + 1}{again}: {report.verdict}, {counts_text(report)}"
            f" in {report.duration:.1f} s; seed {seed}",
            markup=False,
        )
        worst = max(worst or 0, int(report.exit_code))
    first = reports[0]
    first.unstable = instability(reports, compare_packets=config.virtual_time)
    if not first.unstable and worst and worst > int(first.exit_code):
        first.problems.append(f"a repeated run was {ExitCode(worst).name.lower().replace('_', '-')}")
    if not job.quiet:
        console.print(f"{len(reports)} runs, {len(first.unstable)} stability problem(s)", markup=False)
    return first, None


async def _run_recorded(job: Job, record: Path | None) -> None:
    # The recording starts on the run's loop, so a simulated run records on its virtual clock.
    config = job.config
    how = "manip-conform run (client side)"
    with recording(record, how=how, seed=config.seed, virtual=config.virtual_time) as wrap:
        config.wrap_link = wrap
        await _run_target(job)


@contextlib.asynccontextmanager
async def _opened_world(job: Job) -> AsyncIterator[None]:
    """HOST's world (``--world``) for the block, as the run's (nothing without one)."""
    if job.world is None:
        yield
        return
    async with open_world(job.world.spec, answer_timeout=job.world.timeout) as opened:
        job.config.world = opened
        job.console.print(f"world: {opened.description}", markup=False)
        yield


async def _run_target(job: Job) -> None:
    config, target = job.config, job.target
    if isinstance(target, PumaTarget):  # --puma: the suite plays Cougar for the Puma
        await _run_puma(job, target)
        return
    if target is not None:  # --cougar: the Cougar target (embedded or not)
        async with target.running() as address:
            said = f"embedded simulated Cougar at {address}" if target.embedded else ""
            await _run_at(job, address, said)
        return
    if not config.options.embedded:
        async with _opened_world(job):
            await _run_with(job)
        return
    server_config = profile_config(
        job.server_profile, **({} if job.faults is None else {"faults": job.faults})
    )
    # The embedded robot has the simulated Cougar wrist, so the wrist opcodes are checked too.
    broken_after = config.options.broken_after
    if config.virtual_time:
        async with simulated_environment(
            server_config, seed=config.seed, wrist=True, broken_after=broken_after
        ) as environment:
            config.world = environment.world
            said = "embedded reference server in virtual time (with the simulated Cougar wrist)"
            await _run_at(job, environment.address, said)
        return
    embedded = EmbeddedServer(server_config, wrist=True, broken_after=broken_after)
    with embedded as address:
        config.world = embedded.environment.world if embedded.environment is not None else None
        said = f"embedded reference server at {address} (with the simulated Cougar wrist)"
        await _run_at(job, address, said)


async def _run_puma(job: Job, puma: PumaTarget) -> None:
    config, console = job.config, job.console
    if puma.host is not None:
        console.print(
            f"judging Cougar listening on {puma.wrist_listen}: waiting up to {puma.wrist_wait:g} s for the "
            f"Puma's wrist link (manip-server --cougar {puma.wrist_listen})",
            markup=False,
        )
    async with puma.running_with_world(config.seed) as (address, own_world):
        config.world = own_world or config.world
        if puma.embedded:
            how = "in virtual time" if config.virtual_time else f"at {address}"
            said = f"embedded reference server {how}, its wrist played by the judging Cougar"
        else:
            said = f"the Puma's wrist link is up; judging {address}"
        async with _opened_world(job):  # HOST's, once it is up
            await _run_at(job, address, said)


async def _run_at(job: Job, address: str, said: str) -> None:
    """The run against the target now listening at ``address``, once ``said`` (if anything) is
    printed."""
    config = job.config
    config.options = replace(config.options, address=address)
    if said:
        job.console.print(said, markup=False)
    await _run_with(job)


async def _run_with(job: Job) -> None:
    config, quiet = job.config, job.quiet
    progress = progress_bar(
        job.console, quiet or isinstance(config.world, PromptWorld)
    )  # it would hide the questions
    task_id = progress.add_task("conformance", total=0)

    def started(selected: list[Case]) -> None:
        progress.update(task_id, total=len(selected))

    def case_started(item: Case) -> None:
        progress.update(task_id, description=item.id)

    def case_finished(result: CaseResult) -> None:
        # One line as it happens; the details come after the run, below the broken clauses (summary).
        progress.advance(task_id)
        if shown(result, quiet):
            headline(progress.console, result)

    def liveness(check: LivenessCheck) -> None:
        if not check.alive:
            progress.console.print(
                f"[bold red]target not alive[/] ({escape(check.when)}): {escape(check.detail)}"
            )

    job.runner = Runner(config, job.cases, RunEvents(started, case_started, case_finished, liveness))
    with progress:
        await job.runner.run()
