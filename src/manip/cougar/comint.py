"""COMINT (B.7): the input buffer, the table of command lengths and destinations, out-of-sync recovery.

Theory of operation.  Words from the Puma (the DRV-11J's IDXR) are appended to the input buffer as they
arrive.  When GUTS calls COMINT, it looks at the first buffered word: if the word is a known command
code, the table gives the number of data words that follow it (from Table 1, ``manip.spec`` data) and the
memory region the data go to; once that many words are buffered the command is removed, its data words
are copied to memory unchanged, and the command's routine runs.  COMINT repeats this until the buffer is
empty or holds only part of a command, which waits for the rest.  An unknown code word means the two ends
have lost step: the whole buffer is dumped and an out-of-sync report is made (response 2 carrying the
bad word, errata ``cougar-out-of-sync``).

Because the data go to memory as raw words, COMINT never decodes a float: a float that is not a value
(the FP11's undefined variable) is stored as sent and read as 0.0 when used (:mod:`manip.cougar.memory`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Final

from manip.cougar.memory import MAP, region
from manip.spec import SPEC

__all__ = ["COMMANDS", "Comint", "CommandEntry", "Executable", "OutOfSyncEvent"]

# Where each command's data words go (B.7: "a location also found from a table").  NPR's 36 words fill
# theta_sensed, theta_commanded and rate_difference, which are consecutive in the memory map.
_DESTINATIONS: Final[Mapping[str, str]] = {
    "SEN": "theta_sensed",
    "FINIT": "theta_sensed",
    "NPR": "theta_sensed",
    "NFC": "fc",
    "NK": "k",
    "NB": "b",
    "NBJI": "bji",
    "NFV": "fv",
    "DPST": "args",
    "EXMN": "args",
    "VERS": "puma_version",
    "NEWWC": "object",
    "GUARDS": "guard_in",
    "GUARDC": "args",
    "WGOV": "gauge_offsets",
}


@dataclass(frozen=True)
class CommandEntry:
    """One row of COMINT's table."""

    code: int
    name: str
    label: str
    data_words: int
    destination: int | None
    """Byte address the data words are copied to (None for commands without data)."""


def _table() -> dict[int, CommandEntry]:
    ends = {r.end for r in MAP}
    table: dict[int, CommandEntry] = {}
    for code, msg in SPEC.cougar_commands.items():
        n = msg.data_words
        if n is None:
            raise ValueError(f"Cougar command {msg.name} has no fixed length")
        dest: int | None = None
        if n:
            destination = region(_DESTINATIONS[msg.name])
            dest = destination.address
            if dest + 2 * n not in ends and dest + 2 * n > destination.end:
                raise ValueError(f"{msg.name}'s {n} data words do not fill whole memory regions")
        table[code] = CommandEntry(code, msg.name, msg.label or "noop", n, dest)
    return table


#: COMINT's table, by command code.
COMMANDS: Final[Mapping[int, CommandEntry]] = _table()


@dataclass(frozen=True)
class Executable:
    """A complete command taken from the buffer: its table entry and data words."""

    entry: CommandEntry
    data: tuple[int, ...]


@dataclass(frozen=True)
class OutOfSyncEvent:
    """An unknown code word was at the head of the buffer; ``discarded`` is everything dumped with it."""

    code: int
    discarded: tuple[int, ...]


class Comint:
    """The input buffer and its parser; :meth:`take` yields the next thing to do, or None."""

    def __init__(
        self, *, execute_partial: bool = False, table: Mapping[int, CommandEntry] = COMMANDS
    ) -> None:
        self._buffer: list[int] = []
        self._execute_partial = execute_partial
        """A defect for mutation testing (fault ``comint-executes-partial``): never set it otherwise."""
        self._table = table
        """The command table: :data:`COMMANDS` (another only for the faults of the table)."""

    @property
    def pending(self) -> tuple[int, ...]:
        """Words waiting for the rest of their command."""
        return tuple(self._buffer)

    def receive(self, words: Iterable[int]) -> int:
        """Append words to the input buffer; returns how many.  ValueError for a non-16-bit value."""
        new = list(words)
        for w in new:
            if isinstance(w, bool) or not isinstance(w, int) or not 0 <= w <= 0xFFFF:
                raise ValueError(f"{w!r} is not a 16-bit word")
        self._buffer.extend(new)
        return len(new)

    def take(self) -> Executable | OutOfSyncEvent | None:
        if not self._buffer:
            return None
        entry = self._table.get(self._buffer[0])
        if entry is None:
            dumped = tuple(self._buffer)
            self._buffer.clear()
            return OutOfSyncEvent(dumped[0], dumped)
        need = 1 + entry.data_words
        if len(self._buffer) < need:
            if not self._execute_partial:
                return None
            self._buffer += [0] * (need - len(self._buffer))
        data = tuple(self._buffer[1:need])
        del self._buffer[:need]
        return Executable(entry, data)
