"""The Puma's end of the Puma <-> Cougar parallel link (the DRV-11J), as seen by the wrist processes.

A :class:`CougarPort` moves 16-bit words both ways and carries the Puma's clock tick, which drives
Cougar (Appendix A: Cougar's KWV-11C is slaved to the Puma's).  It is sans-I/O friendly: every call
returns at once; words from Cougar are collected as they arrive and handed over by :meth:`receive`.

* :class:`SimPort` wraps an in-process Cougar model (:class:`manip.cougar.CougarSim` or anything with
  its ``receive(words)`` / ``tick(now) -> words`` contract): words sent are handed to it at once (its
  IDXR input buffer), and each :meth:`~CougarPort.tick` runs one GUTS, whose output words are received
  immediately;
* :class:`manip.links.drv11j.Drv11jPort` speaks the emulated DRV-11J over TCP (``docs/drv11j.md``):
  words and ticks become frames, and Cougar's words arrive whenever the network delivers them.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

from manip.cougar.link import CougarModel

__all__ = ["CougarPort", "SimPort"]


class CougarPort(Protocol):
    """The Puma's side of the word link."""

    def send(self, words: Sequence[int]) -> None:
        """Queue words for Cougar, in order."""
        ...

    def tick(self, now: float) -> None:
        """The Puma clock ticks at ``now`` (seconds): Cougar runs one GUTS."""
        ...

    def receive(self) -> list[int]:
        """Words that arrived from Cougar since the last call, in order."""
        ...

    @property
    def error(self) -> str | None:
        """Why the link is down (None while it works)."""
        ...

    def close(self) -> None:
        """Release the link."""
        ...


class SimPort:
    """A :class:`CougarPort` wired straight to an in-process Cougar model."""

    def __init__(self, cougar: CougarModel) -> None:
        self.cougar = cougar
        self.ticks = 0
        self.words_sent = 0
        self.words_received = 0
        self._inbox: list[int] = []
        self._closed = False

    def send(self, words: Sequence[int]) -> None:
        if self._closed:
            return
        self.words_sent += len(words)
        self.cougar.receive(list(words))

    def tick(self, now: float) -> None:
        if self._closed:
            return
        self.ticks += 1
        out = self.cougar.tick(now)
        self.words_received += len(out)
        self._inbox.extend(out)

    def receive(self) -> list[int]:
        out, self._inbox = self._inbox, []
        return out

    @property
    def error(self) -> str | None:
        return "port closed" if self._closed else None

    def close(self) -> None:
        self._closed = True
