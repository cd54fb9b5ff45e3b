"""Hypothesis strategies derived from the spec tables: one rule per field type, none per message.

The rules are the conformance suite's (:mod:`manip.conformance.suite.strategies`); what is test-only is
longer: counted word lists and LispM text that span several packets, text with newlines and tabs, and
Cougar messages."""

from __future__ import annotations

import struct
from typing import Any

from hypothesis import strategies as st

from manip.conformance.suite import strategies as suite
from manip.conformance.suite.strategies import f_floats
from manip.spec import SPEC, CougarMessage, FieldType, Layout, RequestOpcode
from manip.spec.model import Element

# Every F-representable value, generated from bit patterns so e=1 and e=255 are reached too: the suite's
# own strategy (the same bit patterns, so the same examples, as the copy that stood here).
f_values = f_floats
words = st.integers(0, 0xFFFF)
lispm_text = st.text(
    alphabet=st.characters(min_codepoint=0x20, max_codepoint=0x7E) | st.sampled_from("\n\t"), max_size=600
)


def element_values(element: Element) -> st.SearchStrategy[Any]:
    """One value of a fixed-size element, by the suite's rule."""
    return suite.field_values(FieldType(element, element, 1))


def field_values(ft: FieldType) -> st.SearchStrategy[Any]:
    """The suite's rule, but counted words and text reach past one packet, and text has control
    characters."""
    if ft.element == "counted":
        return st.lists(words, max_size=200).map(tuple)
    if ft.element == "text":
        return lispm_text.filter(bool)  # an empty chunk is the terminator, not data
    return suite.field_values(ft)


def layout_values(layout: Layout) -> st.SearchStrategy[dict[str, Any]]:
    return st.fixed_dictionaries({f.name: field_values(f.type) for f in layout.fields})


requests = st.sampled_from(sorted(SPEC.requests.values(), key=lambda r: r.opcode))


def request_and_values() -> st.SearchStrategy[tuple[RequestOpcode, dict[str, Any]]]:
    return requests.flatmap(lambda op: st.tuples(st.just(op), layout_values(op.request)))


def cougar_values(msg: CougarMessage) -> st.SearchStrategy[dict[str, Any]]:
    fields: dict[str, st.SearchStrategy[Any]] = {}
    for f in msg.data:
        if f.count is None:
            fields[f.name] = st.lists(words, max_size=40).map(tuple)
        elif f.count == 1:
            fields[f.name] = element_values(f.element)
        else:
            fields[f.name] = st.lists(element_values(f.element), min_size=f.count, max_size=f.count).map(
                tuple
            )
    return st.fixed_dictionaries(fields)


def f_bytes(x: float) -> bytes:
    """Independent of the codec: an exactly representable F value's wire bytes via IEEE double fields."""
    if x == 0:
        return b"\0\0\0\0"
    bits = struct.unpack("<Q", struct.pack("<d", x))[0]
    sign = bits >> 63
    exp = ((bits >> 52) & 0x7FF) - 1023 + 129  # 1.f * 2^e  ==  0.1f * 2^(e+1); bias 128
    frac = (bits >> 29) & 0x7FFFFF
    w0 = sign << 15 | exp << 7 | frac >> 16
    w1 = frac & 0xFFFF
    return struct.pack("<HH", w0, w1)
