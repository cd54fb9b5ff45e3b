"""Lisp reader/printer of the describe-self reply, and Lisp Machine text (golden vectors and properties)."""

from __future__ import annotations

import json
from importlib import resources
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from manip.codecs.errors import DecodeError, EncodeError
from manip.codecs.lisp import (
    Cons,
    Keyword,
    LispValue,
    Symbol,
    alist_to_dict,
    cons,
    dict_to_alist,
    print_lisp,
    read_alist,
    read_all,
    read_lisp,
)
from manip.codecs.lispm_text import (
    PRIVATE_BASE,
    PRIVATE_CODES,
    decode_lispm,
    encode_lispm,
    is_lispm_encodable,
)

# ------------------------------------------------------------------------------------------ vectors


def _load() -> list[dict[str, Any]]:
    doc = json.loads(resources.files("manip.vectors").joinpath("lisp.json").read_text())
    assert doc["format"] == "manip-vectors/1" and doc["subject"] == "lisp"
    return list(doc["vectors"])


VECTORS = _load()


def from_json(j: Any) -> LispValue:
    """The JSON form of the vectors -> a Lisp value (independent of the reader)."""
    if isinstance(j, bool):
        raise TypeError(j)
    if isinstance(j, int | str):
        return j
    if isinstance(j, list):
        return [from_json(x) for x in j]
    assert isinstance(j, dict)
    if "keyword" in j:
        return Keyword(j["keyword"])
    if "symbol" in j:
        return Symbol(j["symbol"])
    if "float" in j:
        return float(j["float"])
    return Cons(from_json(j["car"]), from_json(j["cdr"]))


def _kind(kind: str) -> list[dict[str, Any]]:
    return [v for v in VECTORS if v["kind"] == kind]


def _same(a: LispValue, b: LispValue) -> bool:
    """Equality that also tells ints from floats (== alone says 1 == 1.0)."""
    if type(a) is not type(b):
        return False
    if isinstance(a, list):
        assert isinstance(b, list)
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, Cons):
        assert isinstance(b, Cons)
        return _same(a.car, b.car) and _same(a.cdr, b.cdr)
    return a == b


@pytest.mark.parametrize("vec", _kind("read"), ids=lambda v: v["name"])
def test_read_vectors(vec: dict[str, Any]) -> None:
    value = from_json(vec["value"])
    assert _same(read_lisp(vec["text"], base=vec["base"]), value)
    if "printed" in vec:
        assert print_lisp(value, base=vec["base"]) == vec["printed"]
        assert _same(read_lisp(vec["printed"], base=vec["base"]), value)
    if "alist" in vec:
        expected = {k: from_json(v) for k, v in vec["alist"].items()}
        assert read_alist(vec["text"], base=vec["base"]) == expected
        assert dict_to_alist(expected) == value


@pytest.mark.parametrize("vec", _kind("error"), ids=lambda v: v["name"])
def test_read_error_vectors(vec: dict[str, Any]) -> None:
    with pytest.raises(DecodeError) as info:
        read_lisp(vec["text"], base=vec["base"])
    assert info.value.clause == vec["error"]["clause"]
    assert info.value.offset is not None and 0 <= info.value.offset <= len(vec["text"])


@pytest.mark.parametrize("vec", _kind("alist-error"), ids=lambda v: v["name"])
def test_alist_error_vectors(vec: dict[str, Any]) -> None:
    value = read_lisp(vec["text"], base=vec["base"])
    with pytest.raises(DecodeError) as info:
        alist_to_dict(value)
    assert info.value.clause == vec["error"]["clause"]


def test_describe_example_prints_like_the_notes() -> None:
    alist = dict_to_alist(
        {
            "brand-name": "Unimation Puma 600",
            "degrees-of-freedom": 6,
            "operations": [0o200, 0o201, Cons(0o277, 0)],
        }
    )
    assert print_lisp(alist) == (
        '((:BRAND-NAME . "Unimation Puma 600") (:DEGREES-OF-FREEDOM . 6) (:OPERATIONS 200 201 (277 . 0)))'
    )
    assert print_lisp(alist, base=10) == (
        '((:BRAND-NAME . "Unimation Puma 600") (:DEGREES-OF-FREEDOM . 6.) '
        "(:OPERATIONS 128. 129. (191. . 0.)))"
    )
    assert print_lisp(alist, base=10, nopoint=True, upper=False) == (
        '((:brand-name . "Unimation Puma 600") (:degrees-of-freedom . 6) (:operations 128 129 (191 . 0)))'
    )


# ------------------------------------------------------------------------------------------ reader details


def test_reader_details() -> None:
    assert read_lisp("6.") == 6 and read_lisp("10") == 8 and read_lisp("10", base=10) == 10
    assert read_lisp("-10.") == -10 and read_lisp("#O777") == 511 and read_lisp("#36rZz") == 35 * 36 + 35
    assert read_lisp("#x-ff") == -255
    assert read_lisp('"a\\b"') == "a\\b"  # \ is ordinary in Zetalisp syntax
    assert read_lisp('"a\\"b"', escape="\\") == 'a"b'  # Common Lisp syntax on request
    assert read_lisp("(a ; comment (\n b)") == [Symbol("a"), Symbol("b")]
    assert read_lisp("(1\ue00d\ue00a2)") == [1, 2]  # raw ASCII CR LF as decode_lispm gives them
    assert read_all(" 1 (2) :x ; end") == [1, [2], Keyword("x")]
    assert read_all("") == []
    assert read_lisp("(a b . (c . d))") == Cons(
        Symbol("a"), Cons(Symbol("b"), Cons(Symbol("c"), Symbol("d")))
    )
    assert isinstance(read_lisp("1.0"), float) and isinstance(read_lisp("1."), int)


