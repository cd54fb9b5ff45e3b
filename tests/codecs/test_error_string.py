"""E.2 error strings: golden vectors both ways, hard errors, substitutions and round trips."""

from __future__ import annotations

import json
from importlib import resources
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from manip.codecs.error_string import READINGS, ErrorMessage, format_joint_mask, parse_error, split_error_text
from manip.codecs.errors import DecodeError, EncodeError
from manip.codecs.lispm_text import encode_lispm
from manip.spec import SPEC


def _load() -> list[dict[str, Any]]:
    doc = json.loads(resources.files("manip.vectors").joinpath("error_strings.json").read_text())
    assert doc["format"] == "manip-vectors/1" and doc["subject"] == "error-strings"
    return list(doc["vectors"])


VECTORS = _load()
GOOD = [v for v in VECTORS if "decoded" in v]
BAD = [v for v in VECTORS if "error" in v]


@pytest.mark.parametrize("vec", GOOD, ids=lambda v: v["name"])
def test_decode_vectors(vec: dict[str, Any]) -> None:
    data = bytes.fromhex(vec["hex"])
    m = parse_error(data, align_args=vec["align_args"])
    d = vec["decoded"]
    assert (m.where, m.severity, m.code, m.message) == (d["where"], d["severity"], d["code"], d["message"])
    assert m.args == tuple(d["args"]) and m.has_nul == d["nul"]
    assert m.render() == vec["rendered"]
    if "rendered_octal" in vec:
        assert m.render(radix=8) == vec["rendered_octal"]
    assert (m.problems == ()) == vec["conforms"], m.problems


@pytest.mark.parametrize("vec", GOOD, ids=lambda v: v["name"])
def test_encode_vectors(vec: dict[str, Any]) -> None:
    d = vec["decoded"]
    m = ErrorMessage(d["where"], d["severity"], d["code"], d["message"], tuple(d["args"]), has_nul=d["nul"])
    encoded = m.encode(align_args=vec["align_args"])
    if vec.get("encodes", True):
        assert encoded == bytes.fromhex(vec["hex"])
    assert parse_error(encoded, align_args=vec["align_args"]) == m


@pytest.mark.parametrize("vec", BAD, ids=lambda v: v["name"])
def test_error_vectors(vec: dict[str, Any]) -> None:
    data = bytes.fromhex(vec["hex"])
    with pytest.raises(DecodeError) as info:
        parse_error(data, align_args=vec["align_args"])
    assert info.value.clause == vec["error"]["clause"]
    assert info.value.offset is not None and 0 <= info.value.offset <= len(data)


def test_seed_example() -> None:
    text = b"During calibration: F NZI No zero index found on joint(s) $.\x00"
    pad = b"\x00" * (len(text) % 2)
    m = parse_error(text + pad + (6).to_bytes(2, "little"))
    assert m.render() == "During calibration: F NZI No zero index found on joint(s) 2 and 3."
    assert m.problems == ()


def test_hard_error_offsets() -> None:
    cases = [
        (b"arm E NAP", "error-string.format", 9),
        (b"arm: ", "error-string.format", 5),
        (b"arm: F", "error-string.format", 6),
        (b"arm: F ", "error-string.format", 7),
        (b"ab: E JOR ~\x00\x05\x00\x07", "error-string.arg-layout", 12),  # odd count: a pad, not zero
        (b"abc: E JOR ~\x00\x07\x05\x00", "error-string.arg-layout", 13),
    ]
    for data, clause, offset in cases:
        with pytest.raises(DecodeError) as info:
            parse_error(data)
        assert (info.value.clause, info.value.offset) == (clause, offset), data
    with pytest.raises(DecodeError) as info:  # read as aligned only: no pad due, and half a word left
        parse_error(b"ab: E JOR ~\x00\x05\x00\x07", align_args=True)
    assert (info.value.clause, info.value.offset) == ("error-string.args", 14)


def test_problems() -> None:
    ok = ErrorMessage("arm", "E", "NAP", "No arm power")
    assert ok.problems == ()
    kinds = {
        ErrorMessage("a:b", "E", "NAP", "x"): "colon",
        ErrorMessage("", "E", "NAP", "x"): "empty",
        ErrorMessage("arm", "X", "NAP", "x"): "severity",
        ErrorMessage("arm", "E", "NA", "x"): "three letters",
        ErrorMessage("arm", "E", "N4P", "x"): "three letters",
        ErrorMessage("arm", "E", "JOR", "~ ~", (1,)): "fewer",
        ErrorMessage("arm", "E", "JOR", "~", (1, 2)): "more",
        ErrorMessage("arm", "E", "JOR", "~", has_nul=True): "fewer",
    }
    for m, word in kinds.items():
        assert len(m.problems) == 1 and word in m.problems[0], (m, m.problems)
    # special characters are plain text without a NUL
    assert ErrorMessage("arm", "E", "JOR", "costs $5 ~").problems == ()
    assert ErrorMessage("arm", "E", "JOR", "costs $5 ~").render() == "arm: E JOR costs $5 ~"
    # the tables are parameters
    m = parse_error(b"arm: Z QQQ x", severities={"Z"})
    assert m.problems == ()
    assert parse_error(b"arm: Z QQQ x") == m and parse_error(b"arm: Z QQQ x").problems != ()


