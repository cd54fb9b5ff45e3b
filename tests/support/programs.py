"""Real programs some tests run (a browser, Wireshark's tshark, Lua interpreters): the one rule for all.

A test that needs one calls :func:`need_program`, which returns the program's path.  When the program is
absent the test is skipped, with a reason written in one recognisable form, and the run ends with one
line (``tests/conftest.py``'s ``pytest_terminal_summary``, built by :func:`summary_line`) naming what was
not checked and how to install it.  With ``MANIP_REQUIRE_PROGRAMS=1`` (set by ``.ci/run``, which
installs them) an absent program fails the test instead: CI never passes without having run them.

The reason is the only thing a skip carries from an xdist worker to the controller that prints the
summary, so the program's name travels in it, and :func:`missing_from` reads it back.
"""

from __future__ import annotations

import os
import re
import shutil
from collections.abc import Iterable
from dataclasses import dataclass

import pytest

REQUIRE_VARIABLE = "MANIP_REQUIRE_PROGRAMS"
"""Set to 1, an absent program is a failure of the test that needs it, not a skip."""


@dataclass(frozen=True)
class Program:
    """A program a test runs: the Debian package that installs it, and what goes unchecked without it."""

    package: str
    checks: str


PROGRAMS: dict[str, Program] = {
    "chromium": Program("chromium", "the HTML report in a browser"),
    "tshark": Program("tshark", "the Wireshark dissector in tshark"),
    "lua5.4": Program("lua5.4", "the Wireshark dissector in Lua 5.4"),
    "lua5.2": Program("lua5.2", "the Wireshark dissector in Lua 5.2"),
}
"""Every real program a test needs, by the command name looked up on PATH."""

_REASON = re.compile(r"needs the program (\S+), which is not installed")


def _reason(name: str) -> str:
    program = PROGRAMS[name]
    return (
        f"needs the program {name}, which is not installed: {program.checks} is not checked "
        f"(apt-get install {program.package})"
    )


def need_program(name: str) -> str:
    """The path of the program ``name`` (one of :data:`PROGRAMS`); the calling test is skipped when it
    is absent, or fails under ``MANIP_REQUIRE_PROGRAMS=1``."""
    if name not in PROGRAMS:
        raise KeyError(f"{name!r} is not in tests/support/programs.py's PROGRAMS: add it there")
    found = shutil.which(name)
    if found is not None:
        return found
    if os.environ.get(REQUIRE_VARIABLE) == "1":
        pytest.fail(f"{_reason(name)}; {REQUIRE_VARIABLE}=1 requires it")
    pytest.skip(_reason(name))


def missing_from(reasons: Iterable[str]) -> dict[str, int]:
    """How many tests skipped for each absent program, read from skip reasons (any other is ignored)."""
    counts: dict[str, int] = {}
    for reason in reasons:
        found = _REASON.search(reason)
        if found is not None and found.group(1) in PROGRAMS:
            counts[found.group(1)] = counts.get(found.group(1), 0) + 1
    return counts


def summary_line(missing: dict[str, int]) -> str | None:
    """The one line that ends a run in which tests skipped for absent programs; None when none did."""
    if not missing:
        return None
    names = sorted(missing)
    unchecked = "; ".join(
        f"{PROGRAMS[n].checks} ({missing[n]} test{'s' * (missing[n] != 1)}, no {n})" for n in names
    )
    packages = " ".join(dict.fromkeys(PROGRAMS[n].package for n in names))
    return (
        f"not checked: {unchecked}. Install with `apt-get install {packages}` "
        f"(as .ci/run does, where {REQUIRE_VARIABLE}=1 makes an absent program a failure)."
    )