def test_error_offsets() -> None:
    cases = {"(a b": 0, "(a))": 3, "(a . )": 3, "(19)": 1, '(x "abc': 3, "(a) b": 4, "(a . b c)": 7}
    for text, offset in cases.items():
        with pytest.raises(DecodeError) as info:
            read_lisp(text)
        assert info.value.offset == offset, text


def test_value_invariants_and_printer_errors() -> None:
    assert Keyword("BRAND-Name") == Keyword("brand-name") and Symbol("T").name == "t"
    with pytest.raises(ValueError):
        Cons(1, [2])
    assert cons(1, [2]) == [1, 2] and cons(1, 2) == Cons(1, 2)
    for bad in (True, float("nan"), float("inf"), Symbol("nil"), Symbol("a b"), Symbol("12"), Keyword("")):
        with pytest.raises(EncodeError):
            print_lisp(bad)
    with pytest.raises(EncodeError):
        print_lisp([object()])  # type: ignore[list-item]
    with pytest.raises(ValueError):
        read_lisp("1", base=1)


def test_deep_nesting_is_not_recursive() -> None:
    depth = 20_000
    value = read_lisp("(" * depth + ")" * depth)
    assert print_lisp(value).startswith("((") and print_lisp(value).count("(") == depth - 1


def test_alist_round_trip() -> None:
    d: dict[str, LispValue] = {"brand-name": "x", "operations": [0o200], "empty": [], "pair": Cons(1, 2)}
    assert alist_to_dict(dict_to_alist(d)) == d
    assert alist_to_dict([]) == {}


# ------------------------------------------------------------------------------------------ properties

_names = st.from_regex(r"[a-z][a-z0-9*+!?<>=_.\-]{0,8}", fullmatch=True).filter(lambda n: n != "nil")
_atoms: st.SearchStrategy[LispValue] = st.one_of(
    st.integers(-(2**40), 2**40),
    st.floats(allow_nan=False, allow_infinity=False),
    st.text(max_size=12),
    _names.map(Keyword),
    (_names | st.sampled_from(["1+", "-", "+", "*", "-x"])).map(Symbol),
)
lisp_values: st.SearchStrategy[LispValue] = st.recursive(
    _atoms,
    lambda children: st.lists(children, max_size=5) | st.builds(cons, children, children),
    max_leaves=30,
)


@given(lisp_values, st.sampled_from([8, 10]), st.booleans(), st.booleans(), st.sampled_from(["/", "\\"]))
def test_print_read_round_trip(v: LispValue, base: int, nopoint: bool, upper: bool, escape: str) -> None:
    text = print_lisp(v, base=base, nopoint=nopoint and base == 10, upper=upper, escape=escape)
    assert _same(read_lisp(text, base=base, escape=escape), v)


@given(lisp_values)
def test_base_10_text_reads_the_same_in_base_8(v: LispValue) -> None:
    assert _same(read_lisp(print_lisp(v, base=10), base=8), v)


@given(st.text(alphabet="()'. ;\n\"/ab1:#", max_size=30))
def test_reader_fails_only_with_decode_error(text: str) -> None:
    try:
        read_all(text)
    except DecodeError as exc:
        assert exc.clause == "describe.alist-readable"


# ------------------------------------------------------------------------------------------ Lisp Machine text


def test_lispm_decoding_table() -> None:
    assert decode_lispm(bytes([0o215, 0o212, 0o211, 0o214, 0o210])) == "\n\n\t\f\b"
    assert decode_lispm(b"Puma 600") == "Puma 600"
    assert decode_lispm(bytes([0o201, 0o15, 0o12, 0o377])) == "\ue081\ue00d\ue00a\ue0ff"
    assert decode_lispm(bytes([0, 0o33, 0o177])) == "\x00\x1b\x7f"
    special = set(range(0o200, 0o400)) - {0o210, 0o211, 0o212, 0o214, 0o215}
    assert set(PRIVATE_CODES) == {0o10, 0o11, 0o12, 0o14, 0o15} | special


def test_lispm_encoding_table() -> None:
    assert encode_lispm("a\nb\r\nc\rd\te\ff\bg") == b"a\x8db\x8dc\x8dd\x89e\x8cf\x88g"
    assert encode_lispm("\ue081") == b"\x81"
    for bad in ("é", "\ue041", "\ue08d", "\u2028"):
        assert not is_lispm_encodable(bad)
    with pytest.raises(EncodeError) as info:
        encode_lispm("abc\u00e9")
    assert info.value.clause == "text.lispm-charset" and info.value.offset == 3


def test_lispm_ascii_controls() -> None:
    assert decode_lispm(b"a\r\nb\rc\nd\te\x8df", ascii_controls=True) == "a\nb\nc\nd\te\nf"


_encodable = st.text(
    alphabet=st.characters(max_codepoint=0x7F)
    | st.sampled_from([chr(PRIVATE_BASE + c) for c in PRIVATE_CODES])
)


@given(st.binary())
def test_lispm_bytes_round_trip(b: bytes) -> None:
    assert encode_lispm(decode_lispm(b)) == b.replace(b"\x8a", b"\x8d")


@given(_encodable)
def test_lispm_text_round_trip(s: str) -> None:
    assert is_lispm_encodable(s)
    assert decode_lispm(encode_lispm(s)) == s.replace("\r\n", "\n").replace("\r", "\n")
