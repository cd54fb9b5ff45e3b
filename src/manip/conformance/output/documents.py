"""Every report a judging command writes (``run``, ``client``, ``verify``, ``replay``, ``fuzz``), declared
once: :data:`REPORT_FORMATS` names each format with its option and its writer, :class:`ReportPaths` is
what a command was asked for, and :func:`write_reports` writes them all.  The options themselves come
from one decorator (``manip.conformance.cli_options.report_options``), so each command gets every
format.  ``manip-conform report REPORT.json`` renders a saved JSON report as the HTML and Markdown
documents do (:func:`render_saved`).

Adding a format: its writer (a function of a :class:`RunReport` and a path, writing the file whole or
not at all) and one :class:`ReportFormat` row here.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from manip.conformance.output.html import render_html
from manip.conformance.output.markdown import render_markdown
from manip.conformance.output.report import report_json, write_json, write_junit
from manip.conformance.output.report_view import ReportError, load_report
from manip.conformance.suite.results import RunReport
from manip.outfile import OutputError, atomic_output

__all__ = [
    "REPORT_FORMATS",
    "ReportError",
    "ReportFormat",
    "ReportPaths",
    "render_saved",
    "write_documents",
    "write_reports",
]


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


def _write_html(report: RunReport, path: Path) -> None:
    write_documents(report, path, None)


def _write_markdown(report: RunReport, path: Path) -> None:
    write_documents(report, None, path)


@dataclass(frozen=True)
class ReportFormat:
    """One kind of report: its name, the option that asks for it, and its writer."""

    name: str
    """The option without its dashes, and the keyword of ``check_output_paths``."""
    help: str
    write: Callable[[RunReport, Path], None]
    from_data: bool = False
    """It is rendered from the JSON report's data, so ``manip-conform report`` renders a saved one."""

    @property
    def option(self) -> str:
        return f"--{self.name}"


REPORT_FORMATS: tuple[ReportFormat, ...] = (
    ReportFormat("json", "Write the JSON report.", write_json),
    ReportFormat("junit", "Write JUnit XML.", write_junit),
    ReportFormat(
        "html",
        "Write a one-file HTML report (opens offline: summary, failures by clause, every case's packets).",
        _write_html,
        from_data=True,
    ),
    ReportFormat(
        "markdown",
        "Write a Markdown summary (for CI step summaries: counts, failures by clause, reproduce lines).",
        _write_markdown,
        from_data=True,
    ),
)


@dataclass(frozen=True)
class ReportPaths:
    """The reports a command was asked for: a file per format name (:data:`REPORT_FORMATS`)."""

    paths: Mapping[str, Path] = field(default_factory=dict)

    def get(self, name: str) -> Path | None:
        return self.paths.get(name)


def write_reports(report: RunReport, reports: ReportPaths) -> list[str]:
    """Every report asked for; what could not be written, one message each (the path and why).  A
    report is written whole or not at all, and one that fails does not keep the others from being
    written."""
    problems = []
    for form in REPORT_FORMATS:
        path = reports.get(form.name)
        if path is None:
            continue
        try:
            form.write(report, path)
        except OSError as exc:
            problems.append(str(exc) if isinstance(exc, OutputError) else f"cannot write {path}: {exc}")
    return problems
