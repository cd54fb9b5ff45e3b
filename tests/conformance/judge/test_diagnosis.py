"""The likely cause said beside a wrong value: floats with their words or bytes swapped, numbers one off
or byte-swapped, error-string numbers read a byte early; and expected and actual that describe the same
thing (the whole data, counted the same way)."""

from __future__ import annotations

from manip.codecs.messages import encode_reply
from manip.codecs.pdp11float import pack_f
from manip.conformance.cases.client._support import _arguments_cause
from manip.conformance.judge.checks import check_reply
from manip.conformance.judge.diagnosis import floats_diagnosis, number_diagnosis, swap_bytes, swap_words
from manip.conformance.judge.packets import WirePacket
from manip.spec import SPEC
from manip.spec.constants import ServerOp

HERE = SPEC.request("here").opcode
POSE = [0.95, 0.066, 0.305, -0.07, 0.9976, 0.0, -0.3045, -0.021, 0.952, 248.7, 12.5, 994.000244140625]
"""A hand pose whose last float, words swapped, starts with the word 0x8004: a reserved operand."""


def _here_reply(number: int, data: bytes) -> list[WirePacket]:
    return [WirePacket("s2c", ServerOp.RESPONSE, 30, number, data)]


def test_a_reply_with_swapped_float_words_says_so_and_counts_bytes_one_way() -> None:
    good = encode_reply("here", 7, transform=POSE)
    swapped = good[:2] + swap_words(good[2:])
    (finding,) = check_reply(WirePacket("c2s", HERE, 7, 0, b""), _here_reply(7, swapped))
    assert "with the two words of each float swapped the floats read (0.95, 0.066, 0.305" in finding.message
    assert "248.7, 12.5, 994" in finding.message
    # the same thing on both sides: the whole data, 50 bytes, and what is wrong in it
    assert (
        finding.expected
        == "the request number then transform (transform): 50 data bytes, every float a number"
    )
    assert finding.actual.startswith("50 data bytes; transform[")
    assert finding.packet is not None


def test_swapped_bytes_are_told_apart_from_swapped_words() -> None:
    data = b"".join(pack_f(v) for v in POSE)
    assert floats_diagnosis(data) is None  # right as sent: nothing to say
    assert "two bytes of each word swapped" in (floats_diagnosis(swap_bytes(data)) or "")
    assert "two words of each float swapped" in (floats_diagnosis(swap_words(data)) or "")


def test_a_round_trip_names_the_swap_that_gives_the_values_sent() -> None:
    sent = [10.0, -80.0, 80.0, 0.0, 10.0, 0.25]
    data = swap_words(b"".join(pack_f(v) for v in sent))
    said = floats_diagnosis(data, sent) or ""
    assert "the values expected" in said and "two words of each float swapped" in said
    assert floats_diagnosis(b"".join(pack_f(v + 1) for v in sent), sent) is None


def test_request_numbers_one_off_or_byte_swapped() -> None:
    request = WirePacket("c2s", HERE, 0x0107, 0, b"")
    for number, said, clause in (
        (0x0108, "one more", "response.echoes-request-number"),
        (0x0106, "one less", "response.echoes-request-number"),
        (0x0701, "two bytes swapped", "response.word-byte-order"),  # sent high byte first
    ):
        reply = encode_reply("here", number, transform=POSE)
        (finding,) = check_reply(request, _here_reply(number, reply))
        assert finding.clause == clause and said in finding.message, finding.message
    assert number_diagnosis(900, 7) is None and number_diagnosis(7, 7) is None


def test_error_string_numbers_read_a_byte_early_or_swapped() -> None:
    want = [63, 37158]
    packed = b"\0" + b"".join(w.to_bytes(2, "little") for w in want)
    early = [int.from_bytes(packed[i : i + 2], "little") for i in (0, 2)]
    assert "one byte early" in (_arguments_cause(early, want) or "")
    assert "two bytes swapped" in (_arguments_cause([0x3412, 0x7856], [0x1234, 0x5678]) or "")
    assert _arguments_cause([5, 9], [1, 2]) is None
