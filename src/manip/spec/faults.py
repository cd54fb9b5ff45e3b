"""The one shape of a fault switch: what every implementation manip ships breaks on purpose.

The reference server, the reference client and the simulated Cougar can each be told to break a rule of
the protocol, so the suite is shown to catch it (mutation testing of the suite).  Each of them declares
its switches once, as the members of a subclass of :class:`FaultSwitch` (its registry): a member is the
whole record, its value the name the command line takes (``--fault``, ``--client-fault``,
``--cougar-fault``).

A switch's record says:

* ``name`` (the member's value): the name on the command line;
* ``kind``: ``protocol`` for a defect, which breaks the clauses it names, or ``reading`` for a switch that
  takes another reading the spec allows and breaks nothing (the suite must pass it);
* ``breaks``: one line saying what changes;
* ``clauses``: the clause ids it breaks (none for a reading), checked against the spec;
* ``caught_by``: the cases its fault matrix requires to catch it (fail, or warn for a SHOULD clause),
  each citing one of the clauses it breaks (none for a reading; the tests check the ids, and the
  coverage table of ``docs/spec.md`` reads them);
* ``argument``: what ``NAME=ARG`` means, for the few switches that take one (None for the others).

The conditions of an arm's world (an obstacle, the panic button...) are not fault switches: a conforming
server meets them too (``manip.reference_server.conditions``).
"""

from __future__ import annotations

import enum
from collections.abc import Iterable
from typing import Literal, Self

from manip.spec import SPEC

__all__ = ["FaultKind", "FaultSwitch", "defect", "reading"]

FaultKind = Literal["protocol", "reading"]
"""A defect that breaks its clauses, or another reading the spec allows (it breaks none)."""

Declaration = tuple[str, FaultKind, str, tuple[str, ...], tuple[str, ...], str | None]
"""A member's value as declared: name, kind, breaks, clauses, caught by, argument (:func:`defect`,
:func:`reading`)."""


def defect(
    name: str, breaks: str, *clauses: str, caught_by: tuple[str, ...] = (), argument: str | None = None
) -> Declaration:
    """Declare a switch that breaks ``clauses`` (a registry member's value)."""
    return name, "protocol", breaks, clauses, caught_by, argument


def reading(name: str, breaks: str) -> Declaration:
    """Declare a switch that takes another reading the spec allows: it breaks no clause."""
    return name, "reading", breaks, (), (), None


class FaultSwitch(enum.StrEnum):
    """A fault switch: the base of each implementation's registry (see the module docstring)."""

    kind: FaultKind
    breaks: str
    clauses: tuple[str, ...]
    caught_by: tuple[str, ...]
    argument: str | None

    def __new__(
        cls,
        name: str,
        kind: FaultKind,
        breaks: str,
        clauses: tuple[str, ...],
        caught_by: tuple[str, ...],
        argument: str | None,
    ) -> Self:
        if kind == "protocol" and not clauses:
            raise ValueError(f"fault switch {name} breaks no clause: declare it a reading")
        if kind == "reading" and clauses:
            raise ValueError(f"fault switch {name} is a reading: it breaks no clause")
        unknown = [c for c in clauses if c not in SPEC.clauses]
        if unknown:
            raise ValueError(f"fault switch {name} names unknown clauses {unknown}")
        member = str.__new__(cls, name)
        member._value_ = name
        member.kind, member.breaks, member.clauses = kind, breaks, clauses
        member.caught_by, member.argument = caught_by, argument
        return member

    @classmethod
    def named(cls, name: str, what: str = "fault") -> Self:
        """The switch called ``name``; ValueError naming the known ones when there is none (``what``
        says whose switches they are in the message)."""
        for member in cls:
            if member.value == name:
                return member
        raise ValueError(f"unknown {what} {name!r}; known: {', '.join(sorted(m.value for m in cls))}")

    @classmethod
    def parse(cls, names: Iterable[str], what: str = "fault") -> frozenset[Self]:
        """The switches named (blank names skipped); ValueError for a name that is none."""
        return frozenset(cls.named(n.strip(), what) for n in names if n.strip())