def test_a_code_of_the_servers_own_is_no_problem() -> None:
    # E.2: "others may be used by specific manipulators"; only the three-letter shape is required.
    assert ErrorMessage("arm", "E", "XYZ", "m").problems == ()
    assert ErrorMessage("arm", "E", "XY1", "m").problems != ()


def test_spec_tables_are_used() -> None:
    for sev in SPEC.severities:
        for code in SPEC.error_codes:
            assert ErrorMessage("w", sev, code, "m").problems == ()


def test_encode_refusals() -> None:
    cases = [
        (ErrorMessage("a: b", "E", "NAP", "x"), "error-string.where-no-colon"),
        (ErrorMessage("a", "", "NAP", "x"), "error-string.format"),
        (ErrorMessage("a", "E F", "NAP", "x"), "error-string.format"),
        (ErrorMessage("a", "E", "", "x"), "error-string.format"),
        (ErrorMessage("a", "E", "NAP", "x\0y"), "error-string.args"),
        (ErrorMessage("a", "E", "NAP", "~", (0x10000,)), "error-string.args"),
        (ErrorMessage("a", "E", "NAP", "~", (-1,)), "error-string.args"),
        (ErrorMessage("a", "E", "NAP", "caf\u00e9"), "text.lispm-charset"),
    ]
    for m, clause in cases:
        with pytest.raises(EncodeError) as info:
            m.encode()
        assert info.value.clause == clause, m


def test_split_and_args_imply_nul() -> None:
    assert split_error_text("w: F NAP  two spaces") == ("w", "F", "NAP", " two spaces")
    assert split_error_text("a:b: F NAP") == ("a:b", "F", "NAP", "")
    assert ErrorMessage("w", "F", "NZI", "$", (1,)).has_nul
    assert ErrorMessage("w", "F", "NZI", "$", [1]).args == (1,)  # type: ignore[arg-type]


# ------------------------------------------------------------------------------------------ rendering


def joints_expected(mask: int) -> str:
    """Independent joint-list rendering: scan joints 1..16 and join by hand."""
    names = [str(j) for j in range(1, 17) if mask & (1 << (j - 1))]
    if not names:
        return "none"
    text = names[0]
    for i, name in enumerate(names[1:], start=1):
        text += (" and " if i == len(names) - 1 else ", ") + name
    return text


def test_joint_mask_examples() -> None:
    assert format_joint_mask(6) == "2 and 3"
    assert format_joint_mask(1) == "1"
    assert format_joint_mask(0b100011) == "1, 2 and 6"
    assert format_joint_mask(0) == "none"
    assert format_joint_mask(0xFFFF) == "1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15 and 16"


_plain = st.text(
    alphabet=st.characters(min_codepoint=0x20, max_codepoint=0x7E).filter(lambda c: c not in "~$")
)
_RADIX_FORMAT = {2: "b", 8: "o", 10: "d", 16: "X"}


@given(
    st.lists(st.tuples(_plain, st.sampled_from("~$"), st.integers(0, 0xFFFF)), max_size=6),
    _plain,
    st.sampled_from(sorted(_RADIX_FORMAT)),
)
def test_render_matches_independent_computation(
    parts: list[tuple[str, str, int]], tail: str, radix: int
) -> None:
    template = "".join(p + s for p, s, _ in parts) + tail
    args = tuple(n for _, _, n in parts)
    expected = ""
    for prefix, special, n in parts:
        expected += prefix + (format(n, _RADIX_FORMAT[radix]) if special == "~" else joints_expected(n))
    expected += tail
    m = ErrorMessage("arm", "E", "JOR", template, args, has_nul=True)
    assert m.render_message(radix=radix) == expected
    assert m.render(radix=radix) == ("arm: E JOR " + expected if expected else "arm: E JOR")
    assert m.problems == ()


# ------------------------------------------------------------------------------------------ round trips

