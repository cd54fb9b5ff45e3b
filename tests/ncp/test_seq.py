"""Packet-number arithmetic modulo 2^16."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from manip.ncp.seq import seq_add, seq_ge, seq_gt, seq_le, seq_lt, seq_sub

numbers = st.integers(0, 0xFFFF)
forward = st.integers(1, 0x7FFF)


def test_wrap_around() -> None:
    assert seq_add(0xFFFF, 1) == 0
    assert seq_add(0, -1) == 0xFFFF
    assert seq_sub(0, 0xFFFF) == 1
    assert seq_sub(0xFFFF, 0) == 0xFFFF
    assert seq_lt(0xFFFF, 0) and seq_gt(0, 0xFFFF)
    assert seq_lt(65_530, 5) and not seq_lt(5, 65_530)
    assert seq_le(7, 7) and seq_ge(7, 7) and not seq_lt(7, 7) and not seq_gt(7, 7)


def test_the_notes_definition() -> None:
    # a < b iff bit 15 of (a - b) is set.
    assert seq_lt(1, 2) and seq_lt(0x7FFF, 0xFFFE) and not seq_lt(0x7FFF, 0)
    # Exactly half the space apart, each is "before" the other; an NCP never gets that far apart.
    assert seq_lt(0x8000, 0) and seq_lt(0, 0x8000)


@given(numbers, forward)
def test_going_forward_is_later(a: int, d: int) -> None:
    b = seq_add(a, d)
    assert seq_lt(a, b) and seq_le(a, b) and seq_gt(b, a) and seq_ge(b, a)
    assert not seq_lt(b, a) and not seq_le(b, a)
    assert seq_sub(b, a) == d


@given(numbers, numbers)
def test_add_and_sub_are_inverse(a: int, b: int) -> None:
    assert seq_add(b, seq_sub(a, b)) == a
