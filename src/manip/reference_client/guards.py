"""What the client chooses for itself about the wrist's guards and load (Part II B.8 and B.9 of the
1985 guide): which guard number a new guard gets, and what to send when the hand's load changes.

:class:`WristBook` keeps the guards armed on one connection, from the moment each set guard is sent,
its own and those of plain set guard requests it is told of: a new guard takes the lowest number that
is free (never armed, cleared, refused by the server, or reported tripped by a guard-hit asynchronous
response), and its set guard says in bit 15 whether a trip stops the move; a change of load sends set
frame vector (when the frame vector changes) then set weight (NEWWC) with the new object's weight and
centre of gravity, with or without a new frame vector, and is refused while a guard is armed, since
both change the forces the guard tests (``client.guard-numbers``, ``client.guard-word``,
``client.newwc-on-load``, ``client.no-newwc-with-guard``).  Fault switches of :mod:`.faults` break
each rule on purpose.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, SupportsFloat

from manip.reference_client.errors import ServerError
from manip.reference_client.faults import NO_FAULTS, ClientFault, ClientFaults
from manip.reference_client.puma import GUARDS
from manip.spec.constants import AsyncCondition

__all__ = ["GuardsBusyError", "LoadChangeRefusedError", "WristBook"]


class GuardsBusyError(ValueError):
    """Every guard number is armed: no new guard can be armed until one is cleared or trips."""


class LoadChangeRefusedError(ValueError):
    """A change of load while guards are armed: set weight would change the forces they test."""


class WristBook:
    """The guards armed on ``arm`` (a :class:`~manip.reference_client.Manipulator` of type puma)."""

    def __init__(self, arm: Any, *, faults: ClientFaults = NO_FAULTS) -> None:
        self.arm = arm
        self.faults = faults
        """The client's fault switches (:mod:`.faults`), which break the guard and load rules."""
        self.armed: set[int] = set()
        self._remove = arm.add_async_listener(self._on_async)

    def close(self) -> None:
        self._remove()

    def _on_async(self, response: Any) -> None:
        if response.condition == AsyncCondition.GUARD_HIT:
            self.armed.discard(response.word3 & 0xF)

    def free_number(self) -> int:
        """The lowest guard number not armed (GuardsBusyError when all 16 are)."""
        if ClientFault.GUARD_ZERO in self.faults:
            return 0
        for number in range(GUARDS):
            if number not in self.armed:
                return number
        raise GuardsBusyError(f"all {GUARDS} guards are armed")

    async def arm_guard(
        self, dvec: Sequence[SupportsFloat], tol: float, *, stop: bool = True, timeout: Any = None
    ) -> int:
        """Arm a new guard with a free number; returns the number."""
        number = self.free_number()
        kw = {} if timeout is None else {"timeout": timeout}
        stop = stop and ClientFault.GUARD_ALWAYS_CONTINUE not in self.faults
        self.armed.add(number)  # armed from the moment it is sent: it may trip before the done comes
        try:
            await self.arm.set_guard(number, dvec, tol, stop=stop, **kw)
        except ServerError:
            self.armed.discard(number)  # refused by the server: nothing armed
            raise
        return number

    def note_set_guard(self, type_index: int) -> None:
        """A plain set guard request was sent: its guard (the low 4 bits) is armed from now on (a
        refusal by the server is undone with :meth:`note_clear_guard`)."""
        if ClientFault.PLAIN_GUARDS_UNTRACKED not in self.faults:
            self.armed.add(type_index & 0xF)

    def note_clear_guard(self, index: int) -> None:
        """A plain clear guard request was sent: its guard is no longer armed."""
        if ClientFault.PLAIN_GUARDS_UNTRACKED not in self.faults:
            self.armed.discard(index & 0xF)

    async def clear_guard(self, number: int, *, timeout: Any = None) -> None:
        kw = {} if timeout is None else {"timeout": timeout}
        await self.arm.clear_guard(number, **kw)
        self.armed.discard(number)

    async def change_load(
        self,
        weight: float,
        cg: Sequence[SupportsFloat],
        offset: Sequence[SupportsFloat] | None = None,
        *,
        timeout: Any = None,
    ) -> None:
        """The hand holds a new object (and, with ``offset``, the frame vector moves): set frame
        vector, then set weight (NEWWC).  Refused while a guard is armed."""
        kw = {} if timeout is None else {"timeout": timeout}
        if self.armed and ClientFault.CLEAR_GUARDS_FIRST in self.faults:
            for number in sorted(self.armed):
                await self.clear_guard(number, **kw)
        if self.armed and ClientFault.NEWWC_UNDER_GUARD not in self.faults:
            numbers = ", ".join(str(n) for n in sorted(self.armed))
            raise LoadChangeRefusedError(f"guard(s) {numbers} armed: clear them before the load changes")
        if offset is not None:
            await self.arm.set_frame_vector(offset, **kw)
        if offset is None and ClientFault.NO_NEWWC_WITHOUT_OFFSET in self.faults:
            return
        if ClientFault.NO_NEWWC not in self.faults:
            await self.arm.set_weight(weight, cg, **kw)
