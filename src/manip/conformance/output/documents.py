"""The report documents people open: ``--html FILE`` and ``--markdown FILE`` on every command that
judges (one decorator, :func:`document_options`); ``manip-conform report REPORT.json`` renders a saved
JSON report the same way (:func:`render_saved`).

A command adds both options with ``@document_options`` (its function then takes ``html_path`` and
``markdown_path``), checks the paths with the other outputs before it runs, and ends with
``write_documents(report, html_path, markdown_path)``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

import click

from manip.conformance.output.html import render_html
from manip.conformance.output.markdown import render_markdown
from manip.conformance.output.report import report_json, write_json, write_junit
from manip.conformance.output.report_view import ReportError, load_report
from manip.conformance.suite.results import RunReport
from manip.outfile import OutputError, atomic_output

__all__ = ["ReportError", "document_options", "render_saved", "write_documents", "write_reports"]

F = TypeVar("F", bound=Callable[..., Any])

_html_option = click.option(
    "--html",
    "html_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write a one-file HTML report (opens offline: summary, failures by clause, every case's packets).",
)
_markdown_option = click.option(
    "--markdown",
    "markdown_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write a Markdown summary (for CI step summaries: counts, failures by clause, reproduce lines).",
)


def document_options(function: F) -> F:
    """``--html FILE`` and ``--markdown FILE`` (parameters ``html_path``, ``markdown_path``)."""
    return _html_option(_markdown_option(function))


def write_documents(
    report: RunReport | Mapping[str, Any], html_path: Path | None, markdown_path: Path | None
) -> None:
    """Write the documents asked for, of a run's report or of a JSON report's data."""
    if html_path is None and markdown_path is None:
        return
    data = report_json(report) if isinstance(report, RunReport) else report
    if html_path is not None:
        with atomic_output(html_path) as f:  # whole or not at all; OutputError names the path
            f.write(render_html(data))
    if markdown_path is not None:
        with atomic_output(markdown_path) as f:
            f.write(render_markdown(data))


def render_saved(report_file: Path, html_path: Path | None, markdown_path: Path | None) -> None:
    """Render the JSON report at ``report_file``; :class:`ReportError` says why a file cannot be."""
    data = load_report(report_file)
    try:
        write_documents(data, html_path, markdown_path)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise ReportError(
            f"{report_file} does not hold what a report holds ({type(exc).__name__}: {exc}); "
            "was it edited, or written by another tool?"
        ) from None


def write_reports(
    report: RunReport,
    json_path: Path | None,
    junit_path: Path | None,
    html_path: Path | None = None,
    markdown_path: Path | None = None,
) -> list[str]:
    """Every report asked for; what could not be written, one message each (the path and why).  A
    report is written whole or not at all, and one that fails does not keep the others from being
    written."""
    writers: tuple[tuple[Path | None, Callable[[RunReport, Path], None]], ...] = (
        (json_path, write_json),
        (junit_path, write_junit),
        (html_path, lambda r, path: write_documents(r, path, None)),
        (markdown_path, lambda r, path: write_documents(r, None, path)),
    )
    problems = []
    for path, write in writers:
        if path is None:
            continue
        try:
            write(report, path)
        except OSError as exc:
            problems.append(str(exc) if isinstance(exc, OutputError) else f"cannot write {path}: {exc}")
    return problems
