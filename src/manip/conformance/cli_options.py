"""Command-line options the judging commands share (``run``, ``client``, ``verify``, ``replay``,
``fuzz``), defined once so that each means the same and reads the same in every ``--help``."""

from __future__ import annotations

from pathlib import Path

import click

__all__ = [
    "json_option",
    "junit_option",
    "known_failing_option",
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
json_option = click.option(
    "--json", "json_path", type=click.Path(dir_okay=False, path_type=Path), help="Write the JSON report."
)
junit_option = click.option(
    "--junit", "junit_path", type=click.Path(dir_okay=False, path_type=Path), help="Write JUnit XML."
)
