"""What every manip command shares: ``--version`` and the log format.

Every command (``manip-client``, ``manip-server``, ``manip-cougar``, ``manip-capture``, ``manip-decode``,
``manip-conform``) takes ``--version`` (:func:`version_option`: ``manip-client, version 0.1.0``) and
logs through :func:`configure_logging`, one line a record::

    2026-03-02T14:05:09.123+01:00 INFO manip.reference_server: listening on tcp://127.0.0.1:42085

local time in ISO 8601 with milliseconds and the UTC offset, the level, the logger's name, the message;
to standard error, never coloured.

Every command checks its options the same way before anything runs, with the parameter types here: a
number option is a :class:`FiniteFloat` (``nan``, ``inf`` and anything out of range are usage errors,
exit 2, with a message), a link address is a :class:`LinkAddressType` (parsed, and its host resolved,
before the command starts; ``tcp://300.1.1.1:0`` is a usage error, not a traceback when binding), and a
command line to run is a :class:`CommandLine` (never empty).

This module sits outside the layers (it imports only click and the standard library; the command
gives :class:`LinkAddressType` its parser), so the command of any layer can use it.
"""

from __future__ import annotations

import ipaddress
import logging
import math
import shlex
import socket
import sys
from collections.abc import Callable
from datetime import datetime
from typing import Any, Final, TextIO, TypeVar

import click

__all__ = [
    "FINITE",
    "LOG_FORMAT",
    "CommandLine",
    "FiniteFloat",
    "LinkAddressType",
    "LogFormatter",
    "broken_after_option",
    "check_host",
    "configure_logging",
    "version_option",
]

F = TypeVar("F", bound=Callable[..., Any])

PACKAGE: Final = "manip"
VERSION_MESSAGE: Final = "%(prog)s, version %(version)s"
LOG_FORMAT: Final = "%(asctime)s %(levelname)s %(name)s: %(message)s"


def version_option(prog: str) -> Callable[[F], F]:
    """``--version`` for the command ``prog``: the installed package's version (importlib.metadata,
    read only when asked)."""
    return click.version_option(package_name=PACKAGE, prog_name=prog, message=VERSION_MESSAGE)


def broken_after_option(help: str) -> Callable[[F], F]:
    """``--broken-after SECONDS``: a Chaos connection's broken-connection timer (erratum ncp-timers),
    given to a server or told about a target; ``help`` says which."""
    return click.option(
        "--broken-after", type=FiniteFloat(min=0.1), default=None, metavar="SECONDS", help=help
    )


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


# ---------------------------------------------------------------------------------------- option types


class FiniteFloat(click.FloatRange):
    """A number, finite (``nan``, ``inf``, ``-inf`` refused), optionally in a range like FloatRange's."""

    name = "number"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        if isinstance(value, float) and not math.isfinite(value):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        if isinstance(value, str):
            try:
                number = float(value)
            except ValueError:
                self.fail(f"{value!r} is not a number", param, ctx)
            if not math.isfinite(number):
                self.fail(f"{value!r} is not a finite number", param, ctx)
        return super().convert(value, param, ctx)


FINITE: Final = FiniteFloat()
"""Any finite number (the type of a plain float option or argument)."""


def check_host(host: str) -> str | None:
    """Why ``host`` cannot be used as an address (not an IP address and not a name that resolves), or
    None when it can.  A dotted quad out of range (``300.1.1.1``) is refused without asking DNS."""
    bare = host.strip("[]")
    try:
        ipaddress.ip_address(bare)
    except ValueError:
        pass
    else:
        return None
    if bare.replace(".", "").isdigit():
        return f"{host!r} is not an IP address"
    try:
        socket.getaddrinfo(bare, None)
    except (socket.gaierror, UnicodeError) as exc:
        return f"{host!r} does not resolve ({exc.args[-1] if exc.args else exc})"
    return None


class LinkAddressType(click.ParamType[Any, Any]):
    """A link address (``tcp://HOST:PORT``, ``chudp://...``, ``chaosd:///PATH``, ``unix:///PATH``), parsed
    by ``parse`` (``manip.links.parse_address``, given by the command: this module stays below the
    layers) and its host resolved; the value is the address as given.  ``scheme``: the scheme a bare
    ``HOST:PORT`` means; ``schemes``: the ones allowed (all by default)."""

    name = "url"

    def __init__(self, parse: Callable[..., Any], scheme: str = "tcp", schemes: tuple[str, ...] = ()) -> None:
        self.parse = parse
        self.scheme = scheme
        self.schemes = schemes

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        text = str(value)
        try:
            address = self.parse(text, default_scheme=self.scheme)
        except ValueError as exc:  # manip.links.AddressError
            self.fail(str(exc), param, ctx)
        if self.schemes and address.scheme not in self.schemes:
            allowed = " or ".join(f"{s}://" for s in self.schemes)
            self.fail(f"{text!r} is not a {allowed} address", param, ctx)
        if address.scheme in ("tcp", "chudp"):
            why = check_host(address.host)
            if why is not None:
                self.fail(why, param, ctx)
        return text


class CommandLine(click.ParamType[Any, Any]):
    """A command line to run (split as a shell would); empty or unparsable is a usage error."""

    name = "command"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        try:
            words = shlex.split(str(value))
        except ValueError as exc:
            self.fail(f"{value!r} is not a command line: {exc}", param, ctx)
        if not words:
            self.fail("the command is empty", param, ctx)
        return value
