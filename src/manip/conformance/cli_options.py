"""Command-line options the judging commands share (``run``, ``client``, ``verify``, ``replay``,
``fuzz``), defined once so that each means the same and reads the same in every ``--help``, and the
checks of what they were given (a selection that matches no case, a report path that cannot be written),
made before anything runs."""

from __future__ import annotations

import difflib
import functools
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar, cast

import click
from click.core import ParameterSource

from manip.conformance.cougar.target import cougar_cases
from manip.conformance.output.documents import REPORT_FORMATS, ReportFormat, ReportPaths
from manip.conformance.suite.case import Case, all_cases
from manip.conformance.suite.selection import PatternSet, match_id
from manip.spec import SPEC, UnknownClauseError

F = TypeVar("F", bound=Callable[..., Any])

__all__ = [
    "cases_of_clauses",
    "check_output_paths",
    "check_selection",
    "close_case_ids",
    "document_options",
    "given",
    "known_failing_option",
    "report_options",
    "select_option",
    "skip_option",
    "strict_option",
]

select_option = click.option(
    "--select",
    "--case",
    "select",
    multiple=True,
    metavar="PATTERN",
    help="Run only cases matching PATTERN (glob per dot component, ** any depth; @FILE reads a list).",
)
skip_option = click.option(
    "--skip", "skip", multiple=True, metavar="PATTERN", help="Leave out cases matching PATTERN."
)
known_failing_option = click.option(
    "--known-failing",
    "known_failing",
    multiple=True,
    metavar="@FILE|PATTERN",
    help="Cases expected to fail: they still run; entries matching nothing or now passing fail the run.",
)
strict_option = click.option(
    "--strict", is_flag=True, help="SHOULD failures count (without it they are warnings)."
)


def _format_options(forms: Sequence[ReportFormat]) -> Callable[[F], F]:
    def decorate(function: F) -> F:
        @functools.wraps(function)
        def command(*args: Any, **kwargs: Any) -> Any:
            given_paths = {form.name: kwargs.pop(f"{form.name}_path") for form in forms}
            reports = ReportPaths({name: path for name, path in given_paths.items() if path is not None})
            return function(*args, reports=reports, **kwargs)

        for form in reversed(forms):
            command = click.option(
                form.option,
                f"{form.name}_path",
                type=click.Path(dir_okay=False, path_type=Path),
                metavar="FILE",
                help=form.help,
            )(command)
        return cast(F, command)

    return decorate


report_options = _format_options(REPORT_FORMATS)
"""An option per report format (:data:`~manip.conformance.output.documents.REPORT_FORMATS`: ``--json``,
``--junit``, ``--html``, ``--markdown``), given to the command as one ``reports`` parameter
(:class:`~manip.conformance.output.documents.ReportPaths`)."""
document_options = _format_options([form for form in REPORT_FORMATS if form.from_data])
"""The options of the formats rendered from a JSON report's data (``manip-conform report``)."""


def given(name: str) -> bool:
    """Whether the current command's parameter ``name`` was given (command line or environment), not
    left at its default."""
    source = click.get_current_context().get_parameter_source(name)
    return source is not None and source not in (ParameterSource.DEFAULT, ParameterSource.DEFAULT_MAP)


def check_output_paths(**paths: Path | None) -> None:
    """Fail early (usage error) when a file an option names cannot be written, before the run starts
    rather than with a traceback at its end.  Keywords name the options: ``json=``, ``junit=``,
    ``record=`` check ``--json``, ``--junit``, ``--record``."""
    for name, path in paths.items():
        if path is None:
            continue
        option = "--" + name.replace("_", "-")
        resolved = path.resolve()
        parent = resolved.parent
        if resolved.is_dir():
            raise click.UsageError(f"{option}: {path} is a directory (give a file name)")
        if not parent.exists():
            raise click.UsageError(f"{option}: the directory {parent} of {path} does not exist")
        if not parent.is_dir():
            raise click.UsageError(f"{option}: {parent} (the directory of {path}) is not a directory")
        if resolved.exists() and not os.access(resolved, os.W_OK):
            raise click.UsageError(f"{option}: {path} exists and is not writable")
        if not resolved.exists() and not os.access(parent, os.W_OK | os.X_OK):
            raise click.UsageError(f"{option}: cannot create files in {parent} (permission denied)")


def check_selection(
    select: PatternSet,
    skip: PatternSet,
    cases: Sequence[Case],
    *,
    cougar: bool = False,
    hint: str = " (manip-conform cases lists every case)",
) -> None:
    """A usage error when a ``--select`` pattern matches none of ``cases``, or when ``--select`` and
    ``--skip`` together leave no case: a run of nothing would pass, and say nothing of the typo."""
    ids = sorted(c.id for c in cases)
    for pattern in select.patterns:
        if any(match_id(pattern.text, case_id) for case_id in ids):
            continue
        where = "" if pattern.source == "--select" else f" ({pattern.source})"
        message = f"--select {pattern.text!r}{where} matches no case"
        others = [c.id for c in all_cases() if c.id not in ids and match_id(pattern.text, c.id)]
        if others:
            mode = "--cougar" if not cougar else "a server run (without --cougar)"
            if others[0].startswith("client."):
                mode = "manip-conform client"
            message += f" of this run: it names {len(others)} case(s) of {mode}, such as {others[0]}"
        elif close := close_case_ids(pattern.text, ids):
            message += f"; close matches: {', '.join(close)}"
        else:
            areas = sorted({case_id.split(".")[0] + ".*" for case_id in ids})
            message += f"; the case ids are under {', '.join(areas)}"
        raise click.UsageError(message + hint)
    if any((not select or select.matches(i)) and not skip.matches(i) for i in ids):
        return
    options = [f"--select {p.text}" for p in select.patterns] + [f"--skip {p.text}" for p in skip.patterns]
    verb = "leave" if len(options) > 1 else "leaves"
    raise click.UsageError(f"{' '.join(options)} {verb} no case to run")


def cases_of_clauses(clauses: Sequence[str], *, cougar: bool = False) -> list[str]:
    """The ids of the cases (of a Cougar run, or of a server run) that check any of ``clauses``; a usage
    error names an id the spec does not have, with close matches, or a clause no case checks."""
    cases = cougar_cases(all_cases(), cougar=cougar)
    ids: list[str] = []
    for clause in clauses:
        try:
            SPEC.clause(clause)
        except UnknownClauseError as exc:
            raise click.UsageError(f"--clause: {exc}") from None
        checking = [c.id for c in cases if clause in c.clauses]
        if not checking:
            run = "a Cougar run" if cougar else "a server run"
            raise click.UsageError(
                f"--clause {clause}: no case of {run} checks it (manip-conform coverage shows which do)"
            )
        ids += checking
    return ids


def close_case_ids(pattern: str, ids: Sequence[str], limit: int = 3) -> list[str]:
    """Case ids (or the areas above them: ``server.reply``) that look like ``pattern``, its wildcards
    left out, the closest first."""
    names = set(ids)
    for case_id in ids:
        parts = case_id.split(".")
        names.update(".".join(parts[:n]) for n in range(1, len(parts)))
    stem = ".".join(p for p in pattern.split(".") if not any(ch in p for ch in "*?["))
    close = difflib.get_close_matches(stem or pattern, sorted(names), n=limit, cutoff=0.6)
    return close
