"""`manip-decode`: what a person sees, and the exit codes scripts rely on."""

from __future__ import annotations

import io
import json
import select
import subprocess
import sys
from importlib.resources import files
from pathlib import Path
from typing import Any, Literal

import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from manip.codecs import ErrorMessage, Packet, encode_chudp, encode_reply, encode_request, encode_tcp
from manip.codecs.framing import FRAMINGS, decode_tcp, encode_chaosd
from manip.codecs.messages import encode_async, encode_error, guard_hit
from manip.codecs.packet import Trailer
from manip.decode.cli import main
from manip.decode.describe import _ENCODE, describe_packet, packet_json
from manip.spec import SPEC
from manip.spec.constants import AsyncCondition, ChaosOp, RequestOp, ServerOp
from tests.support.paths import ROOT

RFC_PUMA = "01010000010000040120000001010a01000100005550414d012001015a1a"  # an RFC to contact PUMA


def _run(*args: str, stdin: str | None = None) -> tuple[int, str, str]:
    result = CliRunner().invoke(main, list(args), input=stdin)
    return result.exit_code, result.stdout, result.stderr


def _pkt(opcode: int, data: bytes) -> Packet:
    return Packet(opcode, 0o401, 0x0A01, 0o440, 0x5E02, 7, 3, data)


def test_rfc_vector() -> None:
    code, out, _ = _run(RFC_PUMA)
    assert code == 0
    assert "RFC" in out and "contact 'PUMA'" in out and "checksum 0x5a1a" in out


def test_here_reply_shows_the_transform() -> None:
    transform = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 500.0, 150.0, 400.0)
    wire = encode_chudp(_pkt(ServerOp.RESPONSE, encode_reply("here", 6, transform=transform))).hex()
    code, out, _ = _run("--direction", "response", "--request-opcode", "201", wire)
    assert code == 0
    assert "response to request 6" in out and "P=(500, 150, 400)" in out


def test_request_is_guessed_and_says_so() -> None:
    data = encode_request("set-joint-angles", joints=(0.0, -90.0, 90.0, 0.0, 0.0, 0.0))
    code, out, _ = _run(encode_chudp(_pkt(RequestOp.SET_JOINT_ANGLES, data)).hex())
    assert code == 0
    assert "0215 set-joint-angles" in out and "hazard: motion" in out and "-90.0" in out
    assert "guessed" in out


def test_error_string_is_rendered() -> None:
    err = ErrorMessage("During calibration", "F", "NZI", "No zero index found on joint(s) $.", (6,))
    wire = encode_chudp(_pkt(ServerOp.FATAL_ERROR, encode_error(ServerOp.FATAL_ERROR, 9, err))).hex()
    code, out, _ = _run("--direction", "response", wire)
    assert code == 0
    assert "No zero index found on joint(s) 2 and 3." in out
    assert "severity: F (Fatal error)" in out


def test_json_and_async() -> None:
    wire = encode_chudp(_pkt(ServerOp.ASYNCHRONOUS_RESPONSE, guard_hit(4, 3, stop=True))).hex()
    code, out, _ = _run("--format", "json", wire)
    assert code == 0
    tree = json.loads(out)
    manip = tree[0]["children"][1]
    assert manip["text"] == "0203 guard-hit"
    assert {c["label"]: c.get("value") for c in manip["children"]}["guard"] == 3


def test_async_in_the_guides_layout_is_told_apart_by_length() -> None:
    data = encode_async(0, AsyncCondition.SEGMENT_COMPLETED, 0, 0o17, async_has_request_number=False)
    wire = encode_chudp(_pkt(ServerOp.ASYNCHRONOUS_RESPONSE, data)).hex()
    code, out, _ = _run("--format", "json", wire)
    assert code == 0
    manip = json.loads(out)[0]["children"][1]
    assert manip["text"] == "0203 segment-completed (the 1985 guide's layout)"
    fields = {c["label"]: (c.get("value"), c.get("offset")) for c in manip["children"]}
    assert "request number" not in fields
    assert fields["condition"][0] == 2 and fields["segment"][0] == 0o17
    assert (fields["condition"][1], fields["segment"][1]) == (0, 4)  # no request number before them
    short = encode_chudp(_pkt(ServerOp.ASYNCHRONOUS_RESPONSE, data[:4])).hex()
    code, out, _ = _run(short)
    assert "8 or 6 data bytes" in out


