"""The describe-self text (E.1 Opcode 200): a Lisp-readable alist, one entry per line.

The reply is sent one line per packet (see :mod:`manip.reference_server.session`), so a reader sees
several text packets and then the empty terminator.  Numbers are printed octal (erratum
``octal-numbers``): ``:degrees-of-freedom`` 6, opcodes ``200`` to ``221``; floats print in decimal with a
point, as the Lisp reader expects.

Besides the six descriptors of the 1985 guide the alist carries two the guide wished for ("things to
describe the geometry"): ``:ready-position`` (six joint angles, degrees) and ``:joint-limits`` (a list of
``(lower upper)`` pairs, degrees, joint 1 first).  A client ignores keys it does not know.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from manip.arm.kinematics import ArmModel
from manip.codecs.lisp import Keyword, LispValue, cons, print_lisp

__all__ = ["Description", "Statement", "alist_text", "describe_text"]


@dataclass(frozen=True)
class Description:
    """What describe self says about the server."""

    brand_name: str = "Unimation Puma 600"
    unique_name: str = "MIT AI Lab Puma 600 (manip reference simulator)"
    software_version: tuple[tuple[str, int], ...] = (("server", 1), ("move-process", 1))
    """Module names and version numbers: printed as alternating keywords and numbers."""
    protocol_version: int = 1


@dataclass(frozen=True)
class Statement:
    """What describe self states about the arm: the opcodes it lists and the geometry it gives."""

    operations: frozenset[int]
    degrees_of_freedom: int
    joint_limits: tuple[tuple[float, float], ...]
    ready_position: tuple[float, ...]
    protocol_version: bool = True
    """Whether the alist carries :protocol-version."""

    @classmethod
    def of(cls, model: ArmModel, operations: Iterable[int]) -> Statement:
        """The truth about ``model``, serving ``operations``."""
        limits = tuple(zip(model.limits.lower, model.limits.upper, strict=True))
        return cls(frozenset(operations), len(model.ready), limits, tuple(model.ready))


def _entry(key: str, value: LispValue) -> str:
    return print_lisp(cons(Keyword(key), value))


def alist_text(entries: Iterable[str]) -> str:
    """The printed ``entries`` as describe self sends them: one per line, the first line opening and the
    last closing the list."""
    return "(" + "\n ".join(entries) + ")\n"


def describe_text(
    description: Description,
    model: ArmModel,
    operations: Iterable[int],
    *,
    with_protocol_version: bool = True,
    degrees_of_freedom: int | None = None,
    joint_limits: Sequence[tuple[float, float]] | None = None,
    ready_position: Sequence[float] | None = None,
) -> str:
    """The alist, one entry per line, the first line opening and the last closing the list.

    ``degrees_of_freedom``, ``joint_limits`` and ``ready_position`` state other values than the model's
    (fault switches)."""
    pairs = (
        joint_limits
        if joint_limits is not None
        else list(zip(model.limits.lower, model.limits.upper, strict=True))
    )
    limits: list[LispValue] = [[lo, hi] for lo, hi in pairs]
    version: list[LispValue] = []
    for module, number in description.software_version:
        version += [Keyword(module), number]
    ready: Sequence[float] = model.ready if ready_position is None else ready_position
    entries = [
        _entry("brand-name", description.brand_name),
        _entry("unique-name", description.unique_name),
        _entry("degrees-of-freedom", len(model.ready) if degrees_of_freedom is None else degrees_of_freedom),
        _entry("operations", list(sorted(set(operations)))),
        _entry("software-version", version),
    ]
    if with_protocol_version:
        entries.append(_entry("protocol-version", description.protocol_version))
    entries += [
        _entry("ready-position", [float(q) for q in ready]),
        _entry("joint-limits", limits),
    ]
    return alist_text(entries)
