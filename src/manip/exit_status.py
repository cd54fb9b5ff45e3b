"""The exit statuses of every manip command, in one table.

Each command's ``--help`` shows its row (:func:`epilog`), the README's table is this table
(:func:`markdown_table`; ``tests/project/test_exit_status.py`` holds the README, each ``--help`` and each
command's behaviour to it).  The numbers mean the same thing everywhere: 0 the command did what was
asked and found nothing wrong, 1 it found something wrong (a failure, a malformed input, a file it could
not use), 2 the command line was wrong (a bad option or value, an input file that does not exist), 3 the
peer could not be reached, 4 the command was interrupted or failed itself.  Like
:mod:`manip.commandline`, this module sits outside the layers (it imports nothing of manip).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Final

__all__ = ["EXIT_STATUSES", "epilog", "markdown_table"]

Row = tuple[tuple[int, str], ...]

_USAGE: Final = (
    "usage error: a bad option or value, an input file that does not exist, a report that cannot be written"
)

EXIT_STATUSES: Final[Mapping[str, Row]] = {
    "manip-conform run": (
        (0, "conformant"),
        (
            1,
            "non-conformant: a failure, a stale --known-failing entry, the target died or broke the exchange",
        ),
        (2, _USAGE),
        (3, "target unreachable: nothing it sent reached the run"),
        (4, "interrupted, internal error, or an unstable suite (--repeat); a partial report is written"),
    ),
    "manip-conform verify, replay": (
        (0, "conformant (replay: every answer as recorded)"),
        (1, "non-conformant, or a replayed answer differs from the recording"),
        (2, _USAGE),
        (3, "the capture cannot be read, is damaged or holds no session; the target unreachable"),
        (4, "interrupted or internal error"),
    ),
    "manip-conform client": (
        (0, "conformant (unsupported cases do not count)"),
        (1, "non-conformant: a failure, a stale --known-failing entry"),
        (2, _USAGE),
        (3, "the harness could not be started, or its hello was not the contract's"),
        (4, "interrupted or internal error"),
    ),
    "manip-conform fuzz": (
        (0, "no violation"),
        (1, "violations: a crash, hang, traceback, silent drop, wrong answer or uncounted drop"),
        (2, _USAGE),
        (3, "target unreachable (no liveness check passed before the first batch)"),
        (4, "interrupted, or an internal error of the fuzzer"),
    ),
    "manip-conform diff": (
        (0, "no difference that fails: none, or only ones both sides may show (gaps: --allow-unexplained)"),
        (1, "a violation (one side breaks a clause), or a difference no clause or erratum explains"),
        (2, _USAGE),
        (3, "a side unreachable (no connection, or Here not answered, before the first stream)"),
        (4, "interrupted, or an internal error of the diff; a partial report is written"),
    ),
    "manip-conform coverage": (
        (0, "every MUST clause in scope has a case"),
        (1, "a MUST clause in scope has none"),
        (2, _USAGE),
    ),
    "manip-conform cases, report": (
        (0, "listed, or the documents written"),
        (2, "usage error: a bad option, a file that does not exist or is not a report"),
    ),
    "manip-client": (
        (0, "success (watch: also when stopped with Ctrl-C)"),
        (1, "the server answered with an error, or a reply that could not be read"),
        (2, "usage error: bad arguments or URL, a --record FILE that cannot be created or written"),
        (3, "cannot connect, or the connection was lost"),
        (4, "no reply within --timeout"),
        (130, "interrupted"),
    ),
    "manip-server": (
        (0, "stopped by SIGINT or SIGTERM"),
        (1, "cannot listen, or cannot create or write the --record file"),
        (2, "usage error: a bad option, an unknown fault, a bad address"),
    ),
    "manip-cougar": (
        (0, "stopped by SIGINT or SIGTERM"),
        (1, "cannot listen"),
        (2, "usage error: a bad option, an unknown fault, a bad address"),
    ),
    "manip-capture": (
        (0, "done"),
        (1, "a capture cannot be read, written, recovered, imported or exported; the proxy cannot listen"),
        (2, _USAGE),
    ),
    "manip-decode": (
        (0, "decoded"),
        (1, "malformed or empty input (the message says where and why), or a --filter that selects nothing"),
        (2, _USAGE),
    ),
}  # fmt: skip
"""Command (or subcommands sharing a row) -> its exit statuses and what each means."""


def epilog(command: str) -> str:
    """The ``Exit status:`` block of ``command``'s ``--help`` (click keeps its lines as they are)."""
    width = max(len(str(code)) for code, _ in EXIT_STATUSES[command])
    lines = [f"  {code:<{width}}  {meaning}" for code, meaning in EXIT_STATUSES[command]]
    return "\b\nExit status:\n" + "\n".join(lines)


def markdown_table() -> str:
    """The README's table: one row per command, one column per status."""
    codes = sorted({code for row in EXIT_STATUSES.values() for code, _ in row})
    lines = [
        "| command | " + " | ".join(str(code) for code in codes) + " |",
        "|---|" + "---|" * len(codes),
    ]
    for command, row in EXIT_STATUSES.items():
        meanings = dict(row)
        cells = [meanings.get(code, "") for code in codes]
        lines.append(f"| `{command}` | " + " | ".join(cells) + " |")
    return "\n".join(lines)
