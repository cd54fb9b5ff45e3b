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
from typing import Any

from rich.console import Console
from rich.markup import escape

from manip.conformance.cougar.target import CougarTarget
from manip.conformance.output.console import progress_bar
from manip.conformance.output.run_console import counts_text, headline, shown
from manip.conformance.puma.target import PumaTarget, PumaUnreachableError
from manip.conformance.replay.cli import recording
from manip.conformance.suite.case import Case
from manip.conformance.suite.context import RunOptions
from manip.conformance.suite.embedded import EmbeddedServer, simulated_environment
from manip.conformance.suite.results import CaseResult, ExitCode, LivenessCheck, RunReport
from manip.conformance.suite.runner import RunConfig, RunEvents, Runner
from manip.conformance.suite.stability import instability, repeat_seeds
from manip.conformance.suite.world import WorldError
from manip.conformance.suite.world_link import DEFAULT_ANSWER_TIMEOUT, open_world
from manip.conformance.suite.world_prompt import PROMPT_TIMEOUT, PromptWorld
from manip.links import virtual_clock
from manip.reference_server import ServerConfig

__all__ = ["WorldSpec", "execute", "repeat_run", "world_of"]


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


def execute(
    config: RunConfig,
    cases: Sequence[Case],
    faults: Any,
    holder: dict[str, Runner],
    console: Console,
    quiet: bool,
    cougar: CougarTarget | PumaTarget | None = None,
    record: Path | None = None,
    world: WorldSpec | None = None,
) -> int | None:
    """Run; None means "use the report's exit code"."""
    try:
        virtual_clock.run(
            _run_async(config, cases, faults, holder, console, quiet, cougar, record, world),
            virtual=config.virtual_time,
        )
    except WorldError as exc:
        console.print(f"[bold red]world unusable[/]: {escape(str(exc))}")
        return int(ExitCode.UNREACHABLE)
    except PumaUnreachableError as exc:
        console.print(f"[bold red]target unreachable[/]: {escape(str(exc))}")
        return int(ExitCode.UNREACHABLE)
    except KeyboardInterrupt:
        if "runner" in holder:
            holder["runner"].report.interrupted = True
            problems = holder["runner"].report.problems
            if not any("interrupted" in p for p in problems):
                problems.append("the run was interrupted; this report is partial")
        console.print("[bold]interrupted[/]: the report is partial")
        return int(ExitCode.INTERNAL)
    except Exception as exc:  # an internal error of the suite: keep what was done
        text = traceback.format_exc()
        console.print(f"[bold magenta]internal error[/]: {type(exc).__name__}: {escape(str(exc))}")
        if "runner" in holder:
            holder["runner"].report.internal_error = text
        else:
            console.print(text, markup=False)
        return int(ExitCode.INTERNAL)
    return None


def repeat_run(
    config: RunConfig,
    cases: Sequence[Case],
    faults: Any,
    console: Console,
    quiet: bool,
    cougar: CougarTarget | PumaTarget | None,
    runs: int,
    world: WorldSpec | None = None,
) -> tuple[RunReport | None, int | None]:
    """``--repeat``: the selection with ``runs`` seeds, then the first seed again; the first run's report
    carries what changed between them (:mod:`manip.conformance.suite.stability`)."""
    seeds = repeat_seeds(config.seed, runs)
    reports: list[RunReport] = []
    worst: int | None = None
    for number, seed in enumerate([*seeds, seeds[0]], start=1):
        holder: dict[str, Runner] = {}
        run_config = replace(config, seed=seed, options=replace(config.options))
        code = execute(run_config, cases, faults, holder, console, True, cougar=cougar, world=world)
        if "runner" not in holder:
            return None, code
        report = holder["runner"].report
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
    if not quiet:
        console.print(f"{len(reports)} runs, {len(first.unstable)} stability problem(s)", markup=False)
    return first, None


async def _run_async(
    config: RunConfig,
    cases: Sequence[Case],
    faults: Any,
    holder: dict[str, Runner],
    console: Console,
    quiet: bool,
    cougar: CougarTarget | PumaTarget | None,
    record: Path | None,
    world: WorldSpec | None,
) -> None:
    # The recording starts on the run's loop, so a simulated run records on its virtual clock.
    how = "manip-conform run (client side)"
    with recording(record, how=how, seed=config.seed, virtual=config.virtual_time) as wrap:
        config.wrap_link = wrap
        await _run_target(config, cases, faults, holder, console, quiet, cougar, world)


