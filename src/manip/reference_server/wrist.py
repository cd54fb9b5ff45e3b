"""The seam for the Cougar wrist: how the session serves the Puma extension opcodes that need it.

The extensions 0240-0256 and 0261 (forces, gauges, guards, compliance, examine/deposit, wrist version)
reach the wrist computer.  The session hands each such request, already decoded and length-checked, to
its :class:`Wrist` and sends what comes back:

* the values of the normal reply, by the field names of the spec's reply layout (``{}`` for done,
  ``{"segment": n}`` for a motion request queued on the arm);
* or a :class:`~manip.reference_server.errors.RequestError` raised with the error string to answer,
  non-fatal or fatal.

``served`` lists the opcodes the wrist answers normally; they are added to describe-self's
``:operations``.  Guard hits are to be reported through the session as asynchronous responses (code 1);
that hook comes with the Cougar simulator.

:class:`NoWrist` is the default: a Puma without Cougar.  It serves nothing and answers every wrist
opcode with ``wrist: C UIM No wrist computer: opcode ~ is not served`` (severity C, as clause
``request.unknown-opcode`` asks of an opcode the server does not serve).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol

from manip.arm.sim import ArmSim
from manip.codecs.error_string import ErrorMessage
from manip.codecs.messages import Value
from manip.reference_server.errors import RequestError
from manip.spec import RequestOpcode

__all__ = ["NoWrist", "Wrist"]


class Wrist(Protocol):
    """What the session needs from a wrist computer model."""

    @property
    def served(self) -> frozenset[int]:
        """Opcodes answered normally."""
        ...

    def handle(
        self, op: RequestOpcode, values: Mapping[str, Value], now: float, arm: ArmSim
    ) -> dict[str, Any]:
        """Serve one request; return the reply's values or raise RequestError."""
        ...


class NoWrist:
    """No wrist computer: every wrist opcode is refused with C UIM."""

    @property
    def served(self) -> frozenset[int]:
        return frozenset()

    def handle(
        self, op: RequestOpcode, values: Mapping[str, Value], now: float, arm: ArmSim
    ) -> dict[str, Any]:
        raise RequestError(
            ErrorMessage("wrist", "C", "UIM", "No wrist computer: opcode ~ is not served", (op.opcode,))
        )
