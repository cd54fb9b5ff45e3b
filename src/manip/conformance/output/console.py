"""The rich consoles of the manip commands: styled on a terminal, plain text anywhere else.

Rich wraps every line at the console width, and when the stream is not a terminal it takes 80
columns: a ``reproduce:`` line, a hex dump or a path written to a pipe or a CI log would come out
broken in two.  So a console made here never wraps a printed line (``soft_wrap``: a terminal folds a
long line for display, but it stays one line when copied), and when its stream is not a terminal it
has no width limit and writes no colour or style codes, whatever the environment asks (``FORCE_COLOR``,
``TTY_COMPATIBLE``): a line of output is a line of the file.  A table (:func:`print_table`) is drawn
only on a terminal; anywhere else it is one record per line, its fields separated by tabs, under a
header line of the column names, never padded.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable, Sequence
from typing import Final, TextIO

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table
from rich.text import Text

__all__ = ["UNLIMITED_WIDTH", "make_console", "print_table", "progress_bar", "stream_is_terminal"]

UNLIMITED_WIDTH: Final = 1_000_000
"""The width of a console whose stream is not a terminal: wider than any line or table we print."""


def stream_is_terminal(stream: TextIO) -> bool:
    """Whether ``stream`` is a terminal (a stream without ``isatty``, or a closed one, is not)."""
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):
        return False


def make_console(*, stderr: bool = False, min_width: int = 0) -> Console:
    """A console on stdout (``stderr``: on stderr).  ``min_width``: on a terminal, lay tables out at
    least this wide (a narrower terminal folds their lines) rather than squeezing their columns."""
    stream = sys.stderr if stderr else sys.stdout
    if stream_is_terminal(stream):
        console = Console(stderr=stderr, highlight=False, soft_wrap=True)
        if min_width and console.width < min_width:
            console = Console(stderr=stderr, highlight=False, soft_wrap=True, width=min_width)
        return console
    return Console(
        stderr=stderr,
        force_terminal=False,
        force_interactive=False,
        color_system=None,
        no_color=True,
        highlight=False,
        soft_wrap=True,
        width=UNLIMITED_WIDTH,
        emoji=False,
    )


def progress_bar(console: Console, quiet: bool) -> Progress:
    """The progress bar of a long command (what runs, done of total, time so far): on a terminal only,
    and gone once the command ends (its own lines stay)."""
    return Progress(
        TextColumn("[progress.description]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=console,
        transient=True,
        disable=quiet or not console.is_terminal,
    )


def print_table(console: Console, title: str, columns: Sequence[str], rows: Iterable[Sequence[str]]) -> None:
    """A table on a terminal; elsewhere the column names, then one record per line, tab-separated, with
    no padding and no markup (cells may hold console markup, shown on a terminal only)."""
    if console.is_terminal:
        table = Table(title=title, show_lines=False)
        for column in columns:
            table.add_column(column)
        for row in rows:
            table.add_row(*row)
        console.print(table)
        return
    out = console.file  # written as is: the console would expand the tabs into padding
    out.write("\t".join(columns) + "\n")
    for row in rows:
        out.write("\t".join(Text.from_markup(cell).plain.replace("\t", " ") for cell in row) + "\n")