@contextlib.asynccontextmanager
async def _opened_world(config: RunConfig, world: WorldSpec | None, console: Console) -> AsyncIterator[None]:
    """HOST's world (``--world``) for the block, as the run's (nothing without one)."""
    if world is None:
        yield
        return
    async with open_world(world.spec, answer_timeout=world.timeout) as opened:
        config.world = opened
        console.print(f"world: {opened.description}", markup=False)
        yield


async def _run_target(
    config: RunConfig,
    cases: Sequence[Case],
    faults: Any,
    holder: dict[str, Runner],
    console: Console,
    quiet: bool,
    cougar: CougarTarget | PumaTarget | None,
    world: WorldSpec | None = None,
) -> None:
    if isinstance(cougar, PumaTarget):  # --puma: the suite plays Cougar for the Puma
        await _run_puma(config, cases, holder, console, quiet, cougar, world)
        return
    if cougar is not None:  # --cougar: the Cougar target (embedded or not)
        async with cougar.running() as address:
            config.address = address
            config.options = _with_address(config.options, address)
            if cougar.embedded:
                console.print(f"embedded simulated Cougar at {address}", markup=False)
            await _run_with(config, cases, holder, console, quiet)
        return
    if not config.embedded:
        async with _opened_world(config, world, console):
            await _run_with(config, cases, holder, console, quiet)
        return
    server_config = ServerConfig() if faults is None else ServerConfig(faults=faults)
    # The embedded robot has the simulated Cougar wrist, so the wrist opcodes are checked too.
    if config.virtual_time:
        async with simulated_environment(
            server_config, seed=config.seed, wrist=True, broken_after=config.options.broken_after
        ) as environment:
            address = environment.address
            config.address = address
            config.world = environment.world
            config.options = replace(config.options, address=address, embedded=True)
            console.print("embedded reference server in virtual time (with the simulated Cougar wrist)")
            await _run_with(config, cases, holder, console, quiet)
        return
    embedded = EmbeddedServer(server_config, wrist=True, broken_after=config.options.broken_after)
    with embedded as address:
        config.address = address
        config.world = embedded.environment.world if embedded.environment is not None else None
        config.options = replace(config.options, address=address, embedded=True)
        console.print(
            f"embedded reference server at {address} (with the simulated Cougar wrist)", markup=False
        )
        await _run_with(config, cases, holder, console, quiet)


async def _run_puma(
    config: RunConfig,
    cases: Sequence[Case],
    holder: dict[str, Runner],
    console: Console,
    quiet: bool,
    puma: PumaTarget,
    world: WorldSpec | None = None,
) -> None:
    if puma.host is not None:
        console.print(
            f"judging Cougar listening on {puma.wrist_listen}: waiting up to {puma.wrist_wait:g} s for the "
            f"Puma's wrist link (manip-server --cougar {puma.wrist_listen})",
            markup=False,
        )
    async with puma.running_with_world(config.seed) as (address, own_world):
        config.address = address
        config.world = own_world or config.world
        config.options = _with_address(config.options, address)
        if puma.embedded:
            how = "in virtual time" if config.virtual_time else f"at {address}"
            console.print(
                f"embedded reference server {how}, its wrist played by the judging Cougar", markup=False
            )
        else:
            console.print(f"the Puma's wrist link is up; judging {address}", markup=False)
        async with _opened_world(config, world, console):  # HOST's, once it is up
            await _run_with(config, cases, holder, console, quiet)


def _with_address(options: RunOptions, address: str) -> RunOptions:
    return replace(options, address=address)


async def _run_with(
    config: RunConfig, cases: Sequence[Case], holder: dict[str, Runner], console: Console, quiet: bool
) -> None:
    progress = progress_bar(
        console, quiet or isinstance(config.world, PromptWorld)
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

    runner = Runner(config, cases, RunEvents(started, case_started, case_finished, liveness))
    holder["runner"] = runner
    with progress:
        await runner.run()
