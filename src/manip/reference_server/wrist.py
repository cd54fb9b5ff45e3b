"""The seam for the Cougar wrist: how the session serves the Puma extension opcodes that need it.

The extensions 0240-0256 and 0261 (forces, gauges, guards, compliance, examine/deposit, wrist version)
reach the wrist computer.  The session hands each such request, already decoded and length-checked, to
its :class:`Wrist` and sends what comes back:

* the values of the normal reply, by the field names of the spec's reply layout (``{}`` for done,
  ``{"segment": n}`` for a motion request queued on the arm);
* a :class:`Pending` when the answer needs data from Cougar (Part II §5.1: "if the request itself
  requires information from the appropriate ancillary process ... the main process will indeed wait
  for the data to be returned").  The session then holds this request *and every later one* (the
  Puma's main process waits), and answers once the wrist has resolved the :class:`Pending` with values
  or a :class:`~manip.reference_server.errors.RequestError` (a wrist that does not answer in time is a
  non-fatal error, §6.3);
* or a :class:`~manip.reference_server.errors.RequestError` raised with the error string to answer,
  non-fatal or fatal.

``served`` lists the opcodes the wrist answers normally; they are added to describe-self's
``:operations``.

:meth:`Wrist.tick` is called by the session whenever it runs the arm (every servo tick, and before each
request), after the arm has run; it is the wrist processes' turn: talk to Cougar, resolve pending
requests, and report what happened asynchronously as :data:`WristEvent`\\ s -- :class:`GuardHit` (the
session sends a guard-hit asynchronous response, 0203 code 1, when the client asked for them with
request-notifications mask bit 0) and :class:`WristNotice` (an asynchronous error or warning).

:class:`NoWrist` is the default: a Puma without Cougar.  It serves nothing and answers every wrist
opcode with ``wrist: C UIM No wrist computer: opcode ~ is not served`` (severity C, as clause
``request.unknown-opcode`` asks of an opcode the server does not serve).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol

from manip.arm.sim import ArmEvent, ArmSim
from manip.codecs.error_string import ErrorMessage
from manip.codecs.messages import Value
from manip.reference_server.errors import RequestError, not_served
from manip.spec import RequestOpcode

__all__ = ["GuardHit", "NoWrist", "Pending", "Wrist", "WristDefects", "WristEvent", "WristNotice"]


class Pending:
    """A reply that waits for Cougar.  The wrist resolves it (:meth:`resolve` or :meth:`fail`) from its
    :meth:`Wrist.tick`; the session reads :meth:`outcome` once :attr:`done`.  The session
    :meth:`cancel`\\ s it when the connection ends first."""

    __slots__ = ("_error", "_values", "cancelled", "what")

    def __init__(self, what: str) -> None:
        self.what = what
        """The request waiting (for messages)."""
        self.cancelled = False
        self._values: dict[str, Any] | None = None
        self._error: RequestError | None = None

    def __repr__(self) -> str:
        state = "cancelled" if self.cancelled else "done" if self.done else "waiting"
        return f"<Pending {self.what} {state}>"

    @property
    def done(self) -> bool:
        return self._values is not None or self._error is not None

    def resolve(self, values: dict[str, Any]) -> None:
        """The reply's values arrived."""
        if not self.done:
            self._values = values

    def fail(self, error: RequestError) -> None:
        """The request failed (timeout, link down, ...); ``error`` is the answer."""
        if not self.done:
            self._error = error

    def cancel(self) -> None:
        """Nobody waits any more (the connection ended)."""
        self.cancelled = True

    def outcome(self) -> dict[str, Any]:
        """The reply's values; raises the :class:`RequestError` it failed with."""
        if self._error is not None:
            raise self._error
        if self._values is None:
            raise RuntimeError(f"{self.what}: outcome read before it was resolved")
        return self._values


