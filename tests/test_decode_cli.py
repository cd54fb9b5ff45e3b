"""`manip-decode`: what a person sees, and the exit codes scripts rely on."""

from __future__ import annotations

import json

from click.testing import CliRunner

from manip.codecs import ErrorMessage, Packet, encode_chudp, encode_reply, encode_request, encode_tcp
from manip.codecs.framing import encode_chaosd
from manip.codecs.messages import encode_error, guard_hit
from manip.decode.cli import main
from manip.spec.constants import RequestOp, ServerOp

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


def test_hexdump_annotates_fields() -> None:
    code, out, _ = _run("--format", "hexdump", RFC_PUMA)
    assert code == 0
    assert "0000  00 01 04 00 20 01" in out  # the packet in PDP-11 memory order
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
