"""Chaos packet numbers: 16-bit counters compared modulo 2^16.

Each direction of a connection numbers its controlled packets with a 16-bit counter that wraps from
0xFFFF to 0.  Ordering is therefore circular: ``a`` comes before ``b`` when going forward from ``a``
reaches ``b`` in fewer than 2^15 steps, i.e. when bit 15 of ``a - b`` (taken modulo 2^16) is set.  Two
numbers exactly 2^15 apart are each "before" the other; a correct NCP never has that many packets in
flight, so the case does not arise.
"""

from __future__ import annotations

from typing import Final

MASK: Final = 0xFFFF
_HALF: Final = 0x8000


def seq_add(a: int, n: int) -> int:
    """``a + n`` modulo 2^16 (``n`` may be negative)."""
    return (a + n) & MASK


def seq_sub(a: int, b: int) -> int:
    """How many steps forward from ``b`` to ``a``: ``(a - b)`` modulo 2^16, in 0..65535."""
    return (a - b) & MASK


def seq_lt(a: int, b: int) -> bool:
    """``a`` comes strictly before ``b``."""
    return ((a - b) & _HALF) != 0


def seq_le(a: int, b: int) -> bool:
    """``a`` is ``b`` or comes before it."""
    return (a & MASK) == (b & MASK) or seq_lt(a, b)


def seq_gt(a: int, b: int) -> bool:
    """``a`` comes strictly after ``b``."""
    return seq_lt(b, a)


def seq_ge(a: int, b: int) -> bool:
    """``a`` is ``b`` or comes after it."""
    return seq_le(b, a)