def test_hexdump_annotates_fields() -> None:
    code, out, _ = _run("--format", "hexdump", RFC_PUMA)
    assert code == 0
    assert out.startswith("wire order (chudp: ")  # the header line says which order and from where
    assert "0000  01 01 00 00 01 00 00 04 01 20" in out  # the datagram as it was on the wire
    assert "  0004-0004  chaos header         opcode" in out  # opcode: high byte of word 0, sent first
    assert "  0014-0017  rfc                  contact          PUMA" in out  # 'UPAM' on the wire
    assert "packet number" in out


def test_tcp_stream_with_two_frames_and_chaosd() -> None:
    frames = encode_tcp(_pkt(0o201, b"")) + encode_tcp(_pkt(0o202, b""))
    code, out, _ = _run("--link", "tcp", frames.hex())
    assert code == 0 and "0201 here" in out and "0202 joint-angles" in out
    code, out, _ = _run("--link", "chaosd", encode_chaosd(_pkt(0o214, b"")).hex())
    assert code == 0 and "0214 ready" in out


def test_cougar_words() -> None:
    code, out, _ = _run("--cougar", "command", "000d 0003 0000 0063 0001")
    assert code == 1  # the unknown code 0x63 is reported, so the input is not clean
    assert "VERS" in out and "NOP" in out and "out of sync" in out


def test_malformed_input_exit_1_with_clause() -> None:
    bad = bytearray.fromhex(RFC_PUMA)
    bad[-1] ^= 1
    code, _, err = _run(bytes(bad).hex())
    assert code == 1
    assert "chudp.checksum" in err and "byte" in err


def test_decode_error_in_manip_layer_exit_1() -> None:
    code, out, _ = _run("--direction", "request", encode_chudp(_pkt(RequestOp.MOVE, b"\0" * 44)).hex())
    assert code == 1
    assert "request.data-length" in out


def test_usage_errors_exit_2() -> None:
    assert _run("zz")[0] == 2
    assert _run("--request-opcode", "777", RFC_PUMA)[0] == 2
    assert _run("--link", "nope", RFC_PUMA)[0] == 2


def test_stdin() -> None:
    code, out, _ = _run("-", stdin=RFC_PUMA + "\n")
    assert code == 0 and "PUMA" in out


# ---------------------------------------------------------------------------------------- issue 14


def test_a_missing_file_is_called_that(tmp_path: Path) -> None:
    for args in (["nosuch.bin"], ["--mcap", "nosuch.mcap"], ["--pcap", "nosuch.pcap"]):
        code, _, err = _run(*args)
        assert code == 2 and "no such file: nosuch." in err, (args, err)
        assert "hexadecimal" not in err and "hex digit" not in err
    code, _, err = _run(str(tmp_path))
    assert code == 2 and "is a directory" in err


def test_empty_input_is_handled_the_same_on_every_link() -> None:
    for link in sorted(FRAMINGS):
        code, out, err = _run("--link", link, "-", stdin="")
        assert (code, out) == (1, ""), link
        assert err == f"manip-decode: empty input: no {link} frame to decode\n"
        assert _run("--link", link, "--format", "json", "-", stdin="")[1] == "[]\n"


def _flat(node: dict[str, Any]) -> dict[str, Any]:
    return {c["label"]: c.get("value") for c in node.get("children", [])}


