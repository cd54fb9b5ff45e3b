"""What every manip command shares: ``--version`` and the log format.

Every command (``manip-client``, ``manip-server``, ``manip-cougar``, ``manip-capture``, ``manip-decode``,
``manip-conform``) takes ``--version`` (:func:`version_option`: ``manip-client, version 0.1.0``) and
logs through :func:`configure_logging`, one line a record::

    2026-03-02T14:05:09.123+01:00 INFO manip.reference_server: listening on tcp://127.0.0.1:42085

local time in ISO 8601 with milliseconds and the UTC offset, the level, the logger's name, the message;
to standard error, never coloured.  This module sits outside the layers (it imports only click and the
standard library), so the command of any layer can use it.
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Callable
from datetime import datetime
from typing import Any, Final, TextIO, TypeVar

import click

__all__ = ["LOG_FORMAT", "LogFormatter", "configure_logging", "version_option"]

F = TypeVar("F", bound=Callable[..., Any])

PACKAGE: Final = "manip"
VERSION_MESSAGE: Final = "%(prog)s, version %(version)s"
LOG_FORMAT: Final = "%(asctime)s %(levelname)s %(name)s: %(message)s"


def version_option(prog: str) -> Callable[[F], F]:
    """``--version`` for the command ``prog``: the installed package's version (importlib.metadata,
    read only when asked)."""
    return click.version_option(package_name=PACKAGE, prog_name=prog, message=VERSION_MESSAGE)


class LogFormatter(logging.Formatter):
    """:data:`LOG_FORMAT` with the record's time as local ISO 8601 to the millisecond, with its offset."""

    def __init__(self) -> None:
        super().__init__(LOG_FORMAT)

    def formatTime(self, record: logging.LogRecord, datefmt: str | None = None) -> str:  # noqa: N802
        return datetime.fromtimestamp(record.created).astimezone().isoformat(timespec="milliseconds")


class _StderrHandler(logging.StreamHandler[TextIO]):
    """Writes to whatever ``sys.stderr`` is when a record comes, not what it was when configured (a
    command run in-process, as tests do, swaps it for a while)."""

    def __init__(self) -> None:
        super().__init__(sys.stderr)
        self.setFormatter(LogFormatter())

    @property
    def stream(self) -> TextIO:
        return sys.stderr

    @stream.setter
    def stream(self, value: TextIO) -> None:
        pass


def configure_logging(level: int | str = logging.WARNING) -> None:
    """Log manip's records at ``level`` and above (a level name such as ``"INFO"`` or a number) to
    standard error in the common format.  Calling it again replaces the handler it installed before."""
    root = logging.getLogger()
    for handler in list(root.handlers):
        if isinstance(handler, _StderrHandler):
            root.removeHandler(handler)
    root.addHandler(_StderrHandler())
    root.setLevel(level.upper() if isinstance(level, str) else level)