@dataclass(frozen=True, slots=True)
class GuardHit:
    """Cougar reported guard ``index`` tripped (response 6 or 7).

    ``stop``: a stop-the-move guard; the wrist has then halted the arm (:meth:`ArmSim.halt`) and
    ``arm_events`` are what that returned (segments that had just completed, then the abort)."""

    index: int
    stop: bool
    time: float
    arm_events: tuple[ArmEvent, ...] = ()


@dataclass(frozen=True, slots=True)
class WristNotice:
    """Something the user should hear of asynchronously: a warning (0205) or, with ``error``, an
    asynchronous non-fatal error (0204)."""

    message: ErrorMessage
    error: bool = False


WristEvent = GuardHit | WristNotice


@dataclass(frozen=True)
class WristDefects:
    """How a faulty server's wrist processes depart from the 1985 guide's; the defaults are the guide's
    (no defect).  The wrist is shared: each connection gives it its own as it opens."""

    answer_timeouts: bool = True
    """False: a request whose Cougar command timed out is never answered (a defect)."""
    # The Puma's wrist processes as the 1985 guide has them; the other value of each is a defect, for
    # showing that a judge of the Puma's wrist side (manip-conform run --puma) catches it.
    npr_every_cycle: bool = True
    """A compliant segment sends New Position and Rate every servo cycle (not every other one)."""
    command_floats_swapped: bool = False
    """The floats of the commands queued for Cougar have their two words swapped."""
    user_commands_first: bool = False
    """The output process sends the user's commands before New Position and Rate and Reset."""
    guard_stops_arm: bool = True
    """A stop-the-move guard trip stops the arm."""
    read_forces_sends_angles: bool = True
    """Read forces sends the current joint angles (SEN) before Report Forces."""
    read_forces_waits: bool = True
    """Read forces waits for Cougar's answer (not the last forces seen)."""
    calibrate_two_poses: bool = True
    """Calibrate-wrist takes its readings in two poses (not one, gravity in them)."""
    calibrate_moves_back: bool = True
    """Calibrate-wrist brings the arm back to where it started (not left at its second pose)."""
    user_while_moving: bool = True
    """The user's commands go out on the next tick while the arm moves (not once the queue is done)."""
    user_while_compliant: bool = True
    """The user's commands go out on the next tick during a compliant segment too."""
    handles_out_of_sync: bool = True
    """Cougar's out-of-sync message fails the waiting requests at once and is reported as a warning."""
    clears_old_guards: bool = True
    """A new connection starts with no guard armed: those an earlier one left are cleared on Cougar."""
    compliant_follows_nominal: bool = True
    """A compliant segment follows its nominal path (False: the arm stays where the segment began, moved
    only by Cougar's corrections)."""
    move_queue_before_user: bool = True
    """The move process's wrist packets (the interrupt queue) go out before the user's commands."""


class Wrist(Protocol):
    """What the session needs from a wrist computer model."""

    @property
    def served(self) -> frozenset[int]:
        """Opcodes answered normally."""
        ...

    def handle(
        self, op: RequestOpcode, values: Mapping[str, Value], now: float, arm: ArmSim
    ) -> dict[str, Any] | Pending:
        """Serve one request: the reply's values, a :class:`Pending`, or raise RequestError."""
        ...

    def tick(self, now: float, arm: ArmSim) -> list[WristEvent]:
        """The wrist processes' turn after the arm ran up to ``now``; returns what to report."""
        ...

    def condition(self, defects: WristDefects, *, silent: bool = False) -> None:
        """Take the defects of the connection that opens now, and whether its world keeps Cougar silent
        (a hung Cougar, a cut link: its words never reach the Puma, requests wait the wrist timeout)."""
        ...


class NoWrist:
    """No wrist computer: every wrist opcode is refused with C UIM."""

    @property
    def served(self) -> frozenset[int]:
        return frozenset()

    def handle(
        self, op: RequestOpcode, values: Mapping[str, Value], now: float, arm: ArmSim
    ) -> dict[str, Any] | Pending:
        raise not_served(op.opcode)

    def tick(self, now: float, arm: ArmSim) -> list[WristEvent]:
        return []

    def condition(self, defects: WristDefects, *, silent: bool = False) -> None:
        pass