def test_body_decodes_the_golden_vectors() -> None:
    vectors = json.loads((files("manip.vectors") / "manip.json").read_text())["vectors"]
    seen = set()
    for v in vectors:
        kind = v["kind"]
        if kind == "request":
            args = ["--body", "request", v["opcode"]]
        elif kind in ("reply", "terminator"):
            args = ["--body", "response", v["request_opcode"]]
        elif kind == "error":
            args = ["--body", "response", SPEC.server_opcodes[int(v["opcode"], 8)].name]
        elif kind == "async":
            args = ["--body", "response", "asynchronous-response"]
        else:
            continue
        code, out, err = _run(*args, "--format", "json", v["hex"] or "-", stdin="" if not v["hex"] else None)
        assert code == 0, (v["name"], out, err)
        (body,) = json.loads(out)
        (manip,) = body["children"]
        fields = _flat(manip)
        for name, value in v.get("fields", {}).items():
            assert fields[name] == pytest.approx(value), (v["name"], name)
        if "request_number" in v:
            assert fields["request number"] == v["request_number"]
        if kind == "error":
            assert fields["rendered"] == v["rendered"] and fields.get("arguments", []) == v["args"]
        if kind == "async":
            assert fields["condition"] == v["condition"]
        seen.add(kind)
    assert seen == {"request", "reply", "terminator", "error", "async"}
    code, out, _ = _run("--body", "request", "move", "00" * 44)
    assert code == 1 and "request.data-length" in out
    assert _run("--body", "sideways", "move", "00")[0] == 2
    assert _run("--body", "request", "nope", "00")[0] == 2


def test_hexdump_of_a_stream_shows_wire_order_at_absolute_offsets() -> None:
    first = encode_tcp(_pkt(0o201, b""))
    second = encode_tcp(_pkt(RequestOp.SET_SPEED, encode_request("set-speed", factor=0.5)))
    code, out, _ = _run("--link", "tcp", "--format", "hexdump", (first + second).hex())
    assert code == 0
    dumps = out.split("\n\n")
    assert all(d.startswith("wire order (tcp: 2-byte big-endian length") for d in dumps[::2])
    at = len(first)  # the second frame starts where the first ends
    assert f"{at:04x}  {second[:16].hex(' ')}" in out
    factor = at + 2 + 16  # its data: after the length and the Chaos header
    assert f"  {factor:04x}-{factor + 3:04x}  manip request        factor           0.5" in out
    # the float's four bytes on the wire are its two words, each most significant byte first
    assert second[2 + 16 : 2 + 20] == bytes([0x40, 0x00, 0x00, 0x00])


def test_filter_by_opcode_and_its_usage() -> None:
    frames = b"".join(encode_tcp(_pkt(op, b"")) for op in (0o201, 0o202, 0o201, 0o214))
    code, out, _ = _run("--link", "tcp", "--filter", "opcode=here", "--format", "json", frames.hex())
    assert code == 0 and [p["children"][1]["value"]["name"] for p in json.loads(out)] == ["here", "here"]
    code, out, _ = _run("--link", "tcp", "--filter", "opcode=0214", "--filter", "opcode=202", frames.hex())
    assert code == 0 and "0214 ready" in out and "0202 joint-angles" in out and "0201 here" not in out
    assert (
        _run("--link", "tcp", "--filter", "conn=1", frames.hex())[0] == 2
    )  # no connections outside captures
    assert _run("--link", "tcp", "--filter", "opcode=nope", frames.hex())[0] == 2
    assert _run("--link", "tcp", "--filter", "color=red", frames.hex())[0] == 2


def test_filter_a_capture_by_request_name_takes_its_replies_too() -> None:
    code, out, _ = _run("--mcap", str(ROOT / "captures" / "errors.mcap"), "--filter", "opcode=move")
    assert code == 0, out
    assert "request move" in out and "E NAP" in out and "joint-angles" not in out
    code, out, _ = _run("--mcap", str(ROOT / "captures" / "errors.mcap"), "--filter", "conn=2")
    assert code == 1 and out.count("\n") == 1  # the header line; the capture has one connection
    assert (
        "no packet matches --filter"
        in _run("--mcap", str(ROOT / "captures" / "errors.mcap"), "--filter", "conn=2")[2]
    )


