"""How numbers are written for people: octal as the 1985 guide writes it.

Opcodes, Chaos host addresses, connection indexes, masks and Cougar words are shown in octal with a
leading zero (``0277``, ``0401``), never Python's ``0o277`` nor bare digits whose base a reader must
guess; a Chaos index is octal like the host address beside it (``host 0401 index 05001``).  Checksums
and byte dumps stay hexadecimal.
"""

from __future__ import annotations

from collections.abc import Iterable

__all__ = ["a_or_an", "octal", "octal_words"]


def octal(value: int) -> str:
    """``value`` in octal with a leading zero: ``0277``; zero is ``0``."""
    if value < 0:
        return f"-{octal(-value)}"
    return f"0{value:o}" if value else "0"


def octal_words(words: Iterable[int]) -> str:
    """Words in octal, space separated (``0277 0100``); ``(none)`` for no words."""
    return " ".join(octal(w) for w in words) or "(none)"


def a_or_an(name: str) -> str:
    """``name`` with its indefinite article, for the spec's lower-case names: ``an asynchronous-warning``,
    ``a response``.  (Upper-case acronyms are read letter by letter and are left to the caller.)"""
    return f"{'an' if name[:1] in ('a', 'e', 'i', 'o', 'u') else 'a'} {name}"