_text_chars = st.characters(min_codepoint=0x20, max_codepoint=0x7E) | st.sampled_from("\n\t\ue081")
_field = st.text(alphabet=_text_chars.filter(lambda c: c != " "), min_size=1, max_size=4)
_where = st.text(alphabet=_text_chars, max_size=20).filter(lambda w: ": " not in w)
_messages = st.builds(
    ErrorMessage,
    where=_where,
    severity=st.sampled_from(sorted(SPEC.severities)) | _field,
    code=st.sampled_from(sorted(SPEC.error_codes)) | _field,
    message=st.text(alphabet=_text_chars, max_size=40),
    args=st.lists(st.integers(0, 0xFFFF), max_size=5).map(tuple),
    has_nul=st.booleans(),
)


@given(_messages, st.booleans())
def test_encode_parse_round_trip(m: ErrorMessage, align: bool) -> None:
    data = m.encode(align_args=align)
    assert parse_error(data, align_args=align) == m
    assert parse_error(data) == m  # a reader told neither layout reads both (erratum error-arg-layout)
    nul = len(encode_lispm(m.text))
    assert data[:nul] == encode_lispm(m.text) and (len(data) > nul) == m.has_nul
    if m.args:
        first = len(data) - 2 * len(m.args)
        assert data[nul] == 0 and first - nul - 1 == (1 if align and (nul + 1) % 2 else 0)
        if align:
            assert first % 2 == 0  # words sit at even offsets of the packet data


@given(st.binary(max_size=40), st.none() | st.booleans())
def test_parse_never_crashes(data: bytes, align: bool | None) -> None:
    try:
        m = parse_error(data, align_args=align)
    except DecodeError as exc:
        assert exc.clause in {"error-string.format", "error-string.args", "error-string.arg-layout"}
        assert exc.offset is not None and 0 <= exc.offset <= len(data)
    else:
        assert isinstance(m.problems, tuple)
        m.render()


def test_parse_error_takes_either_form_of_body() -> None:
    err = ErrorMessage("During calibration", "F", "NZI", "No zero index found on joint(s) $.", (6,))
    string = err.encode()
    packet = (3).to_bytes(2, "little") + string  # what a fatal-error packet's data hold
    assert parse_error(string) == parse_error(packet) == err
    assert parse_error(packet, body="packet") == parse_error(string, body="string") == err
    assert parse_error(packet).render().endswith("No zero index found on joint(s) 2 and 3.")
    with pytest.raises(DecodeError) as caught:
        parse_error(packet, body="string")
    assert caught.value.clause == "error-string.format"
    with pytest.raises(DecodeError) as caught:  # neither reading works: the message says both were tried
        parse_error((3).to_bytes(2, "little") + b"no separator here")
    assert "read as an error string" in caught.value.message and "request number 3" in caught.value.message
    with pytest.raises(DecodeError) as caught:  # offsets count from the start of the bytes given
        parse_error((3).to_bytes(2, "little") + b"arm: E", body="packet")
    assert caught.value.offset == 2 + len(b"arm: E") and caught.value.path == "error.code"
    with pytest.raises(ValueError, match="body must be"):
        parse_error(string, body="both")  # type: ignore[arg-type]


def test_substitution_readings() -> None:
    """Erratum error-substitution: one number per special character by default, with the surplus named
    as a problem; reading='one-or-more' gives the surplus to the last special character."""
    data = ErrorMessage("arm", "E", "JOR", "Joint(s) $ at ~", (0b110, 10, 20, 30)).encode()
    strict = parse_error(data)
    assert len(strict.problems) == 1 and "one-or-more" in strict.problems[0]
    assert "more than the 2" in strict.problems[0]
    assert strict.render() == "arm: E JOR Joint(s) 2 and 3 at 10"
    lenient = parse_error(data, reading="one-or-more")
    assert lenient == strict and lenient.problems == ()
    assert lenient.render() == "arm: E JOR Joint(s) 2 and 3 at 10, 20, 30"
    masks = parse_error(ErrorMessage("arm", "F", "NZI", "joint(s) $", (1, 6)).encode(), reading="one-or-more")
    assert masks.problems == () and masks.render() == "arm: F NZI joint(s) 1; 2 and 3"
    # fewer numbers than special characters, or numbers without any: a problem under both readings
    for reading in READINGS:
        few = parse_error(ErrorMessage("arm", "E", "XYZ", "~ ~", (1,)).encode(), reading=reading)
        assert "fewer" in few.problems[0] and few.render() == "arm: E XYZ 1 ~"
        none = parse_error(ErrorMessage("arm", "E", "XYZ", "no place", (1,)).encode(), reading=reading)
        assert "more than the 0" in none.problems[0]
    # one to one reads the same either way
    exact = ErrorMessage("arm", "E", "JOR", "Joint(s) $ at ~", (2, 7)).encode()
    assert parse_error(exact).render() == parse_error(exact, reading="one-or-more").render()
    with pytest.raises(ValueError, match="reading"):
        parse_error(exact, reading="several")  # type: ignore[arg-type]