def test_output_starts_before_the_input_ends() -> None:
    frame = encode_tcp(_pkt(0o201, b""))
    # A process on purpose (manip-decode, not a server): its output must come while its stdin is open.
    proc = subprocess.Popen(
        [str(Path(sys.executable).with_name("manip-decode")), "--link", "tcp", "--binary", "-"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )  # fmt: skip
    assert proc.stdin is not None and proc.stdout is not None
    try:
        proc.stdin.write(frame * 4 + bytes(70_000))  # whole frames, then more than one read block
        proc.stdin.flush()
        ready, _, _ = select.select([proc.stdout], [], [], 20)
        assert ready, "no output while the input is still open"
        assert proc.stdout.readline().startswith(b"packet: DAT 0201")
    finally:
        proc.kill()
        proc.communicate(timeout=20)


def test_a_bad_frame_in_a_stream_is_shown_in_place_and_the_stream_goes_on() -> None:
    good = encode_tcp(_pkt(0o201, b""))
    bad = bytearray(encode_tcp(_pkt(0o202, b"")))
    bad[-1] ^= 0xFF
    code, out, err = _run("--link", "tcp", "--format", "json", (good + bytes(bad) + good).hex())
    assert code == 1 and "1 tcp frame(s) did not decode" in err
    packets = json.loads(out)
    assert len(packets) == 3 and packets[1]["label"] == "frame"
    assert f"tcp frame at byte {len(good)}" in packets[1]["text"]
    assert packets[1]["children"][0]["value"]["clause"] == "chudp.checksum"


def test_hex_text_split_anywhere_decodes_the_same() -> None:
    from manip.decode.source import Source, byte_blocks

    text = b"0x01 0x01:00,00\n" + b"0101 0x0a01 00ff"
    want = bytes.fromhex("0101000001010a0100ff")

    class Trickle(io.BytesIO):
        def read(self, size: int | None = -1) -> bytes:
            return super().read(3)

    assert b"".join(byte_blocks(Source("t", Trickle(text), True), None)) == want


def test_no_python_octal_in_messages() -> None:
    code, out, _ = _run("--direction", "request", encode_chudp(_pkt(0o277, b"")).hex())
    assert code == 1 and "opcode 0277 is not a request opcode" in out and "0o" not in out


def test_cougar_words_or_a_missing_file() -> None:
    code, _, err = _run("--cougar", "command", "words.txt")
    assert code == 2 and "no such file: words.txt" in err
    assert _run("--cougar", "command", "000d 0003")[0] in (0, 1)  # words, not a file name


def test_the_decoder_does_not_import_numpy() -> None:
    """numpy takes a large part of a cold start: decoding (floats included) does not need it."""
    frames = (
        encode_tcp(_pkt(RequestOp.SET_JOINT_ANGLES, encode_request("set-joint-angles", joints=[0.5] * 6)))
        + encode_tcp(_pkt(RequestOp.SET_SPEED, encode_request("set-speed", factor=0.25)))
    ).hex()
    script = (
        "import sys\n"
        "import manip.decode.cli\n"
        "assert 'numpy' not in sys.modules, 'import manip.decode.cli loaded numpy'\n"
        "from click.testing import CliRunner\n"
        f"result = CliRunner().invoke(manip.decode.cli.main, ['--link', 'tcp', {frames!r}])\n"
        "assert result.exit_code == 0 and 'factor: 0.25' in result.output, result.output\n"
        "assert 'numpy' not in sys.modules, 'decoding floats loaded numpy'\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], check=False, capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr


_WORD = st.integers(0, 0xFFFF)


@settings(max_examples=300, deadline=None)
@given(
    st.integers(0, 0xFF),
    st.tuples(_WORD, _WORD, _WORD, _WORD, _WORD, _WORD),
    st.binary(max_size=64),
    st.integers(0, 15),
    st.one_of(st.none(), st.tuples(_WORD, _WORD, _WORD)),
    st.sampled_from(["auto", "request", "response"]),
)
def test_packet_json_is_the_tree_encoded(
    opcode: int,
    words: tuple[int, int, int, int, int, int],
    data: bytes,
    fc: int,
    trailer: tuple[int, int, int] | None,
    direction: Literal["auto", "request", "response"],
) -> None:
    """--format json writes the Chaos header from the packet, not from its tree: the same bytes."""
    dh, di, sh, si, pn, an = words
    t = None if trailer is None else Trailer(*trailer)
    p = Packet(opcode, dh, di, sh, si, pn, an, data, fc, t)
    want = _ENCODE(describe_packet(p, direction=direction).to_json())
    headless = describe_packet(p, direction=direction, header=False)
    assert packet_json(headless, p) == want
    headless.add("decode error", "added after describing, as the decoder does")
    whole = describe_packet(p, direction=direction)
    whole.add("decode error", "added after describing, as the decoder does")
    assert packet_json(headless, p) == _ENCODE(whole.to_json())


def test_packet_json_on_packets_read_from_the_tcp_link() -> None:
    err = ErrorMessage("During calibration", "F", "NZI", "No zero index found on joint(s) $.", (6,))
    packets = [
        _pkt(RequestOp.HERE, b""),
        _pkt(0o204, encode_request("move", transform=(1.5,) * 12)),
        _pkt(ServerOp.RESPONSE, encode_reply("here", 7, transform=(0.25,) * 12)),
        _pkt(ServerOp.FATAL_ERROR, encode_error(ServerOp.FATAL_ERROR, 7, err)),
    ]
    for sent in packets:
        p = decode_tcp(encode_tcp(sent))
        assert p.trailer is not None
        assert packet_json(describe_packet(p, header=False), p) == _ENCODE(describe_packet(p).to_json())


TRANSFORM = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 500.0, 150.0, 400.0)
CLIENT, SERVER = (0o401, 0x0A01), (0o440, 0x5E02)


def _between(opcode: int, number: int, data: bytes, *, to_server: bool) -> Packet:
    (dh, di), (sh, si) = (SERVER, CLIENT) if to_server else (CLIENT, SERVER)
    return Packet(opcode, dh, di, sh, si, number, 0, data)


def test_a_tcp_stream_pairs_each_reply_with_its_request() -> None:
    """No --request-opcode: a stream holding both sides decodes each reply by its request's layout (the
    server is the side the RFC went to), as --pcap and the Wireshark dissector do."""
    rfc = Packet(ChaosOp.RFC, SERVER[0], 0, CLIENT[0], CLIENT[1], 1, 0, b"PUMA")
    stream = [
        rfc,
        _between(ChaosOp.OPN, 1, b"\x01\x00\x0f\x00", to_server=False),
        _between(ServerOp.RESPONSE, 2, (1).to_bytes(2, "little"), to_server=False),
        _between(RequestOp.HERE, 2, b"", to_server=True),
        _between(RequestOp.JOINT_ANGLES, 3, b"", to_server=True),
        _between(ServerOp.RESPONSE, 3, encode_reply("here", 2, transform=TRANSFORM), to_server=False),
        _between(ServerOp.RESPONSE, 4, encode_reply("joint-angles", 3, joints=(1.0,) * 6), to_server=False),
    ]
    code, out, err = _run("--link", "tcp", b"".join(encode_tcp(p) for p in stream).hex())
    assert code == 0, out + err
    assert "P=(500, 150, 400)" in out and "answers: request #2 (here 0201), paired by position" in out
    assert "answers: request #3 (joint-angles 0202), paired by position" in out
    assert "guessed" not in out.split("0201 here")[1]  # the sides come from the RFC, not a guess


def test_a_stream_cut_mid_connection_pairs_by_the_number_a_reply_carries() -> None:
    stream = [
        _between(RequestOp.HERE, 7, b"", to_server=True),
        _between(ServerOp.RESPONSE, 9, encode_reply("here", 7, transform=TRANSFORM), to_server=False),
    ]
    code, out, err = _run("--link", "tcp", b"".join(encode_tcp(p) for p in stream).hex())
    assert code == 0, out + err
    assert "P=(500, 150, 400)" in out and "request #7 (here 0201), paired by the number it carries" in out


DECODE = [sys.executable, "-c", "from manip.decode.cli import main; main()"]


def test_no_source_on_a_terminal_says_what_it_waits_for() -> None:
    """Standard input is a terminal (a pseudo-terminal here): a prompt on stderr, then the hex typed."""
    import os
    import pty

    master, slave = pty.openpty()
    try:
        proc = subprocess.Popen(
            DECODE, stdin=slave, stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        os.close(slave)
        slave = -1
        os.write(master, RFC_PUMA.encode() + b"\n\x04")
        out, err = proc.communicate(timeout=60)  # one Ctrl-D after the line ends the input
    finally:
        os.close(master)
        if slave >= 0:
            os.close(slave)
    assert "reading standard input, a terminal: type or paste hex" in err and "Ctrl-D" in err
    assert proc.returncode == 0 and "contact 'PUMA'" in out, out + err
    piped = subprocess.run(DECODE, input=RFC_PUMA, capture_output=True, text=True, timeout=60, check=False)
    assert piped.returncode == 0 and piped.stderr == ""  # a pipe gets no prompt
